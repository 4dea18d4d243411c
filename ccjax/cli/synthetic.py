"""``ccjax compare`` and ``ccjax reproduce``: synthetic sweeps and the thesis tables (Barnard 1999 ch. 4-10)."""

from __future__ import annotations

import sys
import time

from ccjax import limits
from ccjax._numbers import decimal
from ccjax.cli.common import (
    build_world,
    check_outputs,
    check_plot,
    count_within,
    data_output_argument,
    int_list,
    item_mesh_if_distributed,
    label_list,
    overwrite_argument,
    seed,
    start_processes,
    table_stream,
    world_arguments,
    write,
    write_outputs,
    write_plot,
)
from ccjax.cli.option_checks import data_folder

DEFAULT_COMPARE_METHODS = [
    "NOTHING",
    "AVE-ILLUM",
    "GW",
    "DB-GW",
    "RETINEX",
    "shades-of-grey-p6",
    # ND (Barnard 1999 §6.1): the default world's fluorescent and LED lights break the diagonal
    # model, so the plain ECRULE gamut goes empty (relaxed scenes) as surfaces grow; ND-ECRULE-MV
    # keeps improving toward zero error (§6.3). SCWIA-12 (§6.2) is the thesis' choice for few
    # surfaces, but its error levels off above 256 surfaces in this world (the ND feasible set
    # stays wide and it averages over it; "MV wins as surfaces increase", §6.3), so it is not a
    # default here.
    "ND-ECRULE-MV",
    "C-by-C-MMSE",
    "RGB-C-by-C-MMSE",
    "NEURAL-NET",
]
"""The comparison set of ``ccjax compare`` (those registered and, if learned, trained)."""

SUMMARIES = ("rms", "mean", "median", "trimean", "best25", "worst25", "max")


def add_compare(sub) -> None:
    p = sub.add_parser(
        "compare",
        help="run a synthetic comparison sweep (the main job)",
        description="Run every method on the same synthetic scenes for each number of surfaces; "
        "print RMS (r,g) and angular errors, and per surface count the share of scenes whose estimate "
        "was relaxed (Status.RELAXED) or fell back to the model's fallback light (NO_DATA, EMPTY_SET).",
    )
    world_arguments(p)
    p.add_argument(
        "--methods",
        type=label_list,
        default=None,
        help="comma-separated labels of surface estimators (default: the built-in comparison set; `ccjax methods` "
        "lists each label's input). Scenes here are surface lists, with no pixels or neighbours: image "
        "estimators (grey-edge-<n>-<p>-<sigma>, FFCC) are scored on images with `ccjax evaluate DIR`",
    )
    p.add_argument(
        "--surfaces",
        type=int_list,
        default=[4, 8, 16, 32, 64],
        help="comma-separated surface counts (default: 4,8,16,32,64)",
    )
    p.add_argument(
        "--scenes",
        type=count_within(limits.SCENES),
        default=1000,
        help="scenes per surface count (default: %(default)s)",
    )
    p.add_argument(
        "--specular",
        action="store_true",
        help="add the thesis' specularities (25 %% of surfaces, +U(0,2) x white)",
    )
    p.add_argument(
        "--clip",
        type=decimal,
        default=None,
        help="discard surfaces with a channel above this level, thesis units (white = 255)",
    )
    p.add_argument("--plot", default=None, help="write a PNG of error versus number of surfaces")
    data_output_argument(p, "--json", "the tidy table")
    data_output_argument(p, "--csv", "the tidy table")
    p.add_argument(
        "--recompute",
        action="store_true",
        help="compute every (method, surface count) cell again instead of reading it from the cache of "
        "sweeps (fits still come from the cache of fits)",
    )
    overwrite_argument(p, "--plot, --json and --csv files")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    # The parser's own error (usage, one line, exit 2) for checks across options, made once all
    # of them are parsed (check_scene_results).
    p.set_defaults(func=run_compare, usage_error=p.error)


PLOTTED = ("rg", "angular")
"""The statistics of ``compare --plot``'s panels (RMS over scenes)."""


