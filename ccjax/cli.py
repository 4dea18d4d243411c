"""The ``ccjax`` command line.

Each sub-command is a pair: ``_add_<name>(subparsers)`` declaring its arguments and a ``_run_<name>``
function; :data:`_COMMANDS` lists them in the order ``ccjax --help`` shows.
"""

from __future__ import annotations

import argparse
import json
import sys
import time


def _world_arguments(parser: argparse.ArgumentParser, default: str = "default") -> None:
    parser.add_argument(
        "--world", choices=["default", "barnard1999"], default=default, help="synthetic world (default: %(default)s)"
    )
    parser.add_argument("--camera", default=None, help="camera name for the default world (see `ccjax cameras`)")
    parser.add_argument(
        "--data-dir", default=None, help="external data directory (else $CCJAX_DATA, else ../shared/data)"
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of the illuminant sets and scenes")


def _build_world(args):
    from ccjax.world import World

    if args.world == "barnard1999":
        if args.camera:
            raise SystemExit("--camera applies to --world default only (barnard1999 is the Sony DXC-930 world)")
        return World.barnard1999(args.data_dir, seed=args.seed)
    return World.default(args.camera or "Canon EOS 5D Mark II", seed=args.seed)


def _int_list(text: str) -> list[int]:
    try:
        values = [int(part) for part in text.split(",") if part.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated integers, got {text!r}") from None
    if not values:
        raise argparse.ArgumentTypeError("empty list")
    return values


def _label_list(text: str) -> list[str]:
    return [part.strip() for part in text.split(",") if part.strip()]


def _write(path: str, text: str) -> None:
    if path == "-":
        sys.stdout.write(text + ("\n" if not text.endswith("\n") else ""))
    else:
        with open(path, "w") as f:
            f.write(text)
        print(f"wrote {path}", file=sys.stderr)


# ---------------------------------------------------------------------------------------------
# compare

DEFAULT_COMPARE_METHODS = [
    "NOTHING",
    "AVE-ILLUM",
    "GW",
    "DB-GW",
    "RETINEX",
    "shades-of-grey-p6",
    "ECRULE-MV",
    "ECRULE-SCWIA-12",
    "C-by-C-MMSE",
    "RGB-C-by-C-MMSE",
    "NEURAL-NET",
]


def _weights_ready(label: str, world) -> bool:
    """Learned methods join default runs only when their weights are cached (never train silently)."""
    from ccjax.estimators import neural

    return not neural.is_net_label(label) or neural.has_weights(world, label)


def _add_compare(sub) -> None:
    p = sub.add_parser(
        "compare",
        help="run a synthetic comparison sweep (the main job)",
        description="Run every method on the same synthetic scenes for each number of surfaces; print RMS (r,g) and angular errors.",
    )
    _world_arguments(p)
    p.add_argument(
        "--methods",
        type=_label_list,
        default=None,
        help="comma-separated labels (default: the built-in comparison set)",
    )
    p.add_argument(
        "--surfaces",
        type=_int_list,
        default=[4, 8, 16, 32, 64],
        help="comma-separated surface counts (default: 4,8,16,32,64)",
    )
    p.add_argument("--scenes", type=int, default=1000, help="scenes per surface count (default: %(default)s)")
    p.add_argument(
        "--specular", action="store_true", help="add the thesis' specularities (25 %% of surfaces, +U(0,2) x white)"
    )
    p.add_argument(
        "--clip",
        type=float,
        default=None,
        help="discard surfaces with a channel above this level, thesis units (white = 255)",
    )
    p.add_argument("--plot", default=None, help="write a PNG of error versus number of surfaces")
    p.add_argument("--json", default=None, help="write the tidy table as JSON ('-' for stdout)")
    p.add_argument("--csv", default=None, help="write the tidy table as CSV ('-' for stdout)")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    p.set_defaults(func=_run_compare)


def _run_compare(args) -> int:
    import jax

    from ccjax import experiments

    start = time.perf_counter()
    world = _build_world(args)
    methods = args.methods or [
        m for m in DEFAULT_COMPARE_METHODS if experiments._is_registered(m) and _weights_ready(m, world)
    ]
    result = experiments.sweep(
        world,
        methods,
        args.surfaces,
        args.scenes,
        jax.random.key(args.seed),
        specular=args.specular or None,
        clip=None if args.clip is None else args.clip / 255.0,
        progress=not args.no_progress,
    )
    print(f"world: {world.name}; {args.scenes} scenes per surface count; RMS over scenes")
    print(result.table("rg"))
    print()
    print(result.table("angular"))
    if args.plot:
        experiments.plot(result, args.plot, title=f"{world.name}: {args.scenes} scenes per point")
        print(f"wrote {args.plot}", file=sys.stderr)
    if args.json:
        _write(args.json, result.to_json(("rms", "mean", "median", "trimean", "best25", "worst25", "max")))
    if args.csv:
        _write(args.csv, result.to_csv(("rms", "mean", "median", "trimean", "best25", "worst25", "max")))
    print(f"done in {time.perf_counter() - start:.1f} s", file=sys.stderr)
    return 0


# ---------------------------------------------------------------------------------------------
# reproduce


def _add_reproduce(sub) -> None:
    p = sub.add_parser(
        "reproduce",
        help="reproduce a thesis table on the thesis world",
        description="Run a table of Barnard (1999) with the thesis protocol on World.barnard1999 and print ours, the thesis value and the relative difference per cell.",
    )
    p.add_argument("table", help="table id, e.g. 4.2, 4.3, 4.4")
    p.add_argument(
        "--methods", type=_label_list, default=None, help="comma-separated labels (default: every registered row)"
    )
    p.add_argument("--scenes", type=int, default=1000, help="scenes per condition (default: %(default)s)")
    p.add_argument("--data-dir", default=None, help="external data directory (else $CCJAX_DATA, else ../shared/data)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(func=_run_reproduce)


def _run_reproduce(args) -> int:
    import jax

    from ccjax import experiments, thesis
    from ccjax.world import World

    world = World.barnard1999(args.data_dir, seed=args.seed)
    if args.table == "5.1":
        return _run_reproduce_5_1(args, world)
    methods = args.methods
    if methods is None and args.table in thesis.TABLES:
        methods = [m for m in thesis.TABLES[args.table] if experiments._is_registered(m) and _weights_ready(m, world)]
    result = experiments.reproduce(
        args.table, world, methods, args.scenes, jax.random.key(args.seed), progress=not args.no_progress
    )
    print(result.to_json() if args.json else result.text())
    return 0


# ---------------------------------------------------------------------------------------------
# world


def _add_world(sub) -> None:
    p = sub.add_parser("world", help="describe a synthetic world and plot its chromaticities")
    _world_arguments(p)
    p.add_argument(
        "--plot", default=None, help="write a PNG of the illuminant sets and reflectances in (r,g) (thesis Fig. 4.1)"
    )
    p.set_defaults(func=_run_world)


def _run_world(args) -> int:
    import numpy as np

    from ccjax import data
    from ccjax.metrics import angular_error

    world = _build_world(args)
    print(f"world: {world.name}")
    for name, size in world.sizes().items():
        print(f"  {name:<22}{size}")
    print(f"  camera                {world.camera.name}")
    print(f"  canonical white RGB   {np.round(np.asarray(world.canonical_white), 4).tolist()}")
    if args.world == "barnard1999":
        # Check the camera against the SFU-321 ground truth: white under each lab light.
        truth = data.sfu321_groundtruth(args.data_dir)
        lights = data.sfu_illuminants(args.data_dir)
        print("  perfect white under each lab light vs mean SFU-321 ground truth (degrees):")
        for code, name in data.SFU_LAB_LIGHTS.items():
            rows = [i for i, label in enumerate(truth.labels) if label == code]
            mean_truth = truth.rgb[rows].mean(axis=0)
            white = np.asarray(world.camera.response(lights.values[lights.names.index(name)]))
            print(f"    {code:<18}{float(angular_error(white, mean_truth)):6.2f}   ({len(rows)} images)")
    if args.plot:
        _plot_world(world, args.plot)
        print(f"wrote {args.plot}", file=sys.stderr)
    return 0


def _plot_world(world, path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from ccjax.spectra import chromaticity

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.8), sharex=True, sharey=True)
    panels = [
        ("training illuminants", np.asarray(world.train_whites), 12),
        ("test illuminants", np.asarray(world.test_whites), 6),
        ("reflectances under the canonical light", np.asarray(world.canonical_rgb), 2),
    ]
    for ax, (title, rgb, size) in zip(axes, panels):
        rg = chromaticity(rgb)
        ax.scatter(rg[:, 0], rg[:, 1], s=size, alpha=0.7)
        canon = chromaticity(np.asarray(world.canonical_white))
        ax.scatter([canon[0]], [canon[1]], marker="*", s=120, c="red", label="canonical")
        ax.set_title(f"{title} ({len(rgb)})")
        ax.set_xlabel("r")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("g")
    axes[0].legend()
    fig.suptitle(f"{world.name}: (r,g) chromaticities")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ---------------------------------------------------------------------------------------------
# cameras / methods


def _add_cameras(sub) -> None:
    p = sub.add_parser("cameras", help="list the cameras ccjax can build")
    p.add_argument("--data-dir", default=None)
    p.set_defaults(func=lambda args: _print_cameras(args.data_dir))


def _print_cameras(data_dir) -> int:
    from ccjax.camera import cameras

    for name, source in cameras(data_dir).items():
        print(f"{name:<36}{source}")
    return 0


def _add_methods(sub) -> None:
    p = sub.add_parser("methods", help="list the estimator labels")
    p.set_defaults(func=lambda args: _print_methods())


def _print_methods() -> int:
    from ccjax.estimators import available

    for example, description in available():
        print(f"{example:<28}{description}")
    return 0


# ---------------------------------------------------------------------------------------------
# estimate / correct / evaluate (real images; ccjax.images)


def _image_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--preprocessing",
        default="ave5",
        help="surface-list preprocessing (Table 4.6): ave<b>, ave<b>-cluster, ave<b>-hull, seg-<min>-<rg>-<rel>[-hull], generic (default: %(default)s)",
    )
    parser.add_argument(
        "--dark",
        type=float,
        default=0.02,
        help="drop pixels with R+G+B below this fraction of the brightest usable pixel's (default: %(default)s)",
    )
    parser.add_argument("--black-level", type=float, default=0.0, help="black level in file units (default: 0)")
    parser.add_argument(
        "--saturation",
        type=float,
        default=None,
        help="saturation level in file units (default: the format maximum, 65535 for 16-bit)",
    )
    parser.add_argument(
        "--assume-linear", action="store_true", help="accept 8-bit files as linear data (they are refused otherwise)"
    )
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")


def _read_options(args) -> dict:
    return {"black_level": args.black_level, "saturation": args.saturation, "assume_linear": args.assume_linear}


def _image_world(args):
    from ccjax import images

    if args.world == "barnard1999" and args.camera:
        raise SystemExit("--camera applies to --world default only (barnard1999 is the Sony DXC-930 world)")
    images.enable_compilation_cache()
    return images.cached_world(args.world, args.camera, seed=args.seed, data_dir=args.data_dir)


def _check_images(paths, args) -> None:
    """Read every input once before anything is computed or written (bad files -> no output)."""
    from ccjax import images
    from ccjax.images import Preprocessing

    Preprocessing.parse(args.preprocessing)
    if not paths:
        raise ValueError("images: no image files given (folders are searched for .png, .tif, .tiff and raw files)")
    for path in paths:
        images.read_image(path, **_read_options(args))


def _add_estimate(sub) -> None:
    p = sub.add_parser(
        "estimate",
        help="estimate the light of linear images",
        description="Estimate the illuminant of each image (files or folders); print its camera RGB (unit scale: saturation = 1) and (r,g).",
    )
    p.add_argument("images", nargs="+", help="16-bit PNG/TIFF files, raw files (raw extra), or folders of them")
    p.add_argument("--method", required=True, help="estimator label (see `ccjax methods`)")
    _world_arguments(p)
    _image_arguments(p)
    p.add_argument(
        "--json",
        action="store_true",
        help="print a JSON list with one object per image: path, illuminant [R,G,B], rg, ok",
    )
    p.set_defaults(func=_run_estimate)


def _run_estimate(args) -> int:
    from ccjax import images

    paths = images.list_images(args.images)
    _check_images(paths, args)
    world = _image_world(args)
    model = images.cached_fit(args.method, world)
    results = images.run_images(
        paths,
        {args.method: [model]},
        preprocessing=args.preprocessing,
        dark=args.dark,
        read_options=_read_options(args),
        progress=not args.no_progress,
    )
    records = [{k: r[k] for k in ("path", "illuminant", "rg", "ok")} for r in results.records()]
    if args.json:
        print(json.dumps(records, indent=1))
    else:
        print(f"{'image':<40}{'R':>9}{'G':>9}{'B':>9}{'r':>8}{'g':>8}  ok")
        for r in records:
            print(
                f"{r['path']:<40}"
                + "".join(f"{v:9.5f}" for v in r["illuminant"])
                + "".join(f"{v:8.4f}" for v in r["rg"])
                + f"  {'yes' if r['ok'] else 'no'}"
            )
    return 0


def _add_correct(sub) -> None:
    p = sub.add_parser(
        "correct",
        help="correct linear images to the canonical light",
        description="Estimate each image's light, map it to the canonical light with a diagonal map and write the corrected linear 16-bit image and an 8-bit sRGB preview. IN and OUT are files, or folders (OUT is created).",
    )
    p.add_argument("input", help="a linear image or a folder of them")
    p.add_argument("output", help="output .png/.tif/.tiff file, or a folder when INPUT is a folder")
    p.add_argument("--method", required=True, help="estimator label (see `ccjax methods`)")
    p.add_argument(
        "--preview", default=None, help="preview path for a single image (default: OUTPUT stem + '_preview.png')"
    )
    p.add_argument(
        "--sharpening",
        default=None,
        help="3x3 sharpening transform T (text or .npy; rows = sharpened sensors) for a sharpened-diagonal map T^-1 diag(T w_C / T e) T",
    )
    _world_arguments(p)
    _image_arguments(p)
    p.set_defaults(func=_run_correct)


def _run_correct(args) -> int:
    from pathlib import Path

    import numpy as np
    from tqdm.auto import tqdm

    from ccjax import images

    source, target = Path(args.input), Path(args.output)
    if source.is_dir():
        paths = images.list_images([source])
        outputs = [
            target / f"{p.stem}{p.suffix.lower() if p.suffix.lower() in ('.png', '.tif', '.tiff') else '.tiff'}"
            for p in paths
        ]
        previews = [target / f"{p.stem}_preview.png" for p in paths]
        if target.exists() and not target.is_dir():
            raise ValueError(f"output: {target} exists and is not a folder")
    else:
        paths, outputs = [source], [target]
        previews = [Path(args.preview) if args.preview else target.with_name(f"{target.stem}_preview.png")]
        if target.suffix.lower() not in (".png", ".tif", ".tiff"):
            raise ValueError(f"output: {target} must end in .png, .tif or .tiff")
        if not target.parent.is_dir():
            raise ValueError(f"output: folder {target.parent} does not exist")
    sharpening = None
    if args.sharpening:
        sharpening = np.load(args.sharpening) if args.sharpening.endswith(".npy") else np.loadtxt(args.sharpening)
        if sharpening.shape != (3, 3) or not np.all(np.isfinite(sharpening)) or abs(np.linalg.det(sharpening)) < 1e-9:
            raise ValueError(f"sharpening: {args.sharpening} must hold an invertible 3x3 matrix")
    _check_images(paths, args)
    world = _image_world(args)
    model = images.cached_fit(args.method, world)
    canonical = world.canonical_white
    matrix = images.preview_matrix_cached(world)
    if source.is_dir():
        target.mkdir(parents=True, exist_ok=True)
    for path, output, preview in zip(
        tqdm(paths, desc="images", unit="image", disable=args.no_progress, file=sys.stderr), outputs, previews
    ):
        image = images.read_image(path, **_read_options(args))
        estimate = images.estimate_image(model, image, args.preprocessing, dark=args.dark)
        corrected = np.asarray(images.correct(image.rgb, estimate.illuminant, canonical, sharpening))
        images.write_linear(output, corrected)
        images.write_preview(preview, corrected, matrix)
        rgb = np.asarray(estimate.illuminant)
        print(f"{path}: illuminant {np.round(rgb, 5).tolist()} (ok: {bool(estimate.ok)}) -> {output}, {preview}")
    return 0


def _add_evaluate(sub) -> None:
    p = sub.add_parser(
        "evaluate",
        help="evaluate methods on a folder of images with ground truth",
        description="Run each method on every image listed in the ground truth and print angular error statistics (mean, median, trimean, best 25%%, worst 25%%, max) and the share of images where a method fell back or relaxed (not ok). Ground truth: CSV with header image,r,g,b (file name in DIR; r,g,b = camera RGB of the light, any scale).",
    )
    p.add_argument("directory", help="folder of linear images")
    p.add_argument("--ground-truth", required=True, help="CSV with header image,r,g,b")
    p.add_argument("--methods", type=_label_list, required=True, help="comma-separated labels")
    p.add_argument(
        "--folds",
        type=int,
        default=None,
        help="K-fold cross-validation: each fold's models learn the expected lights from the other folds' ground truth",
    )
    p.add_argument("--json", default=None, help="write summaries and per-image results as JSON ('-' for stdout)")
    p.add_argument("--csv", default=None, help="write per-image results as CSV ('-' for stdout)")
    _world_arguments(p)
    _image_arguments(p)
    p.set_defaults(func=_run_evaluate)


def _run_evaluate(args) -> int:
    import numpy as np

    from ccjax import images

    start = time.perf_counter()
    pairs = images.match_ground_truth(images.read_ground_truth(args.ground_truth), args.directory)
    pairs.sort(key=lambda pair: str(pair[0]))
    paths, truth = [p for p, _ in pairs], np.stack([t for _, t in pairs])
    _check_images(paths, args)
    world = _image_world(args)
    fold_of = None
    if args.folds:
        fold_of, worlds = images.fold_worlds(world, truth, args.folds)
        models = {label: [images.cached_fit(label, w) for w in worlds] for label in args.methods}
    else:
        models = {label: [images.cached_fit(label, world)] for label in args.methods}
    results = images.run_images(
        paths,
        models,
        fold_of=fold_of,
        preprocessing=args.preprocessing,
        dark=args.dark,
        read_options=_read_options(args),
        progress=not args.no_progress,
        truth=truth,
    )
    folds = f"; {args.folds}-fold cross-validation" if args.folds else ""
    print(f"world: {world.name}; preprocessing: {args.preprocessing}{folds}")
    print(results.table(), flush=True)
    if args.json:
        summary = {label: results.summary(label) for label in args.methods}
        _write(args.json, json.dumps({"summary": summary, "images": results.records()}, indent=1))
    if args.csv:
        lines = ["path,method,R,G,B,r,g,ok,angular"] + [
            ",".join(
                [
                    r["path"],
                    r["method"],
                    *(f"{v:.9g}" for v in r["illuminant"] + r["rg"]),
                    str(r["ok"]),
                    f"{r['angular']:.9g}",
                ]
            )
            for r in results.records()
        ]
        _write(args.csv, "\n".join(lines) + "\n")
    print(f"done in {time.perf_counter() - start:.1f} s", file=sys.stderr)
    return 0


# ---------------------------------------------------------------------------------------------
# train-net


def _add_train_net(sub) -> None:
    p = sub.add_parser(
        "train-net",
        help="train the neural-net estimator for a world and cache its weights",
        description="Train NEURAL-NET (or SP-NEURAL-NET with --specular) on synthetic scenes of the world's training illuminants (Barnard 1999 §4.5.5) and save the weights in the cache ($CCJAX_CACHE, else the user cache directory).",
    )
    _world_arguments(p)
    p.add_argument(
        "--specular", action="store_true", help="train SP-NEURAL-NET (specular training scenes) instead of NEURAL-NET"
    )
    p.add_argument("--steps", type=int, default=None, help="optimiser steps (default: 3000)")
    p.add_argument("--batch-size", type=int, default=None, help="training scenes per step (default: 256)")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    p.set_defaults(func=_run_train_net)


def _run_train_net(args) -> int:
    import dataclasses

    from ccjax.estimators import neural

    label = "SP-NEURAL-NET" if args.specular else "NEURAL-NET"
    world = _build_world(args)
    changes = {"seed": args.seed}
    if args.steps is not None:
        changes["steps"] = args.steps
    if args.batch_size is not None:
        changes["batch_size"] = args.batch_size
    schedule = dataclasses.replace(neural.Schedule(), **changes)
    print(
        f"training {label} for world {world.name}: {schedule.steps} steps x {schedule.batch_size} scenes",
        file=sys.stderr,
    )
    path, log = neural.train_and_save(world, label, schedule, progress=not args.no_progress)
    print(f"{label}: final training RMS (r,g) error {log.losses[-1] ** 0.5:.4f}; trained in {log.seconds:.1f} s")
    print(f"saved {path}")
    return 0


# ---------------------------------------------------------------------------------------------
# indexing (chapter 11; ccjax.indexing)

DEFAULT_INDEXING_METHODS = [
    "ACTUAL",
    "NOTHING",
    "AVE-ILLUM",
    "GW",
    "DB-GW",
    "RETINEX",
    "grey-edge-1-6-2",
    "CIP-MV",
    "CIP-AVE",
    "CIP-ICA",
    "CRULE-MV",
    "CRULE-AVE",
    "ECRULE-MV",
    "ECRULE-ICA",
    "ECRULE-SCWIA-12",
    "ND-CRULE-MV",
    "ND-CRULE-AVE",
    "ND-ECRULE-MV",
    "ND-ECRULE-ICA",
    "ND-ECRULE-SCWIA-12",
    "C-by-C-MMSE",
    "RGB-C-by-C-MMSE",
]


def _add_indexing(sub) -> None:
    p = sub.add_parser(
        "indexing",
        help="colour indexing with each estimator as preprocessing (chapter 11)",
        description="Synthetic version of Barnard (1999) chapter 11: objects of random reflectance patches, database under the canonical light, queries under a subset of test lights; print each method's rg error, Score(1..3), rank counts, and the Spearman correlation of score with error.",
    )
    _world_arguments(p)
    p.add_argument(
        "--methods",
        type=_label_list,
        default=None,
        help="comma-separated labels; ACTUAL = the true light (default: baselines, grey edge and every registered gamut / C-by-C row)",
    )
    p.add_argument("--objects", type=int, default=50, help="objects in the database (default: %(default)s)")
    p.add_argument("--surfaces", type=int, default=8, help="reflectances per object (default: %(default)s)")
    p.add_argument("--lights", type=int, default=20, help="test lights per object (default: %(default)s)")
    p.add_argument("--size", type=int, default=64, help="image side in pixels (default: %(default)s)")
    p.add_argument(
        "--preprocessing", default="ave5", help="preprocessing for surface-list methods (default: %(default)s)"
    )
    p.add_argument("--json", default=None, help="write the table as JSON ('-' for stdout)")
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(func=_run_indexing)


def _run_indexing(args) -> int:
    import jax

    from ccjax import indexing
    from ccjax.estimators import registry

    def registered(label):
        try:
            registry.lookup(label)
            return True
        except ValueError:
            return False

    methods = args.methods or [m for m in DEFAULT_INDEXING_METHODS if m == "ACTUAL" or registered(m)]
    start = time.perf_counter()
    world = _image_world(args)
    result = indexing.run_indexing(
        world,
        methods,
        jax.random.key(args.seed),
        n_objects=args.objects,
        n_surfaces=args.surfaces,
        n_lights=args.lights,
        size=args.size,
        preprocessing=args.preprocessing,
        progress=not args.no_progress,
    )
    print(
        f"world: {world.name}; {args.objects} objects x {args.lights} lights, {args.surfaces} reflectances each, {args.size}x{args.size} px"
    )
    print(result.table(), flush=True)
    if args.json:
        _write(
            args.json,
            json.dumps(
                {
                    "rows": result.rows,
                    "spearman_score3": result.spearman(),
                    "spearman_score1": result.spearman("score1"),
                },
                indent=1,
            ),
        )
    print(f"done in {time.perf_counter() - start:.1f} s", file=sys.stderr)
    return 0


_COMMANDS = [
    _add_compare,
    _add_reproduce,
    _add_world,
    _add_cameras,
    _add_methods,
    _add_estimate,
    _add_correct,
    _add_evaluate,
    _add_indexing,
    _add_train_net,
]


# ---------------------------------------------------------------------------------------------
# sharpen (Barnard 1999 ch. 5; ccjax.sharpening)


def _add_sharpen(sub) -> None:
    p = sub.add_parser(
        "sharpen",
        help="compute a sensor-sharpening transform and its effect",
        description="Compute a sharpening transform T for the world's camera (thesis ch. 5): 'new' (the thesis' method: mapping error over the training lights + positivity + norm, from the identity), 'database' (eigenvectors of the best linear map for one test light) or 'average' (database sharpening for the mean training light). Prints T, the sharpened sensors' negative-lobe fractions and RMS mapping errors over the test lights (white = 255).",
    )
    _world_arguments(p)
    p.add_argument(
        "--method",
        choices=["new", "database", "average"],
        default="new",
        help="sharpening method (default: %(default)s)",
    )
    p.add_argument(
        "--light", type=int, default=0, help="test-illuminant index for --method database (default: %(default)s)"
    )
    p.add_argument(
        "--lambda-p",
        type=float,
        default=None,
        help="positivity weight for --method new (default: the smallest leaving < 0.1%% negative training responses)",
    )
    p.add_argument("--plot", default=None, help="write a PNG of the original and sharpened sensor curves")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.add_argument(
        "--rank-cameras",
        action="store_true",
        help="rank every available camera (each in the default world) by sharpness, then run the new method on the least sharp one and compare GW and ECRULE-ICA with and without it",
    )
    p.add_argument("--scenes", type=int, default=1000, help="test scenes for --rank-cameras (default: %(default)s)")
    p.set_defaults(func=_run_sharpen)


def _run_rank_cameras(args) -> int:
    import jax
    import numpy as np

    from ccjax import experiments, sharpening
    from ccjax.camera import Camera
    from ccjax.world import World

    start = time.perf_counter()
    ranking = sharpening.rank_cameras(args.data_dir)
    print(f"{'rank':>4}  {'camera':<36}{'sharpness':>10}{'BEST-LINEAR':>13}{'BEST-DIAGONAL':>15}")
    for index, row in enumerate(ranking, 1):
        print(
            f"{index:>4}  {row['camera']:<36}{row['ratio']:>10.3f}{row['best_linear']:>13.3f}{row['best_diagonal']:>15.3f}"
        )
    least = ranking[0]["camera"]
    world = World.default(Camera.from_name(least, args.data_dir), seed=args.seed)
    new = sharpening.new_sharpening(world, lambda_p=args.lambda_p)
    print(
        f"least sharp: {least}; new method: lambda_P {new.lambda_p:g}, {new.iterations} iterations, "
        f"objective {new.initial_objective:.4f} -> {new.objective:.4f}, negative training responses {new.negative_fraction:.4%}"
    )
    print("T =", np.round(new.transform, 4).tolist())
    transforms = {"none": np.eye(3), "new": new.transform}
    print(
        f"{args.scenes} scenes of 8 surfaces under test lights; RMS mapping error (white = 255), RMS angle, reverted:"
    )
    for label in ("GW", "DB-GW", "RETINEX", "ECRULE-ICA", "ECRULE-MV"):
        if not experiments._is_registered(label):
            print(f"  {label:<12} pending (not registered)")
            continue
        out = sharpening.evaluate_transforms(world, label, transforms, args.scenes, key=jax.random.key(args.seed))
        change = out["new"]["map_rgb"] / out["none"]["map_rgb"] - 1.0
        print(
            f"  {label:<12} none {out['none']['map_rgb']:8.2f} {out['none']['angular']:6.2f}   new {out['new']['map_rgb']:8.2f} "
            f"{out['new']['angular']:6.2f} (reverted {out['new']['reverted']})   mapping change {change:+.1%}"
        )
    print(f"done in {time.perf_counter() - start:.1f} s", file=sys.stderr)
    return 0


def _run_sharpen(args) -> int:
    import numpy as np

    from ccjax import sharpening

    if args.rank_cameras:
        return _run_rank_cameras(args)
    start = time.perf_counter()
    world = _build_world(args)
    info = {"world": world.name, "camera": world.camera.name, "method": args.method}
    if args.method == "new":
        result = sharpening.new_sharpening(world, lambda_p=args.lambda_p)
        transform = result.transform
        info.update(
            lambda_p=result.lambda_p,
            iterations=result.iterations,
            converged=result.converged,
            objective_initial=result.initial_objective,
            objective_final=result.objective,
            lambda_p_search=[list(step) for step in result.search],
        )
    elif args.method == "average":
        transform = sharpening.average_sharpening(world)
    else:
        n_lights = int(world.test_illuminants.shape[0])
        if not 0 <= args.light < n_lights:
            raise ValueError(f"light: expected an index in [0, {n_lights}), got {args.light}")
        transform = sharpening.optimal_sharpening(world, world.test_illuminants[args.light : args.light + 1])[0]
    info["T"] = np.asarray(transform).tolist()
    info.update(sharpening.summary(world, transform))
    if args.json:
        print(json.dumps(info, indent=1))
    else:
        print(f"world: {world.name}; camera {world.camera.name}; method {args.method}")
        print("T =")
        for row in np.asarray(transform):
            print("  " + " ".join(f"{v:9.5f}" for v in row))
        if args.method == "new":
            print(
                f"lambda_P = {info['lambda_p']:g} (search: {info['lambda_p_search']}); {info['iterations']} iterations, converged {info['converged']}"
            )
            print(f"objective {info['objective_initial']:.5f} (identity) -> {info['objective_final']:.5f}")
        print(
            "negative-lobe fraction of the sharpened sensors (R, G, B): "
            + ", ".join(f"{v:.4f}" for v in info["negative_lobes"])
        )
        print(f"negative sharpened training responses: {info['negative_training_responses']:.4%}")
        print("RMS mapping error over the test lights (white = 255):")
        print(f"  BEST-LINEAR                  {info['best_linear']:8.3f}")
        print(
            f"  BEST-DIAGONAL  none / T      {info['best_diagonal_unsharpened']:8.3f} / {info['best_diagonal_sharpened']:8.3f}"
        )
        print(f"  ACTUAL         none / T      {info['actual_unsharpened']:8.3f} / {info['actual_sharpened']:8.3f}")
    if args.plot:
        sharpening.plot_sensors(world, transform, args.plot, title=f"{world.camera.name}: {args.method} sharpening")
        print(f"wrote {args.plot}", file=sys.stderr)
    print(f"done in {time.perf_counter() - start:.1f} s", file=sys.stderr)
    return 0


def _run_reproduce_5_1(args, world) -> int:
    """Table 5.1 has its own protocol (sharpening variants, whole-database mapping error)."""
    import jax

    from ccjax import sharpening

    result = sharpening.reproduce_5_1(
        world, args.methods, args.scenes, jax.random.key(args.seed), progress=not args.no_progress
    )
    print(result.to_json() if args.json else result.text())
    return 0


_COMMANDS.append(_add_sharpen)


# ---------------------------------------------------------------------------------------------
# calibrate (Barnard 1999 ch. 3; ccjax.calibration)


def _add_calibrate(sub) -> None:
    p = sub.add_parser(
        "calibrate",
        help="fit camera sensors and linearisation to calibration data (thesis ch. 3)",
        description="Fit sensor curves and the linearisation F(x) = x - a0 - a1 exp(-C (x - b)) (thesis ch. 3) by every method of "
        "Table 3.1 and print the table. DATA is a CSV with one measurement per line: the spectrum at 380,384,...,780 nm "
        "(101 values) then the raw R,G,B (an optional header 380,...,780,R,G,B and '#' comment lines are allowed). "
        "--synthetic runs the thesis' experiment with a known camera (24 ColorChecker patches under 26 lights, noise, "
        "clipping, a known F) and checks the fits against the truth.",
    )
    p.add_argument("file", nargs="?", metavar="DATA", help="calibration CSV (see above)")
    p.add_argument(
        "--synthetic", action="store_true", help="run the thesis' synthetic experiment instead of reading DATA"
    )
    p.add_argument(
        "--camera",
        default=None,
        help="true camera for --synthetic (default: 'Sony DXC-930' when the external data is present, else 'Canon EOS 5D Mark II')",
    )
    p.add_argument("--data-dir", default=None, help="external data directory (else $CCJAX_DATA, else ../shared/data)")
    p.add_argument("--seed", type=int, default=0, help="seed of the synthetic data, the held-out split and the subsets")
    p.add_argument(
        "--smoothness",
        type=float,
        default=None,
        help="lambda of the smoothness term (default: the library default, or --cv)",
    )
    p.add_argument(
        "--cv", action="store_true", help="choose the smoothness by 5-fold cross-validation of the joint fit"
    )
    p.add_argument(
        "--black",
        type=float,
        default=None,
        help="camera black b of F, raw units (default: 0 for DATA; the true 10 for --synthetic)",
    )
    p.add_argument("--exp-rate", type=float, default=None, help="C of F (default: searched per channel)")
    p.add_argument(
        "--json", action="store_true", help="print the RMS relative error of each method as a fraction, as JSON"
    )
    p.add_argument("--plot", default=None, help="write a PNG of the fitted (and, with --synthetic, true) sensor curves")
    p.add_argument("--save", default=None, help="write the proposed method's curves (and F) as CSV")
    p.add_argument(
        "--robustness",
        default=None,
        metavar="PNG",
        help="also run the robustness experiment (Fig. 3.6) and write its log-log plot",
    )
    p.add_argument(
        "--subsets", type=int, default=100, help="random subsets per size for --robustness (default: %(default)s)"
    )
    p.add_argument(
        "--sizes",
        type=_int_list,
        default=[400, 200, 100, 50, 25, 15],
        help="subset sizes for --robustness (default: 400,200,100,50,25,15)",
    )
    p.set_defaults(func=_run_calibrate)


def _run_calibrate(args) -> int:
    import os

    import numpy as np

    from ccjax.calibration import experiment, files, synthetic

    start = time.perf_counter()
    if args.synthetic == (args.file is not None):
        raise ValueError("give either a calibration file DATA or --synthetic (not both)")
    if args.subsets < 1:
        raise ValueError(f"--subsets: expected a positive number, got {args.subsets}")
    if args.synthetic:
        camera = args.camera or (
            "Sony DXC-930" if synthetic.has_external_lights(args.data_dir) else "Canon EOS 5D Mark II"
        )
        report = experiment.synthetic_experiment(
            camera,
            seed=args.seed,
            smoothness=args.smoothness,
            cv=args.cv,
            exp_rate=args.exp_rate,
            data_dir=args.data_dir,
        )
        table, truth = report.table, report.data.sensors
        spectra, raw = report.data.usable_data()
        black = report.data.linearisation.black[0]
        print(table.to_json() if args.json else report.text(), flush=True)
        title = f"{camera}: fitted (solid) vs true (dashed) sensors"
    else:
        if args.camera:
            raise ValueError("--camera applies to --synthetic only")
        data = files.read_calibration_csv(args.file)
        spectra, raw = data.spectra, data.responses
        black = 0.0 if args.black is None else args.black
        smoothness = args.smoothness
        if args.cv:
            from ccjax.calibration import fit_sensors_cv

            _, cross_validation = fit_sensors_cv(
                spectra, raw, linearisation="exp", black=black, exp_rate=args.exp_rate, seed=args.seed
            )
            smoothness = cross_validation.best
            if not args.json:
                print(cross_validation.table())
        table = experiment.calibration_table(
            spectra,
            raw,
            black=black,
            exp_rate=args.exp_rate,
            smoothness=experiment.DEFAULT_SMOOTHNESS if smoothness is None else smoothness,
        )
        truth = None
        if args.json:
            print(table.to_json())
        else:
            print(f"{args.file}: {len(spectra)} measurements")
            print(table.text())
            rates = table.row(experiment.JOINT).fit.linearisation.exp_rate
            print()
            print(
                experiment.held_out(
                    spectra, raw, black=black, exp_rate=rates, smoothness=table.smoothness, seed=args.seed
                ).text(),
                flush=True,
            )
        title = f"{args.file}: fitted sensors"
    if args.plot:
        experiment.plot_sensors(table, args.plot, truth=truth, title=title)
        print(f"wrote {args.plot}", file=sys.stderr)
    if args.save:
        fit = table.row(experiment.JOINT).fit
        files.write_sensors_csv(args.save, np.asarray(fit.sensors), fit.linearisation)
        print(f"wrote {args.save}", file=sys.stderr)
    if args.robustness:
        sizes = [n for n in args.sizes if n < len(spectra)]
        if not sizes:
            raise ValueError(f"--sizes: every size is >= the {len(spectra)} measurements")
        rates = table.row(experiment.JOINT).fit.linearisation.exp_rate
        result = experiment.robustness(
            spectra,
            raw,
            black=black,
            exp_rate=rates,
            smoothness=table.smoothness,
            sizes=sizes,
            n_subsets=args.subsets,
            seed=args.seed,
            progress=lambda size, label: print(
                f"  robustness: {size} measurements, {label} done ({time.perf_counter() - start:.0f} s)",
                file=sys.stderr,
                flush=True,
            ),
        )
        if not args.json:
            print("\n" + result.text())
        experiment.plot_robustness(result, args.robustness, title=f"robustness: {args.subsets} random subsets per size")
        numbers = os.path.splitext(args.robustness)[0] + ".json"
        with open(numbers, "w") as f:
            f.write(result.to_json())
        print(f"wrote {args.robustness} and {numbers}", file=sys.stderr)
    print(f"done in {time.perf_counter() - start:.1f} s", file=sys.stderr)
    return 0


_COMMANDS.append(_add_calibrate)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="ccjax", description="JAX colour constancy: estimate and correct the colour of the light."
    )
    sub = parser.add_subparsers(dest="command", required=True)
    for add in _COMMANDS:
        add(sub)
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (ValueError, FileNotFoundError) as error:
        print(f"ccjax {args.command}: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
