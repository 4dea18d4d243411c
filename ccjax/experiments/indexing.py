"""Colour indexing as a yardstick for colour constancy (Barnard 1999 ch. 11, §11.2-§11.3).

Swain & Ballard's colour indexing on (r,g) chromaticity: every image becomes a 16x16 histogram of
pixel chromaticities (bin width 1/16, coarse on purpose), normalised to unit mass; the
match score of a test histogram ``T`` against a model ``M`` is the histogram intersection
``H(T, M) = sum_j min(T_j, M_j) / sum_j M_j`` (eq. 11.2), and the model with the highest score is
the answer. Colour constancy is the preprocessing: each test image is mapped to the canonical light
with the diagonal map ``w_C / e`` of its estimated illuminant ``e`` before its histogram is taken.
With ``n_k`` the number of test images whose correct model ranks k-th,
``Score(1) = n1 / N``, ``Score(2) = (n1 + n2 / 2) / N``, ``Score(3) = (n1 + n2 / 2 + n3 / 3) / N``.

The experiment (:func:`run_indexing`) is the chapter's on synthetic object images: ``n_objects``
objects, each ``n_surfaces`` reflectances on a Mondrian with random areas; the database holds each
object under the canonical light, the queries show every object under every light of a random
``n_lights`` subset of the world's test illuminants, each in a new pose (random flips and
transposition), with new shading and noise. ``ACTUAL`` uses the true light (the thesis' row name).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int, Key, PRNGKeyArray

from ccjax import limits, scenes
from ccjax._colour import rg_bin
from ccjax.metrics import rg, rg_error

BINS = 16
"""Histogram bins per (r,g) axis: bin width 1/16, coarse on purpose (§11.2)."""

IMAGE_NOISE = scenes.ShotNoise(a=1e-4, b=0.0)
"""Noise of the experiment's images (variance ``a * rho + b`` on the image's scale)."""


def rg_histogram(rgb: Float[Array, "... 3"], mask: Bool[Array, "..."], bins: int = BINS) -> Float[Array, "bins bins"]:
    """Unit-mass histogram of the (r,g) chromaticities of the masked pixels of one image.

    Arguments:
        rgb: pixels ``(..., 3)`` (any leading shape, e.g. ``(H, W, 3)``).
        mask: ``(...)`` True for pixels to count (black pixels never count).
        bins: bins per axis over ``[0, 1]``.

    Returns:
        ``(bins, bins)`` indexed ``[r bin, g bin]``; all zeros if no pixel counts.
    """
    rgb = rgb.reshape(-1, 3)
    valid = mask.reshape(-1) & (jnp.sum(rgb, axis=-1) > 0)
    cells = rg_bin(rg(rgb), bins)
    counts = jnp.zeros(bins * bins, rgb.dtype).at[cells[:, 0] * bins + cells[:, 1]].add(valid.astype(rgb.dtype))
    return (counts / jnp.maximum(jnp.sum(counts), 1.0)).reshape(bins, bins)


def intersection(tests: Float[Array, "Q b b"], models: Float[Array, "M b b"]) -> Float[Array, "Q M"]:
    """Histogram intersection ``sum min(T, M) / sum M`` (eq. 11.2) of every test with every model."""
    overlap = jax.vmap(lambda t: jax.vmap(lambda m: jnp.sum(jnp.minimum(t, m)))(models))(tests)
    return overlap / jnp.maximum(jnp.sum(models, axis=(1, 2)), 1e-12)[None, :]


def correct_ranks(scores: Float[Array, "Q M"], truth: Int[Array, " Q"]) -> Int[Array, " Q"]:
    """Rank (1 = best) of the correct model of each test: 1 + the number of models scoring
    strictly higher (ties resolved in the correct model's favour)."""
    own = jnp.take_along_axis(scores, truth[:, None], axis=1)
    return 1 + jnp.sum(scores > own, axis=1)


def rank_scores(ranks) -> tuple[tuple[float, float, float], tuple[int, int, int]]:
    """``(Score(1), Score(2), Score(3))`` and ``(n1, n2, n3)`` from the correct models' ranks."""
    ranks = np.asarray(ranks)
    n1, n2, n3 = (int(np.sum(ranks == k)) for k in (1, 2, 3))
    total = len(ranks)
    return (n1 / total, (n1 + n2 / 2) / total, (n1 + n2 / 2 + n3 / 3) / total), (n1, n2, n3)


# ---------------------------------------------------------------------------------------------
# The synthetic experiment

BLOCK_PIXELS = 1 << 19
"""Pixels of the images rendered and estimated at once (6 MB of float32 RGB; 128 images of the
default 64 x 64): the experiment goes in blocks of ``BLOCK_PIXELS // size**2`` images (at least
one), so its memory does not grow with the images. The estimators' working memory is most of a
block's (measured: about 1.7 MB an image for a gamut method on 64 x 64 images)."""


class ObjectKeys(eqx.Module):
    """What draws every image of the experiment: the objects' keys, the query lights and keys."""

    objects: Key[Array, " O"]  # one key per object: its surfaces, layout and database image
    lights: Int[Array, " L"]  # indices of the query lights among the world's test illuminants
    queries: Key[Array, "O L"]  # one key per query image: its pose, shading and noise


def object_keys(key: PRNGKeyArray, n_objects: int, n_lights: int, n_available: int) -> ObjectKeys:
    """Split the experiment's key into per-object and per-query keys (the images do not depend on
    how they are grouped into blocks).

    Arguments:
        key: the experiment's key.
        n_objects, n_lights: the experiment's dimensions.
        n_available: the world's test illuminants, drawn from without replacement.

    Returns:
        :class:`ObjectKeys`.
    """
    key_objects, key_lights = jax.random.split(key)
    lights = jax.random.choice(key_lights, n_available, (n_lights,), replace=False)
    objects = jax.random.split(key_objects, n_objects)
    queries = jax.vmap(lambda k: jax.random.split(jax.random.split(k, 4)[3], n_lights))(objects)
    return ObjectKeys(objects=objects, lights=lights, queries=queries)


def _object(tables, object_key, n_surfaces: int, size: int):
    key_surf, key_layout, key_db, _ = jax.random.split(object_key, 4)
    surfaces = scenes.draw_without_replacement(key_surf, tables.surface_rgb.shape[1], n_surfaces)
    return surfaces, scenes.mondrian_layout(key_layout, size, size, n_surfaces), key_db


@eqx.filter_jit
def render_database(tables, objects: Key[Array, " B"], n_surfaces: int, size: int, noise) -> Float[Array, "B H W 3"]:
    """The database images (canonical light) of a block of objects, from their keys.

    Arguments:
        tables: the world's :class:`~ccjax.scenes.SceneTables`.
        objects: the objects' keys (:attr:`ObjectKeys.objects`).
        n_surfaces, size: reflectances per object and image side (static).
        noise: image noise, or None.

    Returns:
        ``(B, size, size, 3)`` images.
    """

    def one(object_key):
        surfaces, labels, key_db = _object(tables, object_key, n_surfaces, size)
        image, _ = scenes.render_mondrian(
            key_db, labels, tables.canonical_rgb[surfaces], tables.canonical_white, noise=noise
        )
        return image

    return jax.vmap(one)(objects)


@eqx.filter_jit
def render_queries(
    tables,
    objects: Key[Array, " B"],
    queries: Key[Array, " B"],
    lights: Int[Array, " B"],
    n_surfaces: int,
    size: int,
    noise,
) -> Float[Array, "B H W 3"]:
    """A block of query images: image ``i`` shows object ``objects[i]`` under test light
    ``lights[i]`` in a new pose (random flips and transposition), drawn from ``queries[i]``.

    Arguments:
        tables: the world's :class:`~ccjax.scenes.SceneTables`.
        objects: each image's object key (:attr:`ObjectKeys.objects`).
        queries: each image's own key (:attr:`ObjectKeys.queries`).
        lights: each image's light, an index into the tables' test illuminants.
        n_surfaces, size: reflectances per object and image side (static).
        noise: image noise, or None.

    Returns:
        ``(B, size, size, 3)`` images.
    """

    def one(object_key, query_key, light):
        surfaces, labels, _ = _object(tables, object_key, n_surfaces, size)
        key_pose, key_render = jax.random.split(query_key)
        flips = jax.random.bernoulli(key_pose, 0.5, (3,))
        posed = jnp.where(flips[0], labels[::-1], labels)
        posed = jnp.where(flips[1], posed[:, ::-1], posed)
        posed = jnp.where(flips[2], posed.T, posed)  # square images: transposition is a pose
        image, _ = scenes.render_mondrian(
            key_render, posed, tables.surface_rgb[light, surfaces], tables.whites[light], noise=noise
        )
        return image

    return jax.vmap(one)(objects, queries, lights)


def blocks(n_items: int, size: int) -> list[np.ndarray]:
    """Indices ``0 .. n_items - 1`` in blocks of ``max(1, BLOCK_PIXELS // size**2)``; the last
    block is padded with its last index, so every block has one shape (one compiled program).

    Arguments:
        n_items: the number of images.
        size: the image side in pixels.

    Returns:
        The blocks' index arrays (the padding is dropped by keeping ``[: n_items - start]``).
    """
    block = max(1, min(n_items, BLOCK_PIXELS // (size * size)))
    return [np.minimum(np.arange(start, start + block), n_items - 1) for start in range(0, n_items, block)]


def _dark_mask(images: Float[Array, "... H W 3"], dark: float | Float[Array, ""]) -> Bool[Array, "... H W"]:
    brightness = jnp.sum(images, axis=-1)
    peak = jnp.max(brightness, axis=(-2, -1), keepdims=True)
    return (brightness >= dark * peak) & (brightness > 0)


@dataclass
class IndexingResult:
    """Per method: rg RMS error of the estimates, Score(1..3) and rank counts (Table 11.1 layout)."""

    rows: dict[str, dict] = field(default_factory=dict)
    n_queries: int = 0

    def spearman(self, score: str = "score3") -> float:
        """Spearman rank correlation between the score and the rg error over the methods."""
        from scipy.stats import spearmanr

        errors = [row["rg_error"] for row in self.rows.values()]
        scores = [row[score] for row in self.rows.values()]
        # scipy's stubs type the result as a bare tuple; it is a SignificanceResult.
        return float(spearmanr(errors, scores).statistic)  # pyright: ignore[reportAttributeAccessIssue]

    def table(self) -> str:
        lines = [
            f"colour indexing, {self.n_queries} query images (Barnard 1999 Table 11.1 layout)",
            f"{'method':<24}{'rg error':>9}{'Score(1)':>10}{'Score(2)':>10}{'Score(3)':>10}{'n1':>6}{'n2':>6}{'n3':>6}",
        ]
        for method, row in self.rows.items():
            lines.append(
                f"{method:<24}{row['rg_error']:9.4f}{row['score1']:10.3f}{row['score2']:10.3f}{row['score3']:10.3f}"
                f"{row['n1']:6d}{row['n2']:6d}{row['n3']:6d}"
            )
        lines.append(
            f"Spearman correlation of Score(3) with rg error over the {len(self.rows)} rows: {self.spearman():.3f}"
        )
        lines.append(f"Spearman correlation of Score(1) with rg error: {self.spearman('score1'):.3f}")
        return "\n".join(lines)


def _estimates(model, queries: np.ndarray, preprocessing, dark: float) -> tuple[np.ndarray, np.ndarray]:
    """Run one model on every query image through the image pipeline (vmapped over queries)."""
    from ccjax.io import LinearImage
    from ccjax.preprocessing import surfaces

    flat = queries.reshape((-1,) + queries.shape[-3:])
    if model.input_kind == "image":
        rgb, mask = jnp.asarray(flat), jnp.ones(flat.shape[:3], bool)
    else:
        # The thesis' dark rule (relative to the brightest pixel, as ``_dark_mask``): these
        # synthetic images have no highlights, and Table 11.1 is defined with it.
        lists = [
            surfaces(LinearImage(image, np.zeros(image.shape[:2], bool)), preprocessing, dark=dark, percentile=100.0)
            for image in flat
        ]
        # Each list is padded to its own size class; the batch takes the largest (one compilation).
        size = max(len(data) for data, _ in lists)
        rgb = np.zeros((len(lists), size, 3), np.float32)
        mask = np.zeros((len(lists), size), bool)
        for index, (data, valid) in enumerate(lists):
            rgb[index, : len(data)], mask[index, : len(data)] = data, valid
        rgb, mask = jnp.asarray(rgb), jnp.asarray(mask)
    estimate = _batched(model, rgb, mask)
    return np.asarray(estimate.illuminant), np.asarray(estimate.ok)


@eqx.filter_jit
def _batched(model, rgb, mask):
    return jax.vmap(model)(rgb, mask)


@jax.jit
def _histograms(images: Float[Array, "B H W 3"], dark) -> Float[Array, "B b b"]:
    return jax.vmap(rg_histogram)(images, _dark_mask(images, dark))


@jax.jit
def _scores(queries, whites, estimates, canonical_white, database_histograms, truth, dark):
    """Correct each query of a block by its estimate, histogram it, rank the correct object."""
    maps = canonical_white / jnp.maximum(estimates, 1e-12)  # (B, 3)
    corrected = queries * maps[:, None, None, :]
    histograms = jax.vmap(rg_histogram)(corrected, _dark_mask(queries, dark))
    ranks = correct_ranks(intersection(histograms, database_histograms), truth)
    return ranks, rg_error(estimates, whites)


def run_indexing(
    world,
    methods,
    key: PRNGKeyArray,
    *,
    n_objects: int = 50,
    n_surfaces: int = 8,
    n_lights: int = 20,
    size: int = 64,
    noise: scenes.ShotNoise | None = IMAGE_NOISE,
    preprocessing: str = "ave5",
    dark: float = 0.02,
    fit=None,
    progress: bool = False,
) -> IndexingResult:
    """The chapter 11 experiment on synthetic object images (module docstring).

    Arguments:
        world: reflectances, test illuminants, canonical light and camera.
        methods: estimator labels; ``"ACTUAL"`` is the true light.
        key: ``jax.random`` key of objects, lights, poses, shading and noise.
        n_objects, n_surfaces, n_lights, size: the experiment's dimensions (thesis: 20 objects,
            11 lights; the defaults: a synthetic version with 50 objects of 8 reflectances, 20 lights);
            ``n_objects`` at most :data:`ccjax.limits.OBJECTS`, ``size`` at most
            :data:`ccjax.limits.INDEXING_SIZE`. The images are rendered, estimated and scored in
            blocks of :data:`BLOCK_PIXELS` pixels: what grows with the objects is only what is
            kept (each object's histogram, each query's rank and error per method).
        noise: image noise (variance ``a * rho + b``), or None.
        preprocessing, dark: the image pipeline's settings for surface-list methods.
        fit: ``fit(label, world) -> estimator`` (default :func:`ccjax.runs.store.fit`).
        progress: show a progress bar over the blocks of images and the methods.

    Returns:
        :class:`IndexingResult`.

    Raises:
        ValueError: a dimension out of range or past its limit, naming the argument (before any
            image is rendered).
    """
    from tqdm.auto import tqdm

    from ccjax.runs import store

    n_objects = limits.require_count(n_objects, "n_objects", 1, limits.OBJECTS)
    size = limits.require_count(size, "size", 1, limits.INDEXING_SIZE)
    if not 1 <= n_lights <= world.test_illuminants.shape[0]:
        raise ValueError(f"n_lights: expected 1 .. {world.test_illuminants.shape[0]}, got {n_lights}")
    if not 1 <= n_surfaces <= world.reflectances.shape[0]:
        raise ValueError(f"n_surfaces: expected 1 .. {world.reflectances.shape[0]}, got {n_surfaces}")
    fit = fit or store.fit
    tables = scenes.SceneTables.from_world(world)
    keys = object_keys(key, n_objects, n_lights, tables.whites.shape[0])
    # Pass 1: every object's database histogram (1 KB an object), from blocks of images.
    database = np.zeros((n_objects, BINS, BINS), np.float32)
    for index in blocks(n_objects, size):
        count = min(len(index), n_objects - int(index[0]))
        images = render_database(tables, keys.objects[index], n_surfaces, size, noise)
        database[index[0] : index[0] + count] = np.asarray(_histograms(images, dark))[:count]
    database_histograms = jnp.asarray(database)
    # Pass 2: blocks of query images (query q shows object q // n_lights under light q % n_lights),
    # each rendered once and estimated by every method; only ranks and errors are kept.
    models = {label: fit(label, world) for label in methods if label != "ACTUAL"}
    n_queries = n_objects * n_lights
    ranks = {label: np.zeros(n_queries, np.int64) for label in methods}
    errors = {label: np.zeros(n_queries, np.float64) for label in methods}
    query_blocks = blocks(n_queries, size)
    bar = tqdm(total=len(query_blocks) * len(ranks), desc="methods x blocks", disable=not progress)
    for index in query_blocks:
        start = int(index[0])
        count = min(len(index), n_queries - start)
        objects, columns = index // n_lights, index % n_lights
        lights = keys.lights[columns]
        images = render_queries(
            tables, keys.objects[objects], keys.queries[objects, columns], lights, n_surfaces, size, noise
        )
        whites = tables.whites[lights]
        pixels = np.asarray(images)
        for label in ranks:
            if label == "ACTUAL":
                estimates = whites
            else:
                estimates = jnp.asarray(_estimates(models[label], pixels, preprocessing, dark)[0])
            block_ranks, block_errors = _scores(
                images, whites, estimates, world.canonical_white, database_histograms, jnp.asarray(objects), dark
            )
            ranks[label][start : start + count] = np.asarray(block_ranks)[:count]
            errors[label][start : start + count] = np.asarray(block_errors)[:count]
            bar.update()
    bar.close()
    result = IndexingResult(n_queries=n_queries)
    for label in ranks:
        (s1, s2, s3), (n1, n2, n3) = rank_scores(ranks[label])
        rms = float(np.sqrt(np.mean(errors[label] ** 2)))
        result.rows[label] = {"rg_error": rms, "score1": s1, "score2": s2, "score3": s3, "n1": n1, "n2": n2, "n3": n3}
    return result
