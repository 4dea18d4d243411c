"""One sweep over many cameras at once: ``jax.vmap`` over the cameras' sensor curves for the estimators
whose fit is traceable (the registry's ``traceable_fit``: fit, scenes and errors are one pure
function of the sensors), a Python loop with cached fits (``registry.fit_cached``) for the rest.

Every camera sees the same world (the default world's reflectances and lights, each light
normalised for that camera as ``World`` does) and the same scene keys, so the table compares
cameras, not draws.

Run: ``python examples/camera_sweep.py [--scenes 2000] [--surfaces 8] [--cameras N]``; ``--quick``:
4 cameras, 256 scenes, one looped method.
"""

from __future__ import annotations

import argparse
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ccjax import cameras, losses
from ccjax.camera import Camera
from ccjax.estimators import registry
from ccjax.scenes import SceneTables, sample_batch, scene_keys
from ccjax.world import World

TRACEABLE = ("GW", "DB-GW", "shades-of-grey-p6", "soft-RETINEX-t0.01", "MAX-RGB")
LOOPED = ("C-by-C-MMSE", "ECRULE-MV")


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
    """Per-scene angular errors of ``model`` on the scenes of ``keys`` in ``world``."""
    scenes = sample_batch(keys, SceneTables.from_world(world), n_surfaces)
    estimate = jax.vmap(model)(scenes.rgb, scenes.mask).illuminant
    return losses.angular_errors(estimate, scenes.illuminant)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", type=int, default=2000)
    parser.add_argument("--surfaces", type=int, default=8)
    parser.add_argument("--cameras", type=int, default=None, help="first N embedded cameras (default: all)")
    parser.add_argument("--quick", action="store_true", help="4 cameras, 256 scenes, one looped method")
    args = parser.parse_args(argv)
    looped = LOOPED
    if args.quick:
        args.cameras, args.scenes, looped = 4, 256, LOOPED[:1]
    names = [name for name, source in cameras().items() if source.startswith("embedded")][: args.cameras]
    for label in TRACEABLE:
        assert registry.lookup(label)[0].traceable_fit, label
    base = World.default()
    sensors = jnp.stack([Camera.from_name(name).sensors for name in names])
    keys = scene_keys(jax.random.key(0), 0, args.scenes)

    @jax.jit
    def sweep_all(sensors):
        def one_camera(sensors):
            world = camera_world(base, sensors)
            return {label: scene_angles(registry.fit(label, world), world, keys, args.surfaces) for label in TRACEABLE}

        return jax.vmap(one_camera)(sensors)

    start = time.perf_counter()
    errors = {label: np.asarray(value) for label, value in sweep_all(sensors).items()}
    vmapped_seconds = time.perf_counter() - start
    start = time.perf_counter()
    for label in looped:
        rows = []
        for index in range(len(names)):
            world = camera_world(base, sensors[index])
            rows.append(np.asarray(scene_angles(registry.fit_cached(label, world), world, keys, args.surfaces)))
        errors[label] = np.stack(rows)
    looped_seconds = time.perf_counter() - start

    labels = [*TRACEABLE, *looped]
    print(f"median angular error (degrees), {args.scenes} scenes of {args.surfaces} surfaces per camera")
    print(f"{'camera':<34}" + "".join(f"{label[:12]:>13}" for label in labels))
    for index, name in enumerate(names):
        print(f"{name[:33]:<34}" + "".join(f"{np.median(errors[label][index]):>13.3f}" for label in labels))
    print(
        f"\n{len(TRACEABLE)} traceable methods x {len(names)} cameras in one vmapped, jitted call: "
        f"{vmapped_seconds:.1f} s (with compilation); {len(looped)} looped with cached fits: {looped_seconds:.1f} s"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
