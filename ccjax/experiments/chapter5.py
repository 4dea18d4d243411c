"""The chapter-5 experiment engine (Barnard 1999 §5.4, §5.7): every method under every
sharpening on the same scenes, with the RGB mapping error over the whole reflectance set, the
angular error and the revert counts of §5.2.

Scenes are drawn by :func:`ccjax.scenes.draw_scenes` (the one scene-drawing function), so they are
those of a matte sweep with the same key and scene size. The Table 5.1 protocol and the summaries
of ``ccjax sharpen`` are in :mod:`ccjax.experiments.chapter5_report`.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int, PRNGKeyArray

from ccjax import metrics
from ccjax.precision import matmul
from ccjax.scenes import draw_scenes, sweep_keys
from ccjax.sharpening import (
    ADAPTATION_TRANSFORMS,
    THESIS_SCALE,
    EstimatorFit,
    NewSharpening,
    Sharpened,
    adaptation_sharpening,
    average_sharpening,
    best_diagonal_map,
    best_linear_error,
    database_responses,
    estimator_fit,
    mapping_error,
    new_sharpening,
    optimal_sharpening,
    sharpened,
)
from ccjax.world import World

SHARPENINGS = ("none", "opt", "ave", "new")
"""The sharpenings of Table 5.1: none, per-scene database ("opt"), average database ("ave") and
the new method ("new", §5.3)."""

ADAPTATIONS = {name.lower(): name for name in ADAPTATION_TRANSFORMS}
"""More sharpenings :func:`chapter5_errors` compares (not in Table 5.1): the standard chromatic
adaptation transforms (:func:`ccjax.sharpening.adaptation_sharpening`), by their lower-case names."""


class Chapter5Scenes(eqx.Module):
    """Scenes of Barnard 1999 §5.7 by index: the light (into the world's test illuminants) and
    the surfaces.

    Drawn by :func:`ccjax.scenes.draw_scenes` from the keys :func:`ccjax.scenes.sweep_keys` gives,
    so scene ``k`` has the same light and surfaces as scene ``k`` of a matte sweep with the same
    key and size (and as ``ccjax.scenes.sample`` with the stream's key).
    """

    light: Int[Array, " B"]
    surfaces: Int[Array, "B P"]

    @classmethod
    def draw(
        cls, key: PRNGKeyArray, n_lights: int, n_reflectances: int, n_scenes: int, n_surfaces: int
    ) -> Chapter5Scenes:
        """Scenes ``0 .. n_scenes - 1`` of the ``n_surfaces`` stream of ``key``.

        Arguments:
            key: the experiment's key.
            n_lights: lights to draw from; ``n_reflectances`` reflectances to draw from.
            n_scenes: number of scenes; ``n_surfaces`` surfaces per scene.

        Returns:
            The scenes' indices.
        """
        drawn = draw_scenes(sweep_keys(key, n_surfaces, 0, n_scenes), n_lights, n_reflectances, n_surfaces)
        return cls(light=drawn.light, surfaces=drawn.surfaces)


class Chapter5Data(eqx.Module):
    """Everything the chapter-5 errors (Barnard 1999 §5.7) need from a world: the database under
    every test light."""

    database: Float[Array, "J S 3"]
    canonical: Float[Array, "S 3"]
    whites: Float[Array, "J 3"]
    canonical_white: Float[Array, " 3"]

    @classmethod
    def of(cls, world: World) -> Chapter5Data:
        """The data of ``world`` (database under its test lights, canonical responses, whites)."""
        return cls(
            database=database_responses(world, world.test_illuminants),
            canonical=world.canonical_rgb,
            whites=world.test_whites,
            canonical_white=world.canonical_white,
        )


def _scene_error(data: Chapter5Data, light, transform, illuminant):
    """Mapping error (unit scale) and angle of an estimate ``illuminant`` in camera space, with the
    sharpened map ``d# = (w_c T) / (e T)`` (§5.4)."""
    sharp_map = matmul(data.canonical_white, transform) / matmul(illuminant, transform)
    error = mapping_error(data.database[light], data.canonical, transform, sharp_map)
    return error, metrics.angular_error(illuminant, data.whites[light])


@eqx.filter_jit
def _run_fixed(model, data: Chapter5Data, scenes: Chapter5Scenes, transform):
    def one(light, surfaces):
        rgb = data.database[light, surfaces]
        mask = jnp.ones(surfaces.shape, bool)
        if isinstance(model, Sharpened):
            result, reverted = model.estimate_and_revert(rgb, mask)
        else:
            result = model(rgb, mask)
            reverted = jnp.asarray(False)
        error, angle = _scene_error(data, light, transform, result.illuminant)
        return error, angle, reverted

    return jax.vmap(one)(scenes.light, scenes.surfaces)


def _run_comparison(kind: str, data: Chapter5Data, scenes: Chapter5Scenes, transforms):
    """BEST-LINEAR / BEST-DIAGONAL / ACTUAL (§5.7) with one transform per scene."""

    def one(light, transform):
        source, target = data.database[light], data.canonical
        truth = data.whites[light]
        if kind == "BEST-LINEAR":
            return best_linear_error(source, target), jnp.nan
        if kind == "BEST-DIAGONAL":
            sharp_map = best_diagonal_map(source, target, transform)
            estimate = matmul(matmul(data.canonical_white, transform) / sharp_map, jnp.linalg.inv(transform))
        else:  # ACTUAL: the true white in sharpened space
            sharp_map = matmul(data.canonical_white, transform) / matmul(truth, transform)
            estimate = truth
        return mapping_error(source, target, transform, sharp_map), metrics.angular_error(estimate, truth)

    error, angle = jax.jit(jax.vmap(one))(scenes.light, transforms)
    return error, angle, jnp.zeros(error.shape, bool)


COMPARISONS = ("BEST-LINEAR", "BEST-DIAGONAL", "ACTUAL")


def _run_per_scene(label: str, world: World, data, scenes, transforms, plain):
    """An estimator under a different ``T`` per scene ("opt"): traced through ``vmap`` when the
    estimator's fit is plain JAX, else refitted once per distinct light (gamut mapping uses Qhull)."""

    def one(light, surfaces, transform):
        model = sharpened(label, transform, world, plain=plain)
        rgb = data.database[light, surfaces]
        result, reverted = model.estimate_and_revert(rgb, jnp.ones(surfaces.shape, bool))
        error, angle = _scene_error(data, light, transform, result.illuminant)
        return error, angle, reverted

    try:
        return jax.jit(jax.vmap(one))(scenes.light, scenes.surfaces, transforms)
    except (
        jax.errors.ConcretizationTypeError,
        jax.errors.TracerArrayConversionError,
        jax.errors.TracerBoolConversionError,
    ):
        pass
    lights = np.asarray(scenes.light)
    n = lights.shape[0]
    error, angle, reverted = np.zeros(n), np.zeros(n), np.zeros(n, bool)
    for light in np.unique(lights):
        rows = np.flatnonzero(lights == light)
        transform = transforms[rows[0]]
        model = sharpened(label, transform, world, plain=plain)
        subset = Chapter5Scenes(light=scenes.light[rows], surfaces=scenes.surfaces[rows])
        e, a, r = _run_fixed(model, data, subset, transform)
        error[rows], angle[rows], reverted[rows] = e, a, r
    return error, angle, reverted


@dataclass
class Chapter5Result:
    """Per-scene chapter-5 errors: ``errors[(method, sharpening)] = (mapping, angle, reverted)``
    NumPy arrays, mapping errors on the unit scale. ``info`` holds the transforms' metadata."""

    n_scenes: int
    errors: dict = field(default_factory=dict)
    info: dict = field(default_factory=dict)

    def rows(self) -> list[dict]:
        """One summary row per (method, sharpening): RMS ``map_rgb`` (thesis units, None for
        NOTHING), RMS ``angular`` (None for BEST-LINEAR) and the ``reverted`` count."""
        out = []
        for (method, sharpening), (mapping, angle, reverted) in self.errors.items():
            out.append(
                {
                    "method": method,
                    "sharpening": sharpening,
                    "map_rgb": None if method == "NOTHING" else float(np.sqrt(np.mean(mapping**2))) * THESIS_SCALE,
                    "angular": None if method == "BEST-LINEAR" else float(np.sqrt(np.mean(angle**2))),
                    "reverted": int(np.sum(reverted)),
                }
            )
        return out


def chapter5_errors(
    world: World,
    methods: Sequence[str],
    sharpenings: Sequence[str] = SHARPENINGS,
    n_scenes: int = 1000,
    n_surfaces: int = 8,
    key=None,
    *,
    new: NewSharpening | None = None,
    progress: bool = False,
) -> Chapter5Result:
    """The chapter-5 protocol (Barnard 1999 §5.7): ``n_scenes`` scenes of ``n_surfaces`` surfaces under random
    test lights; every method under every sharpening; mapping error over the whole reflectance set
    and angular error per scene, and revert counts (§5.2).

    Arguments:
        world: normally :meth:`World.barnard1999`.
        methods: estimator labels and/or ``BEST-LINEAR``, ``BEST-DIAGONAL``, ``ACTUAL``.
        sharpenings: any of ``none``, ``opt`` (per-scene database sharpening with the true light),
            ``ave`` (database sharpening with the mean training light), ``new`` (§5.3), and the
            adaptation transforms ``bradford``, ``cat02``, ``cat16`` (:data:`ADAPTATIONS`).
        n_scenes, n_surfaces: the scenes (thesis: 1000 of 8 surfaces).
        key: PRNG key of the scenes (default ``jax.random.key(0)``).
        new: a precomputed :func:`ccjax.sharpening.new_sharpening` result (computed if needed
            and not given).
        progress: print each (method, sharpening) as it finishes.

    Returns:
        :class:`Chapter5Result`.
    """
    unknown = [s for s in sharpenings if s not in SHARPENINGS and s not in ADAPTATIONS]
    if unknown:
        raise ValueError(f"sharpenings: unknown {unknown}; expected some of {SHARPENINGS + tuple(ADAPTATIONS)}")
    if not isinstance(n_scenes, int) or n_scenes < 1:
        raise ValueError(f"n_scenes: expected a positive integer, got {n_scenes!r}")
    from ccjax.estimators import registry

    key = jax.random.key(0) if key is None else key
    data = Chapter5Data.of(world)
    dtype = data.canonical.dtype
    scenes = Chapter5Scenes.draw(key, data.database.shape[0], data.database.shape[1], n_scenes, n_surfaces)
    result = Chapter5Result(n_scenes=n_scenes)
    fixed = {"none": np.eye(3)}
    if "ave" in sharpenings:
        fixed["ave"] = average_sharpening(world)
    if "new" in sharpenings:
        new = new_sharpening(world) if new is None else new
        fixed["new"] = new.transform
        result.info["new"] = new
    for name in ADAPTATIONS.keys() & set(sharpenings):
        fixed[name] = np.asarray(adaptation_sharpening(world, ADAPTATIONS[name]))
    if "opt" in sharpenings:
        per_light = jnp.asarray(optimal_sharpening(world), dtype)
    for name, t in fixed.items():
        result.info[f"T_{name}"] = np.asarray(t)
    plain_models = {}
    for method in methods:
        for sharpening in sharpenings:
            if method in ("BEST-LINEAR", "NOTHING") and sharpening != "none":
                continue  # invariant to sharpening / no mapping error (§5.7)
            start = time.perf_counter()
            if sharpening == "opt":
                transforms = per_light[scenes.light]
            else:
                transforms = jnp.broadcast_to(jnp.asarray(fixed[sharpening], dtype), (n_scenes, 3, 3))
            if method in COMPARISONS:
                out = _run_comparison(method, data, scenes, transforms)
            else:
                if method not in plain_models:
                    plain_models[method] = registry.fit(method, world)
                plain = plain_models[method]
                if sharpening == "none":
                    out = _run_fixed(plain, data, scenes, transforms[0])
                elif sharpening == "opt":
                    out = _run_per_scene(method, world, data, scenes, transforms, plain)
                else:
                    model = sharpened(method, fixed[sharpening], world, plain=plain)
                    out = _run_fixed(model, data, scenes, transforms[0])
            result.errors[(method, sharpening)] = tuple(np.asarray(x) for x in out)
            if progress:
                print(f"  {method:<14}{sharpening:<6}{time.perf_counter() - start:6.1f} s", flush=True)
    return result


def evaluate_transforms(
    world: World,
    label: str | EstimatorFit,
    transforms: dict,
    n_scenes: int = 1000,
    n_surfaces: int = 8,
    key=None,
    *,
    requires_positive: bool | None = None,
) -> dict:
    """RMS chapter-5 mapping error (thesis units), RMS angular error and revert count of an
    estimator (label or ``fit(world)``) under each named transform, on the same held-out scenes
    under the world's *test* lights (the protocol of Barnard 1999 §5.7).

    Arguments:
        world: the world.
        label: a registry label or ``fit(world) -> estimator``.
        transforms: ``{name: (3, 3) T}``.
        n_scenes, n_surfaces: the scenes; ``key`` their PRNG key (default ``jax.random.key(0)``).
        requires_positive: the revert policy of :func:`ccjax.sharpening.sharpened`.

    Returns:
        ``{name: {"map_rgb", "angular", "reverted"}}``.
    """
    key = jax.random.key(0) if key is None else key
    data = Chapter5Data.of(world)
    scenes = Chapter5Scenes.draw(key, data.database.shape[0], data.database.shape[1], n_scenes, n_surfaces)
    plain = estimator_fit(label)(world)
    out = {}
    for name, transform in transforms.items():
        t = jnp.asarray(transform, data.canonical.dtype)
        model = sharpened(label, t, world, plain=plain, requires_positive=requires_positive)
        mapping, angle, reverted = _run_fixed(model, data, scenes, t)
        out[name] = {
            "map_rgb": float(jnp.sqrt(jnp.mean(mapping**2))) * THESIS_SCALE,
            "angular": float(jnp.sqrt(jnp.mean(angle**2))),
            "reverted": int(jnp.sum(reverted)),
        }
    return out
