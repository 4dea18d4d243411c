"""One sweep over many cameras at once: ``jax.vmap`` over the cameras' sensor curves for the estimators
whose fit is traceable (the registry's ``traceable_fit``: fit, scenes and errors are one pure
function of the sensors), a Python loop with cached fits (``ccjax.runs.store.fit``) for the rest.

Every camera sees the same world (the default world's reflectances and lights, each light
normalised for that camera as ``World`` does) and the same scene keys, so the table compares
cameras, not draws.

Memory and compilation are bounded the JAX way:

* every estimate goes through ``ccjax.estimators.base.estimate_batch`` inside ``jit`` (blocks of
  scenes ``lax.map``-ped for the gamut kernel); an eager ``vmap(model)`` of ECRULE-MV over 2000
  scenes materialises every stage of its search at once (measured: over 3.5 GB for one camera
  at 256 scenes, 24 GB for the whole sweep);
* the scenes are scored in chunks of ``--chunk`` keys, all of one shape, so each function
  compiles once;
* the gamut models of different cameras have different numbers of facets (88-97 top facets),
  which would recompile the kernel for every camera (about 9 s each); their facet lists are
  padded to one length by repeating a facet (a repeated half-space changes no intersection), so
  one compiled kernel serves every camera.

Run: ``python examples/camera_sweep.py [--scenes 2000] [--surfaces 8] [--cameras N]``; ``--quick``:
4 cameras, 256 scenes, one looped method.
"""

from __future__ import annotations

import argparse
import functools
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ccjax import cameras, metrics
from ccjax.camera import Camera
from ccjax.estimators import registry
from ccjax.estimators.base import estimate_batch
from ccjax.estimators.gamut import GamutMapping
from ccjax.runs import store
from ccjax.scenes import SceneTables, sample_batch, scene_keys
from ccjax.world import World

TRACEABLE = ("GW", "DB-GW", "shades-of-grey-p6", "soft-RETINEX-t0.01", "MAX-RGB")
LOOPED = ("C-by-C-MMSE", "ECRULE-MV")
# Half-space lists of a gamut model (GamutModel's attributes): repeating a row is harmless.
FACETS = ("origin_normals", "top_normals", "top_offsets", "illuminant_planes", "map_planes")


def camera_world(world: World, sensors: jax.Array) -> World:
    """``world`` seen by a camera with ``sensors``: the sensors swapped in, every illuminant rescaled
    so the brightest channel of its white is 1 (ccjax's scale), traceably."""

    def normalised(lights):
        return lights / jnp.max(lights @ sensors, axis=-1, keepdims=True)

    world = eqx.tree_at(lambda w: w.camera.sensors, world, sensors)
    return eqx.tree_at(
        lambda w: (w.train_illuminants, w.test_illuminants, w.canonical),
        world,
        (normalised(world.train_illuminants), normalised(world.test_illuminants), normalised(world.canonical[None])[0]),
    )


def scene_angles(model, world: World, keys, n_surfaces: int) -> jax.Array:
    """Per-scene angular errors of ``model`` on the scenes of ``keys`` in ``world`` (call under jit)."""
    scenes = sample_batch(keys, SceneTables.from_world(world), n_surfaces)
    estimate = estimate_batch(model, scenes.rgb, scenes.mask).illuminant
    return metrics.angular_error(estimate, scenes.illuminant)


def same_shapes(models: list) -> list:
    """Gamut models padded to common facet counts (the last facet repeated), so one compiled
    function scores them all; other models are returned unchanged."""
    if not all(isinstance(model, GamutMapping) for model in models):
        return models
    sizes = {name: max(getattr(model.model, name).shape[0] for model in models) for name in FACETS}

    def padded(model):
        rows = [getattr(model.model, name) for name in FACETS]
        rows = [
            jnp.concatenate([x, jnp.repeat(x[-1:], sizes[name] - x.shape[0], axis=0)]) for name, x in zip(FACETS, rows)
        ]
        return eqx.tree_at(lambda m: tuple(getattr(m.model, name) for name in FACETS), model, tuple(rows))

    return [padded(model) for model in models]


