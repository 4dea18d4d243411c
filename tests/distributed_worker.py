"""One process of the scale-out tests (tests/test_distributed.py): a synthetic sweep of two methods,
an image evaluation of a folder and data-parallel training, run in one of three ways:

* ``--role reference``: one process, one device, the library's own unsharded entry points
  (``sweep``, ``run_images`` on every file, ``fit_to_examples`` without a mesh, a plain gradient);
* ``--role mesh``: one process whose (forced) host devices form the mesh;
* ``--role process --process-id i --processes n --port p``: process ``i`` of ``n`` under
  ``jax.distributed`` (CPU collectives): each process samples its share of the scenes and reads its
  share of the image files, results are pooled with ``ccjax.runs.hosts``.

Every role writes ``<out>/<role><i>.npz`` (the pooled per-item results) and ``<out>/<role><i>.json``
(the files this process opened, seen by an audit hook on ``open``, and the images whose pixels it
decoded).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

SCENES = 51  # odd, so the processes' shares differ in length
SURFACES = 8
CHUNK = 16  # scenes per chunk of the mesh sweep (a multiple of the device count)
METHODS = ("GW", "RETINEX")
N_TRAIN, N_VALID, BATCH = 16, 8, 8
LEARNER = "C-by-C-MMSE"
INIT_FAILED = 77  # exit status: jax.distributed cannot start here (the test skips)


def parse(argv):
    parser = argparse.ArgumentParser()
    parser.add_argument("--role", choices=("reference", "mesh", "process"), required=True)
    parser.add_argument("--process-id", type=int, default=0)
    parser.add_argument("--processes", type=int, default=1)
    parser.add_argument("--port", type=int, default=0)
    parser.add_argument("--images", required=True, help="folder with groundtruth.csv")
    parser.add_argument("--out", required=True)
    return parser.parse_args(argv)


def main(argv=None) -> int:
    args = parse(argv)
    opened: list[str] = []
    folder = str(Path(args.images).resolve())

    def audit(event, details):
        if event == "open" and isinstance(details[0], str) and os.path.abspath(details[0]).startswith(folder):
            opened.append(Path(details[0]).name)

    sys.addaudithook(audit)

    import jax

    if args.role == "process":
        # What `hosts.initialize_from_environment` does with JAX_COORDINATOR_ADDRESS,
        # JAX_NUM_PROCESSES and JAX_PROCESS_ID set.
        from ccjax.runs import hosts

        environment = {
            "JAX_COORDINATOR_ADDRESS": f"localhost:{args.port}",
            "JAX_NUM_PROCESSES": str(args.processes),
            "JAX_PROCESS_ID": str(args.process_id),
        }
        try:
            started = hosts.initialize_from_environment(environment)
            count = jax.process_count()  # starts the backend: gloo's cross-process setup
        except Exception as error:  # the platform cannot run JAX processes together
            print(f"jax.distributed: {type(error).__name__}: {error}".replace("\n", " "), flush=True)
            return INIT_FAILED
        assert started and count == args.processes, count
    jax.config.update("jax_numpy_dtype_promotion", "strict")  # as the test suite runs

    import numpy as np

    import ccjax.io
    from ccjax.estimators import registry
    from ccjax.runs import hosts

    # Every process probes every header (a few bytes each, so that all agree on the unusable files
    # and the folds); decoding the pixels is the reading that is shared out: record it.
    decode = ccjax.io.read_image

    def recorded(path, *arguments, **options):
        decoded.append(Path(path).name)
        return decode(path, *arguments, **options)

    decoded: list[str] = []
    ccjax.io.read_image = recorded

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from small_world import small_world

    world = small_world()
    models = {label: registry.fit(label, world) for label in METHODS}
    out: dict[str, np.ndarray] = {}
    sharded = args.role != "reference"
    mesh = hosts.item_mesh() if sharded else None
    if mesh is not None:
        out["mesh_devices"] = np.array(mesh.devices.size)

    sweep_part(world, models, mesh, out)
    image_part(world, models, args.images, out)
    train_part(world, mesh, out)

    name = f"{args.role}{args.process_id}"
    np.savez(Path(args.out) / f"{name}.npz", allow_pickle=False, **out)
    (Path(args.out) / f"{name}.json").write_text(
        json.dumps({"opened": sorted(set(opened)), "decoded": sorted(set(decoded))})
    )
    return 0


def sweep_part(world, models, mesh, out) -> None:
    """(a) Per-scene errors of GW and RETINEX on SCENES scenes of SURFACES surfaces."""
    import jax
    import numpy as np

    from ccjax.experiments.sweeps import sweep
    from ccjax.runs import hosts
    from ccjax.runs.engine import scene_errors
    from ccjax.scenes import SceneTables, sample_batch, sweep_keys

    key = jax.random.key(7)
    # The library's own sweep: on one device, or with the scene axis of every chunk sharded over
    # the mesh (spanning both processes under jax.distributed).
    result = sweep(world, list(models.items()), [SURFACES], SCENES, key=key, progress=False, mesh=mesh)
    for label in models:
        for name, values in result.errors[label][SURFACES].items():
            out[f"library_sweep/{label}/{name}"] = values
    if mesh is None:
        for label in models:
            for name, values in result.errors[label][SURFACES].items():
                out[f"sweep/{label}/{name}"] = values
            out[f"sweep_rms/{label}"] = np.array(result.value(label, SURFACES, "angular", "rms"))
        return
    tables = SceneTables.from_world(world)
    program = jax.jit(
        lambda models, keys: {
            label: scene_errors(m, sample_batch(keys, tables, SURFACES), tables.canonical_white)
            for label, m in models.items()
        }
    )
    # A share per process: this process's scenes on its own devices, pooled by `gather`.
    share = hosts.process_share(SCENES)
    keys = sweep_keys(key, SURFACES, share.start, share.stop - share.start)
    local = {label: jax.device_get(errors) for label, errors in program(models, keys).items()}
    pooled = hosts.gather(local)
    for label in models:
        for name, values in pooled[label].items():
            out[f"sweep/{label}/{name}"] = values
        angular = pooled[label]["angular"].astype(np.float64)
        out[f"sweep_rms/{label}"] = np.array(np.sqrt(np.mean(angular**2)))
    # One global mesh: chunks of CHUNK scenes, each process puts its block of every chunk on the mesh.
    chunks = []
    for start in range(0, SCENES, CHUNK):
        rows = hosts.process_share(CHUNK)
        keys = sweep_keys(key, SURFACES, start + rows.start, rows.stop - rows.start)
        chunks.append(hosts.global_value(program(models, hosts.shard_items(keys, mesh))))
    for label in models:
        for name in chunks[0][label]:
            out[f"mesh_sweep/{label}/{name}"] = np.concatenate([c[label][name] for c in chunks])[:SCENES]


def image_part(world, models, folder, out) -> None:
    """(b) Angular errors of GW and RETINEX on the folder's images (each process reads its share)."""
    import numpy as np

    from ccjax.evaluation import run_images
    from ccjax.io import match_ground_truth, read_ground_truth

    pairs = match_ground_truth(read_ground_truth(Path(folder) / "groundtruth.csv"), folder)
    # The library splits the files over the processes (each reads its share) and pools the results.
    result = run_images(
        [p for p, _ in pairs], {label: [m] for label, m in models.items()}, truth=np.array([t for _, t in pairs])
    )
    for label in models:
        out[f"images/{label}"] = result.angular(label)
    out["images/index"] = np.arange(len(pairs))
    # `ccjax evaluate --folds 3`'s library call: fold worlds from the other folds' ground truth.
    from ccjax.evaluation import evaluate_folder

    evaluation = evaluate_folder(folder, Path(folder) / "groundtruth.csv", list(models), world=world, folds=3)
    for label in models:
        out[f"folds/{label}"] = evaluation.results.angular(label)
    out["folds/fold_of"] = np.asarray(evaluation.fold_of)