def run_compare(args) -> int:
    import jax

    from ccjax import _cache, experiments
    from ccjax.cli import STARTED as start
    from ccjax.runs import CompileLog

    imported = time.perf_counter()
    check_scene_results(args)
    check_outputs([], [("--plot", args.plot), ("--json", args.json), ("--csv", args.csv)], overwrite=args.overwrite)
    check_plot(args.plot)
    out = table_stream(args)  # stderr when --json - or --csv - puts the data on stdout
    if args.methods:
        check_surface_methods(args.methods)
    writer = start_processes()
    # Compiled programs go to <cache>/xla, so a second run skips compilation (as its fits are read
    # from <cache>/fits by the sweep).
    _cache.enable_compilation_cache()
    with CompileLog() as log:
        world = build_world(args)
        methods = args.methods or experiments.runnable_methods(DEFAULT_COMPARE_METHODS, world)
        # Fitted ahead (the sweep then finds them in the store's memory) so that the fits' time is
        # apart from the sweep's compiling and running.
        counts: dict[str, int] = {}
        experiments.resolve_methods(world, methods, counts, progress=not args.no_progress)
        fitted = time.perf_counter()
        result = _sweep(args, world, methods)
    swept = time.perf_counter()
    if not writer:  # under jax.distributed every process holds the pooled result; one reports it
        return 0
    n_cells = len(result.methods) * len(result.surfaces)
    print(f"world: {world.name}; {args.scenes} scenes per surface count; RMS over scenes", file=out)
    print(
        f"fits: {counts.get('cached', 0)} from cache, {counts.get('fitted', 0)} fitted ({_cache.cache_directory()})",
        file=out,
    )
    print(
        f"results: {result.cells_from_cache} of {n_cells} (method, surfaces) cells from cache, "
        f"{n_cells - result.cells_from_cache} computed",
        file=out,
    )
    print(result.table("rg"), file=out)
    print(file=out)
    print(result.table("angular"), file=out)
    print(file=out)
    # Estimate.status per surface count: a rising relaxed share is how a gamut method's failure
    # to find a feasible light shows (thesis §4.3.2), before its error does.
    print(result.status_table(), file=out)
    if args.plot:
        title = f"{world.name}: {args.scenes} scenes per point"
        # The figure is a function of the plotted summaries, labels and title: a repeated run
        # writes the stored PNG.
        plotted = [[[result.value(m, n, s) for n in result.surfaces] for m in result.methods] for s in PLOTTED]
        write_plot(
            args.plot,
            lambda file: experiments.plot_sweep(result, file, statistics=PLOTTED, title=title),
            overwrite=args.overwrite,
            drawn_from=("compare", title, result.methods, result.surfaces, plotted),
        )
    if args.json or args.csv:
        write_outputs(args, result.report(SUMMARIES))
    fit_compile, sweep_compile = log.seconds() - log.seconds(fitted), log.seconds(fitted)
    print(
        f"done in {time.perf_counter() - start:.1f} s: import {imported - start:.1f} s, fit {fitted - imported:.1f} s "
        f"(world and fits, {fit_compile:.1f} s of it compiling), compile {sweep_compile:.1f} s, "
        f"run {max(swept - fitted - sweep_compile, 0.0):.1f} s, output {time.perf_counter() - swept:.1f} s; "
        f"{log.programs} programs built: {log.compiled} compiled, {log.cache_hits} from the persistent "
        f"compilation cache ({jax.default_backend()})",
        file=sys.stderr,
    )
    return 0


def check_scene_results(args) -> None:
    """Refuse, as the parser refuses an option past its limit (usage, one line, exit 2), a
    comparison whose scenes x surface counts x methods is over :data:`ccjax.limits.SCENE_RESULTS`
    (each keeps a few numbers per scene), before anything is built. Without ``--methods`` the
    default set is counted whole (an untrained net among it is dropped later).

    Arguments:
        args: the parsed arguments (``scenes``, ``surfaces``, ``methods``, ``usage_error``).
    """
    methods = args.methods or DEFAULT_COMPARE_METHODS
    factors = ((args.scenes, "scenes"), (len(set(args.surfaces)), "surface counts"), (len(methods), "methods"))
    try:
        limits.require_product(factors, "--scenes", limits.SCENE_RESULTS)
    except ValueError as error:
        args.usage_error(str(error))


