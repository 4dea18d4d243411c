"""Pretraining from spectra: training images rendered with a camera's spectral curves, prepared as
photographs are, a learned estimator trained on them, then refined on photographs.

The renderer draws Mondrians (:func:`ccjax.scenes.sample_mondrians`: the world's SFU reflectances
under its test illuminants, per-patch shading, dielectric highlights of §4.7, shot noise), at the
photographs' thumbnail size so that FFCC's edge channel sees edges; each image is exposed by a
random gain, clipped at saturation and quantised to the 16-bit codes of the development sets, and
becomes a :class:`ccjax.io.LinearImage` with the reader's clip rule, so
:func:`ccjax.preprocessing.prepare_input` makes the estimator's input exactly as it does for a
photograph (Barnard 1999 §4.6-§4.7 for the scenes and preprocessing).

Lights: photographs are lit along the Planckian locus (daylight, tungsten), so only the world's
test illuminants whose camera log-chroma lies within :attr:`Pretraining.locus` of the camera's
Planckian locus (2000-20000 K blackbodies) are drawn (:func:`planckian_lights`): the default
world's CIE daylights, blackbodies, the LEDs and mixtures near it; fluorescents off the locus are
left out.

:func:`pretrain` trains the family's start on the rendered set (FFCC: its L-BFGS fit; the Colour
by Correlation matrices: the Adam loop), and :func:`fine_tune` refines a pretrained model on
photographs (:func:`ccjax.training.train_model` with ``fine_tune``: FFCC's regulariser centred on
the pretrained model, the Adam loop started from it).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from ccjax import limits
from ccjax._cache import content_key
from ccjax._entries import Expect, read_arrays, write_arrays
from ccjax.estimators.base import AbstractEstimator
from ccjax.io.reading import LinearImage
from ccjax.preprocessing import DEFAULT_DARK, Preprocessing, prepare_input
from ccjax.runs import store
from ccjax.scenes import SceneTables, ShotNoise, Specular, mondrian_batch, scene_keys
from ccjax.spectra import WAVELENGTHS
from ccjax.training._data import Examples, stack_inputs
from ccjax.training._loop import Schedule, TrainingLog
from ccjax.training._procedures import train_model
from ccjax.world import World

__all__ = [
    "CODES",
    "Pretraining",
    "fine_tune",
    "planckian_lights",
    "planckian_locus",
    "pretrain",
    "render_examples",
    "render_images",
]

CODES = 64224
"""16-bit code of the saturation level (the development sets' ``--saturation``): rendered images
are quantised to these steps, as the photographs were."""

CHUNK = 128
"""Images rendered per compiled call (the highlight blobs take ``H * W * patches`` values an image)."""

SECOND_RADIATION = 1.4388e-2
"""Planck's second radiation constant ``c2 = h c / k``, in m K."""


@dataclass(frozen=True)
class Pretraining:
    """What to render and how.

    Attributes:
        camera: the embedded camera whose curves render the images (e.g. ``"Canon EOS 600D"``).
        images: rendered training images.
        height, width: their size (the photographs' thumbnails: 64 x 64).
        patches: Mondrian patches per image (distinct reflectances).
        locus: largest log-chroma distance of a light from the camera's Planckian locus.
        exposure: range of ``log2`` of the exposure gain applied to the image normalised to a
            brightest value of 1 (above 0: the brightest pixels clip at saturation).
        noise: the shot-noise model on the unit scale.
        specular: the highlights (thesis recipe: a quarter of the patches, up to twice the white).
        seed: the renderer's seed (and the world's).
    """

    camera: str
    images: int = 2000
    height: int = 64
    width: int = 64
    patches: int = 24
    locus: float = 0.12
    exposure: tuple[float, float] = (-1.0, 1.0)
    noise: ShotNoise = field(default_factory=lambda: ShotNoise(a=5e-5, b=1e-7))
    specular: Specular = field(default_factory=Specular)
    seed: int = 0

    def __post_init__(self):
        for name in ("images", "height", "width", "patches"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name}: expected a positive integer, got {value!r}")
        limits.require_count(self.images, "images", 1, limits.RENDERED_IMAGES)
        if not self.locus > 0:
            raise ValueError(f"locus: expected a positive log-chroma distance, got {self.locus!r}")
        low, high = self.exposure
        if not low <= high:
            raise ValueError(f"exposure: expected (low, high) with low <= high, got {self.exposure!r}")


def planckian_locus(world: World, kelvin: Float[np.ndarray, " T"] | None = None) -> Float[np.ndarray, "T 2"]:
    """The camera log-chroma ``(log(G/R), log(G/B))`` of blackbodies (Planck's law on the
    wavelength grid, ``lambda^-5 / (exp(c2 / (lambda T)) - 1)``).

    Arguments:
        world: the world whose camera sees them.
        kelvin: colour temperatures (default 2000-20000 K in 50 K steps).

    Returns:
        ``(T, 2)`` the locus, one point per temperature.
    """
    kelvin = np.arange(2000.0, 20000.0 + 1, 50.0) if kelvin is None else np.asarray(kelvin, np.float64)
    metres = WAVELENGTHS * 1e-9
    radiance = metres[None, :] ** -5 / np.expm1(SECOND_RADIATION / (metres[None, :] * kelvin[:, None]))
    return _log_chroma(radiance @ np.asarray(world.camera.sensors, np.float64))


def _log_chroma(rgb: np.ndarray) -> np.ndarray:
    return np.stack([np.log(rgb[:, 1] / rgb[:, 0]), np.log(rgb[:, 1] / rgb[:, 2])], axis=-1)


def planckian_lights(world: World, locus: float) -> World:
    """``world`` with only the test illuminants near the camera's Planckian locus (module docstring).

    Arguments:
        world: the world.
        locus: largest log-chroma distance from :func:`planckian_locus`.

    Returns:
        The world with those test illuminants.

    Raises:
        ValueError: no test illuminant is that near the locus.
    """
    whites = np.asarray(world.test_illuminants, np.float64) @ np.asarray(world.camera.sensors, np.float64)
    points = _log_chroma(whites)
    curve = planckian_locus(world)
    distance = np.min(np.linalg.norm(points[:, None, :] - curve[None, :, :], axis=-1), axis=1)
    keep = np.flatnonzero(distance <= locus)
    if keep.size == 0:
        raise ValueError(f"locus: no test illuminant of {world.name} lies within {locus} of the Planckian locus")
    return eqx.tree_at(lambda w: w.test_illuminants, world, world.test_illuminants[keep])


def render_images(
    pretraining: Pretraining, world: World | None = None, *, progress: bool = False
) -> tuple[Float[Array, "N H W 3"], Bool[Array, "N H W"], Float[Array, "N 3"]]:
    """The rendered photographs (module docstring), as the reader returns photographs.

    Arguments:
        pretraining: what to render.
        world: the world to render from (default: the camera's default world, :func:`ccjax.runs.store.world`).
        progress: a progress bar over the images rendered.

    Returns:
        ``(rgb (N, H, W, 3), clipped (N, H, W), lights (N, 3))``: linear RGB on the unit scale
        (1.0 = saturation) quantised to :data:`CODES` steps, the reader's clip rule (a channel at
        saturation), and the camera RGB of a white under each image's light.
    """
    p = pretraining
    world = store.world("default", p.camera, seed=p.seed) if world is None else world
    world = planckian_lights(world, p.locus)
    if p.patches > world.reflectances.shape[0]:
        raise ValueError(f"patches: the world has {world.reflectances.shape[0]} reflectances, got {p.patches}")
    tables = SceneTables.from_world(world)
    key_scenes, key_exposure = jax.random.split(jax.random.PRNGKey(p.seed))
    from tqdm.auto import tqdm

    images, lights = [], []
    bar = tqdm(total=p.images, desc="render", unit="image", disable=not progress, leave=False)
    for start in range(0, p.images, CHUNK):
        keys = scene_keys(key_scenes, start, min(CHUNK, p.images - start))
        # Image i is a function of fold_in(key, i) alone: the set does not depend on CHUNK.
        scenes = mondrian_batch(keys, tables, p.height, p.width, p.patches, specular=p.specular, noise=p.noise)
        images.append(scenes.image)
        lights.append(scenes.illuminant)
        bar.update(len(keys))
    bar.close()
    image = jnp.concatenate(images)
    gain = 2.0 ** jax.random.uniform(key_exposure, (p.images, 1, 1, 1), minval=p.exposure[0], maxval=p.exposure[1])
    # The sensor saturates at 1, then the converter keeps whole codes of the 16-bit file.
    rgb = jnp.round(jnp.minimum(image * gain, 1.0) * CODES) / CODES
    return rgb, jnp.any(rgb >= 1.0, axis=-1), jnp.concatenate(lights) * gain[:, 0, 0]


def render_examples(
    pretraining: Pretraining,
    rule: Preprocessing,
    input_kind: str,
    *,
    dark: float = DEFAULT_DARK,
    progress: bool = False,
) -> Examples:
    """Rendered training examples prepared by ``rule`` (as :func:`ccjax.training.source_examples`
    prepares photographs), cached on disk by everything they depend on.

    Arguments:
        pretraining: what to render.
        rule: the resolved input rule of the estimator (:func:`ccjax.preprocessing.resolve`).
        input_kind: the estimator's input kind (``"surfaces"`` or ``"image"``).
        dark: the surface lists' dark rule.
        progress: progress bars over the images rendered and prepared (not when cached).

    Returns:
        The :class:`Examples` (names ``synthetic-<i>``).
    """
    key = content_key("pretraining", asdict(pretraining), rule.name, input_kind, dark)
    facts = {"pretraining": repr(pretraining), "rule": rule.name, "input_kind": input_kind, "dark": dark}
    n, axes = pretraining.images, (None, None) if input_kind == "image" else (None,)
    layout = {
        "x": Expect((n, *axes, 3), "f"),
        "mask": Expect((n, *axes), "b"),
        "illuminant": Expect((n, 3), "f", 0.0),
    }
    stored = read_arrays("pretraining", key, layout, facts)
    if stored is None or stored["mask"].shape != stored["x"].shape[:-1]:
        from tqdm.auto import tqdm

        rgb, clipped, lights = (np.asarray(a) for a in render_images(pretraining, progress=progress))
        prepared = tqdm(range(len(rgb)), desc="prepare", unit="image", disable=not progress, leave=False)
        inputs = [prepare_input(rule, LinearImage(rgb[i], clipped[i]), dark=dark) for i in prepared]
        x, mask = stack_inputs([a for a, _ in inputs], [m for _, m in inputs], input_kind)
        stored = {"x": x, "mask": mask, "illuminant": lights.astype(np.float32)}
        write_arrays("pretraining", key, stored, facts)
    names = tuple(f"synthetic-{i}" for i in range(len(stored["x"])))
    return Examples(jnp.asarray(stored["x"]), jnp.asarray(stored["mask"]), jnp.asarray(stored["illuminant"]), names)


def pretrain(
    start: AbstractEstimator,
    pretraining: Pretraining,
    rule: Preprocessing,
    schedule: Schedule | None = None,
    *,
    progress: bool = False,
) -> tuple[AbstractEstimator, TrainingLog]:
    """Train ``start`` on rendered images (its family's procedure,
    :func:`ccjax.training.train_model`).

    Arguments:
        start: the fitted, trainable start (e.g. FFCC untrained, or the Colour by Correlation
            matrices fitted to the camera's world).
        pretraining: what to render.
        rule: the start's resolved input rule.
        schedule: the Adam loop's schedule (families with their own solver ignore it).
        progress: progress bars.

    Returns:
        ``(pretrained model, its TrainingLog)``.
    """
    examples = render_examples(pretraining, rule, start.input_kind, progress=progress)
    return train_model(start, examples, schedule, progress=progress)


def fine_tune(
    pretrained: AbstractEstimator, examples: Examples, schedule: Schedule | None = None, *, progress: bool = False
) -> tuple[AbstractEstimator, TrainingLog]:
    """Refine a pretrained model on photographs (:func:`ccjax.training.train_model` with
    ``fine_tune``: FFCC's regulariser centred on ``pretrained``; the Adam loop started from it).

    Arguments:
        pretrained: :func:`pretrain`'s model.
        examples: the photographs' training examples.
        schedule: the Adam loop's schedule.
        progress: progress bars.

    Returns:
        ``(fine-tuned model, its TrainingLog)``.
    """
    return train_model(pretrained, examples, schedule, progress=progress, fine_tune=True)
