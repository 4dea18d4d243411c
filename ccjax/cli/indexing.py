"""``ccjax indexing``: colour indexing with each estimator as preprocessing (Barnard 1999 ch. 11)."""

from __future__ import annotations

import json
import sys
import time

from ccjax import limits
from ccjax._numbers import whole
from ccjax.cli.common import (
    check_outputs,
    count_within,
    data_output_argument,
    label_list,
    overwrite_argument,
    table_stream,
    world_arguments,
    write,
)
from ccjax.cli.image_options import check_labels, image_world

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


def add_indexing(sub) -> None:
    p = sub.add_parser(
        "indexing",
        help="colour indexing with each estimator as preprocessing (chapter 11)",
        description="Synthetic version of Barnard (1999) chapter 11: objects of random reflectance patches, database "
        "under the canonical light, queries under a subset of test lights; print each method's rg error, "
        "Score(1..3), rank counts, and the Spearman correlation of score with error.",
    )
    world_arguments(p)
    p.add_argument(
        "--methods",
        type=label_list,
        default=None,
        help="comma-separated labels; ACTUAL = the true light (default: baselines, grey edge and every registered "
        "gamut / C-by-C row)",
    )
    p.add_argument(
        "--objects",
        type=count_within(limits.OBJECTS),
        default=50,
        help="objects in the database (default: %(default)s)",
    )
    p.add_argument(
        "--surfaces",
        type=whole,
        default=8,
        help="reflectances per object (default: %(default)s)",
    )
    p.add_argument(
        "--lights",
        type=whole,
        default=20,
        help="test lights per object (default: %(default)s)",
    )
    p.add_argument(
        "--size",
        type=count_within(limits.INDEXING_SIZE),
        default=64,
        help="image side in pixels (default: %(default)s)",
    )
    p.add_argument(
        "--preprocessing",
        default="ave5",
        help="preprocessing for surface-list methods (default: %(default)s)",
    )
    data_output_argument(p, "--json", "the table and its rank correlations")
    overwrite_argument(p)
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(func=run_indexing)


def run_indexing(args) -> int:
    import jax

    from ccjax import experiments
    from ccjax.experiments import indexing
    from ccjax.preprocessing import as_preprocessing

    # Everything the run needs is checked before the world is built: a bad option found after the
    # slow build would lose it.
    check_outputs([], [("--json", args.json)], overwrite=args.overwrite)
    check_labels([label for label in args.methods or [] if label != "ACTUAL"])
    as_preprocessing(args.preprocessing)
    for option in ("objects", "surfaces", "lights", "size"):
        if getattr(args, option) < 1:
            raise ValueError(f"--{option}: expected a positive number, got {getattr(args, option)}")
    methods = args.methods or [m for m in DEFAULT_INDEXING_METHODS if m == "ACTUAL" or experiments.is_registered(m)]
    start = time.perf_counter()
    world = image_world(args)
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
    out = table_stream(args)  # standard error when --json puts the data on standard output
    print(
        f"world: {world.name}; {args.objects} objects x {args.lights} lights, {args.surfaces} reflectances each, "
        f"{args.size}x{args.size} px",
        file=out,
    )
    print(result.table(), file=out, flush=True)
    if args.json:
        write(
            args.json,
            json.dumps(
                {
                    "rows": result.rows,
                    "spearman_score3": result.spearman(),
                    "spearman_score1": result.spearman("score1"),
                },
                indent=1,
            ),
            overwrite=args.overwrite,
        )
    print(f"done in {time.perf_counter() - start:.1f} s", file=sys.stderr)
    return 0


COMMANDS = [add_indexing]