def check_surface_methods(labels: list[str]) -> None:
    """Refuse image estimators in ``compare --methods`` before anything is fitted, naming them and
    the command that scores them, and methods that must be trained first.

    Raises:
        ValueError: a label of an image estimator or of an untrained learned method (an unknown
            label is left to the fit's message).
    """
    from ccjax.estimators import registry

    images, known = [], []
    for label in labels:
        try:
            entry, _ = registry.lookup(label)
        except ValueError:
            continue
        known.append(label)
        if entry.input_kind == "image":
            images.append(label)
    if images:
        raise ValueError(
            f"--methods: {', '.join(images)}: image estimators; compare's scenes are surface lists (no pixels, no "
            "neighbours): score them on images with `ccjax evaluate DIR --methods ...` (a folder of linear images "
            "with ground truth, e.g. written by ccjax.io.write_dataset)"
        )
    registry.refuse_untrained([label for label in labels if label in known], "--methods")


def _sweep(args, world, methods):
    """The comparison sweep of ``ccjax compare``."""
    import jax

    from ccjax import experiments

    return experiments.sweep(
        world,
        methods,
        args.surfaces,
        args.scenes,
        jax.random.key(args.seed),
        specular=args.specular or None,
        clip=None if args.clip is None else args.clip / 255.0,
        progress=not args.no_progress,
        # Each cell's per-scene errors are cached under a key of everything they depend on
        # (ccjax's code included), so a repeated comparison reads what it has computed before.
        cache=not args.recompute,
        mesh=item_mesh_if_distributed(),
    )


def add_reproduce(sub) -> None:
    p = sub.add_parser(
        "reproduce",
        help="reproduce a thesis table on the thesis world",
        description="Run a table of Barnard (1999) with the thesis protocol on World.barnard1999 and print ours, "
        "the thesis value, the relative difference and our value's sampling error per cell (the standard "
        "error over scenes: delta method for the RMS, SE(mean(e^2)) / (2 RMS)).",
    )
    p.add_argument("table", help="table id, e.g. 4.2, 4.3, 4.4, 5.1, 6.1, 10.1, 10.2")
    p.add_argument(
        "--methods",
        type=label_list,
        default=None,
        help="comma-separated labels (default: every registered row)",
    )
    p.add_argument(
        "--scenes",
        type=count_within(limits.SCENES),
        default=1000,
        help="scenes per condition (default: %(default)s)",
    )
    p.add_argument(
        "--data-dir",
        type=data_folder,
        default=None,
        help="external data directory (else $CCJAX_DATA, else ../shared/data)",
    )
    p.add_argument("--seed", type=seed, default=0)
    data_output_argument(p, "--json", "the table (ours, the thesis value, differences, sampling errors)")
    overwrite_argument(p, "--json file")
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(func=run_reproduce)


def run_reproduce(args) -> int:
    import jax

    from ccjax import experiments, thesis
    from ccjax.runs import store

    check_outputs([], [("--json", args.json)], overwrite=args.overwrite)
    world = store.world("barnard1999", seed=args.seed, data_dir=args.data_dir)
    key = jax.random.key(args.seed)
    if args.table == "5.1":
        # Table 5.1 has its own protocol (sharpening variants, whole-database mapping error).
        from ccjax.experiments import chapter5_report

        result = chapter5_report.reproduce_5_1(world, args.methods, args.scenes, key, progress=not args.no_progress)
    else:
        methods = args.methods
        if methods is None and args.table in thesis.TABLES:
            methods = experiments.runnable_methods(list(thesis.TABLES[args.table]), world)
        result = experiments.reproduce(args.table, world, methods, args.scenes, key, progress=not args.no_progress)
    print(result.text(), file=table_stream(args))  # standard error when --json puts the data on standard output
    if args.json:
        write(args.json, result.to_json(), overwrite=args.overwrite)
    return 0


COMMANDS = [add_compare, add_reproduce]
