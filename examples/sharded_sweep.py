"""A synthetic sweep sharded over a device mesh (docs/training.md): the scene axis of every chunk is split
across the devices with ``jax.sharding``; the per-scene errors must agree with the one-device run to
1e-6 (relative for errors above 1, absolute below: the statistics of a group of models are one
program, which XLA partitions, and so rounds, otherwise; an (r,g) error of 2.7e-4 computed from
chromaticities near 0.3 moves by 2e-8, 7e-5 of itself), and the example prints scenes/s per device
count.

On a CPU the devices are forced host devices (``XLA_FLAGS=--xla_force_host_platform_device_count=4``,
set here before JAX starts when it is not set already); they share the machine's cores, so on CPU
the speed-up is not the point, the agreement is. On accelerators the same code uses real devices.

The mesh is :func:`ccjax.runs.hosts.item_mesh` (one axis, ``"items"``, devices in process order),
the mesh every ccjax run shards its item axis over. This example runs one process; across processes
(``jax.distributed``, started by :func:`ccjax.runs.hosts.initialize_from_environment` from
``JAX_COORDINATOR_ADDRESS``, ``JAX_NUM_PROCESSES`` and ``JAX_PROCESS_ID``) the mesh spans every
process's devices, each process puts its own block of a chunk's scene keys on it
(:func:`ccjax.runs.hosts.shard_items`; scene ``i`` is a pure function of its key, so no data moves
between hosts but the collected errors, :func:`ccjax.runs.hosts.global_value`); see
``tests/distributed_worker.py``.

Run: ``python examples/sharded_sweep.py [--scenes 20000] [--devices 1,2,4]``; ``--quick``: 1,024 scenes.
"""

from __future__ import annotations

import os

if "--xla_force_host_platform_device_count" not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=4").strip()

import argparse
import time

import jax
import numpy as np

from ccjax.experiments import sweep
from ccjax.runs import hosts, store
from ccjax.world import World

METHODS = ("GW", "shades-of-grey-p6", "soft-RETINEX-t0.01", "C-by-C-MMSE")


def run(world: World, methods: list, n_devices: int, n_scenes: int, n_surfaces: int) -> tuple[dict, float]:
    """One sweep on a mesh of the first ``n_devices`` devices; per-method errors and seconds (warm).

    ``methods`` are ``(label, fitted model)`` pairs, fitted once: the warm-up and the timed sweep get
    the same model objects and so share one compiled chunk."""
    mesh = hosts.item_mesh(jax.devices()[:n_devices])

    def once(count: int):
        return sweep(
            world, methods, [n_surfaces], count, key=jax.random.key(0), mesh=mesh, progress=False, chunk_size=1024
        )

    once(1024)  # compile once, outside the timing
    start = time.perf_counter()
    result = once(n_scenes)
    return result.errors, time.perf_counter() - start


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").strip().split("\n")[0])
    parser.add_argument("--scenes", type=int, default=20000)
    parser.add_argument("--surfaces", type=int, default=8)
    parser.add_argument("--devices", default="1,2,4", help="device counts to compare (the first is the reference)")
    parser.add_argument(
        "--quick", action="store_true", help="1,024 scenes (one compiled chunk), 1 and 4 devices (smoke test)"
    )
    args = parser.parse_args(argv)
    if args.quick:
        args.scenes, args.devices = 1024, "1,4"
    counts = [int(n) for n in args.devices.split(",")]
    if max(counts) > len(jax.devices()):
        raise SystemExit(f"--devices: only {len(jax.devices())} devices (set XLA_FLAGS before starting Python)")
    world = World.default()
    methods = [(label, store.fit(label, world)) for label in METHODS]
    print(f"{len(jax.devices())} {jax.devices()[0].platform} devices; {args.scenes} scenes of {args.surfaces} surfaces")
    reference, worst = None, 0.0
    print(f"{'devices':>8}{'seconds':>10}{'scenes/s':>12}{'max diff':>16}")
    for count in counts:
        errors, seconds = run(world, methods, count, args.scenes, args.surfaces)
        if reference is None:
            reference, difference = errors, 0.0
        else:
            difference = 0.0
            for method in METHODS:
                for name, values in errors[method][args.surfaces].items():
                    if name == "ok":
                        assert np.array_equal(values, reference[method][args.surfaces][name]), (method, count)
                        continue
                    expected = reference[method][args.surfaces][name]
                    scale = np.maximum(np.abs(expected), 1.0)
                    difference = max(difference, float(np.max(np.abs(values - expected) / scale)))
        worst = max(worst, difference)
        print(f"{count:>8}{seconds:>10.2f}{args.scenes / seconds:>12.0f}{difference:>16.2e}")
    verdict = "agree" if worst <= 1e-6 else "DISAGREE"
    print(f"sharded and unsharded per-scene errors {verdict} to {worst:.1e} (relative above 1, target 1e-6)")
    return 0 if worst <= 1e-6 else 1


if __name__ == "__main__":
    raise SystemExit(main())
