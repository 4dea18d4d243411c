"""``ccjax world``, ``ccjax cameras`` and ``ccjax methods``: what ccjax can build."""

from __future__ import annotations

from ccjax.cli.common import (
    build_world,
    check_camera_name,
    check_outputs,
    check_plot,
    data_output_argument,
    overwrite_argument,
    table_stream,
    world_arguments,
    write,
    write_plot,
)


def add_world(sub) -> None:
    p = sub.add_parser("world", help="describe a synthetic world and plot its chromaticities")
    world_arguments(p)
    p.add_argument(
        "--plot",
        default=None,
        help="write a PNG of the illuminant sets and reflectances in (r,g) (thesis Fig. 4.1)",
    )
    overwrite_argument(p, "--plot file")
    p.set_defaults(func=run_world)


def run_world(args) -> int:
    import numpy as np

    from ccjax import experiments

    check_outputs([], [("--plot", args.plot)], overwrite=args.overwrite)
    check_plot(args.plot)
    check_camera_name(args)
    world = build_world(args)
    print(f"world: {world.name}")
    for name, size in world.sizes().items():
        print(f"  {name:<22}{size}")
    print(f"  camera                {world.camera.name}")
    print(f"  canonical white RGB   [{', '.join(f'{v:.4f}' for v in np.asarray(world.canonical_white))}]")
    if args.world == "barnard1999":
        check = experiments.sfu321_check(world, args.data_dir)
        print("  perfect white under each lab light vs mean SFU-321 ground truth (degrees):")
        for row in check.rows:
            print(f"    {row['light']:<18}{row['angular']:6.2f}   ({row['images']} images)")
    if args.plot:
        write_plot(args.plot, lambda file: experiments.plot_world(world, file), overwrite=args.overwrite)
    return 0


def add_cameras(sub) -> None:
    p = sub.add_parser(
        "cameras",
        help="list the cameras ccjax can build; check ground truth against a camera's curves",
        description="List every camera ccjax can build and where its curves come from. With --check GT.csv: "
        "compare the ground-truth lights with the camera's Planckian/daylight locus (its responses to blackbodies "
        "of 1500-20000 K and CIE daylights of 4000-25000 K): the lower quartile over images of the (r,g) distance "
        "to the locus, above 0.008 when the images were probably taken with another camera's curves (exit "
        "status 1).",
    )
    world_arguments(p)
    p.add_argument(
        "--check",
        default=None,
        metavar="GT.csv",
        help="ground-truth CSV (header image,r,g,b) to check against --camera's curves",
    )
    p.add_argument(
        "--plot",
        default=None,
        help="with --check: write a PNG of the ground truth and the camera's locus in (r,g)",
    )
    overwrite_argument(p, "--plot file")
    p.set_defaults(func=run_cameras)


def run_cameras(args) -> int:
    from ccjax import experiments

    if args.check is None:
        if args.plot:
            raise ValueError("--plot: plots the camera check; give --check GT.csv too")
        print(experiments.camera_listing(args.data_dir).text())
        return 0
    import numpy as np

    from ccjax import io
    from ccjax.experiments import curve_check, plot_curve_check
    from ccjax.runs import store

    check_outputs([args.check], [("--plot", args.plot)], overwrite=args.overwrite)
    check_plot(args.plot)
    if args.world == "default" and args.camera is None:
        raise ValueError("--camera: name the camera to check the ground truth against (`ccjax cameras` lists them)")
    check_camera_name(args)
    truth = np.stack(list(io.read_ground_truth(args.check).values()))
    world = store.world(args.world, args.camera, seed=args.seed, data_dir=args.data_dir)
    check = curve_check(truth, world)
    print(check.message())
    if args.plot:
        write_plot(args.plot, lambda file: plot_curve_check(check, world, truth, file), overwrite=args.overwrite)
    return 0 if check.passed else 1


def registered_families() -> list:
    """The registry entries, one per family (:func:`ccjax.estimators.registry.available`)."""
    from ccjax.estimators import registry

    return registry.available()


def method_catalogue():
    """A :class:`ccjax.experiments.Report` of every registered family: grammar, example, input
    kind, whether the fit is traceable, description."""
    from ccjax.experiments import Column, Report

    rows = []
    for entry in registered_families():
        traceable = getattr(entry, "traceable_fit", None)
        rows.append(
            {
                "grammar": getattr(entry, "grammar", None) or entry.pattern.pattern,
                "example": entry.example,
                "input_kind": getattr(entry, "input_kind", None),
                "traceable_fit": None if traceable is None else ("yes" if traceable else "no"),
                "description": entry.description,
            }
        )
    columns = [
        Column("grammar", "label grammar"),
        Column("example", gap=2),
        Column("input_kind", "input", gap=2, missing="?"),
        Column("traceable_fit", "traceable fit", gap=2, missing="?"),
        Column("description", gap=2),
    ]
    return Report(rows, columns)


def add_methods(sub) -> None:
    p = sub.add_parser(
        "methods",
        help="list the estimator families and their labels",
        description="Every registered estimator family: the grammar of its labels, an example label, its input "
        "(surface lists or images), whether its fit can be traced by JAX (jit/grad through the fit), and a "
        "description.",
    )
    data_output_argument(p, "--json", "the catalogue")
    overwrite_argument(p, "--json file")
    p.set_defaults(func=run_methods)


def run_methods(args) -> int:
    check_outputs([], [("--json", args.json)], overwrite=args.overwrite)
    catalogue = method_catalogue()
    print(catalogue.text(), file=table_stream(args))  # standard error when --json puts the data on standard output
    if args.json:
        write(args.json, catalogue.to_json(), overwrite=args.overwrite)
    return 0


COMMANDS = [add_world, add_cameras, add_methods]