def train_part(world, mesh, out) -> None:
    """(c) One epoch (two Adam steps) of Colour by Correlation, and one pooled gradient."""
    import equinox as eqx
    import jax
    import numpy as np

    from ccjax import losses
    from ccjax.estimators import registry
    from ccjax.estimators.correlation import ColourByCorrelation
    from ccjax.runs import hosts
    from ccjax.scenes import SceneTables, sample_batch, scene_keys
    from ccjax.training import Examples, Schedule, fit_to_examples, learnable

    tables = SceneTables.from_world(world)
    scenes = sample_batch(scene_keys(jax.random.key(3), 0, N_TRAIN + N_VALID), tables, 8)
    examples = Examples(scenes.rgb[:N_TRAIN], scenes.mask[:N_TRAIN], scenes.illuminant[:N_TRAIN])
    validation = Examples(scenes.rgb[N_TRAIN:], scenes.mask[N_TRAIN:], scenes.illuminant[N_TRAIN:])
    # A noisy start (the spectral fit plus unit noise on the log-probabilities), so one epoch
    # improves the held-out error and the trained model (not the start) is what is compared.
    fitted = registry.fit(LEARNER, world)
    assert isinstance(fitted, ColourByCorrelation)
    start = fitted.log_probability
    noise = jax.random.normal(jax.random.key(1), start.shape, start.dtype)
    model = eqx.tree_at(lambda m: m.log_probability, fitted, start + noise)
    # Two Adam steps of BATCH examples: subsets of 6 surfaces and relighting draw random numbers
    # on the sharded batch, the second step's update depends on both gradients' magnitudes.
    schedule = Schedule(epochs=1, batch_size=BATCH, learning_rate=0.05, surfaces=6, relight=0.5)
    trained, log = fit_to_examples(model, examples, schedule, validation=validation, progress=False, mesh=mesh)
    params, _ = eqx.partition(trained, learnable(trained))
    out["train/params"] = np.asarray(jax.tree.leaves(params)[0])
    out["train/loss"] = np.array(log.train_loss)
    out["train/best_epoch"] = np.array(log.best_epoch)

    # The gradient of a mean loss over a batch sharded on the mesh is the pooled gradient.
    params, static = eqx.partition(model, learnable(model))
    x, mask, truth = examples.x[:BATCH], examples.mask[:BATCH], examples.illuminant[:BATCH]
    if mesh is not None:
        rows = hosts.process_share(BATCH)
        x, mask, truth = hosts.shard_items((x[rows], mask[rows], truth[rows]), mesh)
        params = hosts.replicate(params, mesh)

    @jax.jit
    def gradient(params, x, mask, truth):
        def loss(params):
            estimate = jax.vmap(eqx.combine(params, static))(x, mask).illuminant
            return losses.illuminant_loss("angular", estimate, truth)

        return jax.grad(loss)(params)

    grads = hosts.global_value(gradient(params, x, mask, truth))
    out["train/gradient"] = np.asarray(jax.tree.leaves(grads)[0])


if __name__ == "__main__":
    raise SystemExit(main())