def chunked(score, keys, size: int) -> np.ndarray:
    """``score(keys_chunk) -> (size, ...)`` over ``keys`` in chunks of one shape (the last padded with
    repeated keys and trimmed), concatenated on the last (scene) axis."""
    n = keys.shape[0]
    padded = jnp.concatenate([keys, jnp.repeat(keys[-1:], -n % size, axis=0)])
    parts = [np.asarray(score(padded[start : start + size])) for start in range(0, padded.shape[0], size)]
    return np.concatenate(parts, axis=-1)[..., :n]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").strip().split("\n")[0])
    parser.add_argument("--scenes", type=int, default=2000)
    parser.add_argument("--surfaces", type=int, default=8)
    parser.add_argument("--cameras", type=int, default=None, help="first N embedded cameras (default: all)")
    parser.add_argument("--chunk", type=int, default=500, help="scenes per compiled call")
    parser.add_argument("--quick", action="store_true", help="4 cameras, 256 scenes, one looped method")
    args = parser.parse_args(argv)
    looped = LOOPED
    if args.quick:
        args.cameras, args.scenes, args.chunk, looped = 4, 256, 256, LOOPED[:1]
    if args.scenes < 1 or args.chunk < 1:
        raise SystemExit("--scenes and --chunk: expected positive integers")
    names = [name for name, source in cameras().items() if source.startswith("embedded")][: args.cameras]
    for label in TRACEABLE:
        assert registry.lookup(label)[0].traceable_fit, label
    base = World.default()
    sensors = jnp.stack([Camera.from_name(name).sensors for name in names])
    keys = scene_keys(jax.random.key(0), 0, args.scenes)
    chunk = min(args.chunk, args.scenes)

    @jax.jit
    def sweep_all(sensors, keys):
        def one_camera(sensors):
            world = camera_world(base, sensors)
            return jnp.stack(
                [scene_angles(registry.fit(label, world), world, keys, args.surfaces) for label in TRACEABLE]
            )

        return jax.vmap(one_camera)(sensors)  # (cameras, methods, scenes)

    @eqx.filter_jit
    def looped_angles(model, sensors, keys):
        return scene_angles(model, camera_world(base, sensors), keys, args.surfaces)

    start = time.perf_counter()
    table = chunked(lambda k: sweep_all(sensors, k), keys, chunk)
    errors = {label: table[:, index] for index, label in enumerate(TRACEABLE)}
    vmapped_seconds = time.perf_counter() - start
    start = time.perf_counter()
    for label in looped:
        fits = [store.fit(label, camera_world(base, sensors[index])) for index in range(len(names))]
        fits = same_shapes(fits)
        rows = [
            chunked(functools.partial(looped_angles, model, camera_sensors), keys, chunk)
            for model, camera_sensors in zip(fits, sensors)
        ]
        errors[label] = np.stack(rows)
    looped_seconds = time.perf_counter() - start

    labels = [*TRACEABLE, *looped]
    print(f"median angular error (degrees), {args.scenes} scenes of {args.surfaces} surfaces per camera")
    # Each column as wide as its label (labels such as ND-ECRULE-SCWIA-12 are longer than a number).
    widths = [max(len(label), 7) + 2 for label in labels]
    namewidth = max(len("camera"), *(len(name) for name in names)) + 1
    print(f"{'camera':<{namewidth}}" + "".join(f"{label:>{width}}" for label, width in zip(labels, widths)))
    for index, name in enumerate(names):
        cells = (f"{np.median(errors[label][index]):>{width}.3f}" for label, width in zip(labels, widths))
        print(f"{name:<{namewidth}}" + "".join(cells))
    print(
        f"\n{len(TRACEABLE)} traceable methods x {len(names)} cameras in one vmapped, jitted function: "
        f"{vmapped_seconds:.1f} s (with compilation); {len(looped)} looped with cached fits: {looped_seconds:.1f} s"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
