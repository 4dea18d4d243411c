"""``ccjax sharpen``: sensor-sharpening transforms and their effect (Barnard 1999 ch. 5; ccjax.sharpening)."""

from __future__ import annotations

import contextlib
import json
import sys
import time

from ccjax import limits
from ccjax._numbers import whole
from ccjax.cli.common import (
    build_world,
    check_outputs,
    check_plot,
    count_within,
    data_output_argument,
    number_within,
    overwrite_argument,
    table_stream,
    world_arguments,
    write,
    write_plot,
)

ADAPTATION_METHODS = ("bradford", "cat02", "cat16")
"""``--method`` names of the standard adaptation transforms (ccjax.sharpening.ADAPTATION_TRANSFORMS, lower
case: the parser is built without importing JAX)."""


def add_sharpen(sub) -> None:
    p = sub.add_parser(
        "sharpen",
        help="compute a sensor-sharpening transform and its effect",
        description="Compute a sharpening transform T for the world's camera (thesis ch. 5): 'new' (the thesis' "
        "method: mapping error over the training lights + positivity + norm, from the identity), "
        "'database' (eigenvectors of the best linear map for one test light) or 'average' (database "
        "sharpening for the mean training light), or a standard chromatic adaptation transform for comparison "
        "('bradford', 'cat02', 'cat16': colour-science's matrix after a camera -> XYZ map fitted on the world's "
        "surfaces). Prints T, the sharpened sensors' negative-lobe "
        "fractions and RMS mapping errors over the test lights (white = 255).",
    )
    world_arguments(p)
    p.add_argument(
        "--method",
        choices=["new", "database", "average", *ADAPTATION_METHODS],
        default="new",
        help="sharpening method (default: %(default)s)",
    )
    p.add_argument(
        "--light",
        type=whole,
        default=0,
        help="test-illuminant index for --method database (default: %(default)s)",
    )
    p.add_argument(
        "--lambda-p",
        type=number_within(limits.SHARPENING_PENALTY),
        default=None,
        help="positivity weight for --method new (default: the smallest leaving < 0.1%% negative training responses)",
    )
    p.add_argument(
        "--plot",
        default=None,
        help="write a PNG of the original and sharpened sensor curves",
    )
    overwrite_argument(p, "--plot and --json files")
    data_output_argument(p, "--json", "the transform and its summary")
    p.add_argument(
        "--rank-cameras",
        action="store_true",
        help="rank every available camera (each in the default world) by sharpness, then run the new method on the "
        "least sharp one and compare GW and ECRULE-ICA with and without it",
    )
    p.add_argument(
        "--scenes",
        type=count_within(limits.SCENES),
        default=1000,
        help="test scenes for --rank-cameras (default: %(default)s)",
    )
    p.set_defaults(func=run_sharpen)


def run_rank_cameras(args) -> int:
    import numpy as np

    from ccjax import experiments

    start = time.perf_counter()
    study = experiments.sharpening_study(args.data_dir, seed=args.seed, lambda_p=args.lambda_p, n_scenes=args.scenes)
    width = max(36, *(len(row["camera"]) + 2 for row in study.ranking))
    print(f"{'rank':>4}  {'camera':<{width}}{'sharpness':>10}{'BEST-LINEAR':>13}{'BEST-DIAGONAL':>15}")
    for index, row in enumerate(study.ranking, 1):
        print(
            f"{index:>4}  {row['camera']:<{width}}{row['ratio']:>10.3f}{row['best_linear']:>13.3f}"
            f"{row['best_diagonal']:>15.3f}"
        )
    new = study.sharpening
    print(
        f"least sharp: {study.camera}; new method: lambda_P {new.lambda_p:g}, {new.iterations} iterations, "
        f"objective {new.initial_objective:.4f} -> {new.objective:.4f}, "
        f"negative training responses {new.negative_fraction:.4%}"
    )
    print("T =", np.round(new.transform, 4).tolist())
    print(
        f"{study.n_scenes} scenes of 8 surfaces under test lights; RMS mapping error (white = 255), RMS angle, "
        "reverted:"
    )
    for row in study.comparisons:
        label, none, sharp = row["method"], row["none"], row["new"]
        if none is None:
            print(f"  {label:<12} pending (not registered)")
            continue
        change = sharp["map_rgb"] / none["map_rgb"] - 1.0
        print(
            f"  {label:<12} none {none['map_rgb']:8.2f} {none['angular']:6.2f}   new {sharp['map_rgb']:8.2f} "
            f"{sharp['angular']:6.2f} (reverted {sharp['reverted']})   mapping change {change:+.1%}"
        )
    print(f"done in {time.perf_counter() - start:.1f} s", file=sys.stderr)
    return 0


def run_sharpen(args) -> int:
    import numpy as np

    from ccjax import sharpening
    from ccjax.experiments import chapter5_report

    check_outputs([], [("--plot", args.plot), ("--json", args.json)], overwrite=args.overwrite)
    check_plot(args.plot)
    if args.rank_cameras:
        if args.plot:
            raise ValueError("--plot: plots one transform; it does not apply to --rank-cameras")
        if args.json:
            raise ValueError("--json: writes one transform; it does not apply to --rank-cameras")
        return run_rank_cameras(args)
    start = time.perf_counter()
    world = build_world(args)
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
    elif args.method in ADAPTATION_METHODS:
        (name,) = [name for name in sharpening.ADAPTATION_TRANSFORMS if name.lower() == args.method]
        transform = sharpening.adaptation_sharpening(world, name)
    else:
        n_lights = int(world.test_illuminants.shape[0])
        if not 0 <= args.light < n_lights:
            raise ValueError(f"--light: expected a test-illuminant index in [0, {n_lights}), got {args.light}")
        transform = sharpening.optimal_sharpening(world, world.test_illuminants[args.light : args.light + 1])[0]
    info["T"] = np.asarray(transform).tolist()
    info.update(chapter5_report.summary(world, transform))
    # The text for people goes to standard error when --json puts the data on standard output.
    with contextlib.redirect_stdout(table_stream(args)):
        print(f"world: {world.name}; camera {world.camera.name}; method {args.method}")
        print("T =")
        for row in np.asarray(transform):
            print("  " + " ".join(f"{v:9.5f}" for v in row))
        if args.method == "new":
            # Each tried lambda_P: the negative-lobe fraction, negative calibration responses and
            # iterations it gave, with the digits that tell them apart (not float64 noise).
            tried = ", ".join(
                f"{lp:g}: {fraction:.4g} / {negative:d} / {iterations:d}"
                for lp, fraction, negative, iterations in info["lambda_p_search"]
            )
            print(
                f"lambda_P = {info['lambda_p']:g} (tried lambda_P: negative-lobe fraction / negative responses / "
                f"iterations: {tried}); {info['iterations']} iterations, converged {info['converged']}"
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
            f"  BEST-DIAGONAL  none / T      {info['best_diagonal_unsharpened']:8.3f} / "
            f"{info['best_diagonal_sharpened']:8.3f}"
        )
        print(f"  ACTUAL         none / T      {info['actual_unsharpened']:8.3f} / {info['actual_sharpened']:8.3f}")
    if args.json:
        write(args.json, json.dumps(info, indent=1), overwrite=args.overwrite)
    if args.plot:
        title = f"{world.camera.name}: {args.method} sharpening"
        write_plot(
            args.plot,
            lambda file: chapter5_report.plot_sensors(world, transform, file, title=title),
            overwrite=args.overwrite,
        )
    print(f"done in {time.perf_counter() - start:.1f} s", file=sys.stderr)
    return 0


COMMANDS = [add_sharpen]
