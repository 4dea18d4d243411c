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
from jaxtyping import Array, Bool, Float, Int, PRNGKeyArray

from ccjax import scenes
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


class ObjectImages(eqx.Module):
    """The experiment's images: database (canonical light) and queries (object x light)."""

    database: Float[Array, "O H W 3"]
    queries: Float[Array, "O L H W 3"]
    query_whites: Float[Array, "L 3"]  # light of each query column (unit max channel)


@eqx.filter_jit
def render_objects(
    key: PRNGKeyArray, world, n_objects: int, n_surfaces: int, n_lights: int, size: int, noise
) -> ObjectImages:
    """Draw the objects and render database and query images (see the module docstring)."""
    tables = scenes.SceneTables.from_world(world)
    key_objects, key_lights = jax.random.split(key)
    lights = jax.random.choice(key_lights, tables.whites.shape[0], (n_lights,), replace=False)

    def one_object(object_key):
        key_surf, key_layout, key_db, key_queries = jax.random.split(object_key, 4)
        surfaces = scenes.draw_without_replacement(key_surf, tables.surface_rgb.shape[1], n_surfaces)
        labels = scenes.mondrian_layout(key_layout, size, size, n_surfaces)
        database, _ = scenes.render_mondrian(
            key_db, labels, tables.canonical_rgb[surfaces], tables.canonical_white, noise=noise
        )

        def query(query_key, light):
            key_pose, key_render = jax.random.split(query_key)
            flips = jax.random.bernoulli(key_pose, 0.5, (3,))
            posed = jnp.where(flips[0], labels[::-1], labels)
            posed = jnp.where(flips[1], posed[:, ::-1], posed)
            posed = jnp.where(flips[2], posed.T, posed)  # square images: transposition is a pose
            image, _ = scenes.render_mondrian(
                key_render, posed, tables.surface_rgb[light, surfaces], tables.whites[light], noise=noise
            )
            return image

        queries = jax.vmap(query)(jax.random.split(key_queries, n_lights), lights)
        return database, queries

    database, queries = jax.vmap(one_object)(jax.random.split(key_objects, n_objects))
    return ObjectImages(database=database, queries=queries, query_whites=tables.whites[lights])


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
def _scores(queries, whites, estimates, canonical_white, database_histograms, dark):
    """Correct each query by its estimate, histogram it, rank the correct object."""
    n_objects, n_lights = queries.shape[:2]
    maps = canonical_white / jnp.maximum(estimates, 1e-12)  # (O, L, 3)
    corrected = queries * maps[:, :, None, None, :]
    usable = _dark_mask(queries, dark)
    histograms = jax.vmap(jax.vmap(rg_histogram))(corrected, usable).reshape(n_objects * n_lights, BINS, BINS)
    truth = jnp.repeat(jnp.arange(n_objects), n_lights)
    ranks = correct_ranks(intersection(histograms, database_histograms), truth)
    errors = rg_error(estimates, jnp.broadcast_to(whites[None], estimates.shape)).reshape(-1)
    return ranks, errors


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
            11 lights; the defaults: a synthetic version with 50 objects of 8 reflectances, 20 lights).
        noise: image noise (variance ``a * rho + b``), or None.
        preprocessing, dark: the image pipeline's settings for surface-list methods.
        fit: ``fit(label, world) -> estimator`` (default :func:`ccjax.runs.store.fit`).
        progress: show a progress bar over methods.

    Returns:
        :class:`IndexingResult`.
    """
    from tqdm.auto import tqdm

    from ccjax.runs import store

    if not 1 <= n_lights <= world.test_illuminants.shape[0]:
        raise ValueError(f"n_lights: expected 1 .. {world.test_illuminants.shape[0]}, got {n_lights}")
    if not 1 <= n_surfaces <= world.reflectances.shape[0]:
        raise ValueError(f"n_surfaces: expected 1 .. {world.reflectances.shape[0]}, got {n_surfaces}")
    fit = fit or store.fit
    rendered = render_objects(key, world, n_objects, n_surfaces, n_lights, size, noise)
    database_histograms = jax.vmap(rg_histogram)(rendered.database, _dark_mask(rendered.database, dark))
    queries = np.asarray(rendered.queries)
    whites = rendered.query_whites
    result = IndexingResult(n_queries=n_objects * n_lights)
    for label in tqdm(list(methods), desc="methods", disable=not progress):
        if label == "ACTUAL":
            estimates = np.broadcast_to(np.asarray(whites)[None], (n_objects, n_lights, 3))
        else:
            flat, _ = _estimates(fit(label, world), queries, preprocessing, dark)
            estimates = flat.reshape(n_objects, n_lights, 3)
        ranks, errors = _scores(
            rendered.queries, whites, jnp.asarray(estimates), world.canonical_white, database_histograms, dark
        )
        (s1, s2, s3), (n1, n2, n3) = rank_scores(ranks)
        rms = float(np.sqrt(np.mean(np.asarray(errors, np.float64) ** 2)))
        result.rows[label] = {"rg_error": rms, "score1": s1, "score2": s2, "score3": s3, "n1": n1, "n2": n2, "n3": n3}
    return result
