"""``ccjax estimate``: the light of each linear image (Barnard 1999 §4.4)."""

from __future__ import annotations

import json

from ccjax.cli import image_options
from ccjax.cli.common import (
    check_outputs,
    data_output_argument,
    overwrite_argument,
    table_stream,
    world_arguments,
    write,
)


def add_estimate(sub) -> None:
    p = sub.add_parser(
        "estimate",
        help="estimate the light of linear images",
        description="Estimate the illuminant of each image (files or folders); print the camera RGB of white under "
        "it, scaled so that its largest channel is 1 (the scale of ccjax's lights; an image's exposure leaves the "
        "light's brightness unknown), its (r,g) and its status: estimated; relaxed (the method found no answer "
        "meeting all its constraints and gives the nearest one, e.g. a gamut method with no feasible map); fell "
        "back (no answer: the model's fallback light); no usable pixels (every pixel clipped, dark or masked: "
        "the fallback light). A warning line on stderr counts the images that were not estimated.",
    )
    p.add_argument(
        "images",
        nargs="+",
        help="16-bit PNG/TIFF files, raw files (raw extra), or folders of them",
    )
    image_options.model_arguments(p, "estimate")
    world_arguments(p)
    image_options.image_arguments(p)
    data_output_argument(
        p,
        "--json",
        "a list with one object per image (path, illuminant [R,G,B] with largest channel 1, rg, ok, status: "
        "estimated, relaxed, fell back, no usable pixels)",
    )
    overwrite_argument(p, "--json file")
    p.set_defaults(func=run_estimate)


def estimate_model(args):
    """``(label, model)`` of ``ccjax estimate``: ``--method`` (its model None: fitted once the
    images are checked), or the trained ``--model`` file (:func:`ccjax.load_model`).

    Raises:
        ValueError: neither or both given; a model file that cannot be read or whose record names
            another camera than ``--camera``; a world-based ``--method`` without ``--camera``; a
            ``--method`` that must be trained first (FFCC, log-chroma-mlp, any-camera).
    """
    from ccjax.estimators import registry

    if (args.method is None) == (args.model is None):
        raise ValueError("--method, --model: give exactly one (a method label, or a trained model file)")
    if args.model is None:
        image_options.check_labels([args.method], args)
        registry.refuse_untrained(args.method, "--method")
        image_options.require_camera([args.method], args)
        return args.method, None
    image_options.check_labels([], args)
    name, model, _ = image_options.trained_model(args)
    return name, model


def run_estimate(args) -> int:
    from ccjax import runs
    from ccjax.runs.sources import raise_failures

    label, model = estimate_model(args)
    check_outputs(args.images, [("--json", args.json)], overwrite=args.overwrite)
    source = image_options.image_source(args.images, args)
    run = runs.estimate_folder(
        source,
        model if model is not None else label,
        world=image_options.image_world(args) if model is None else None,
        preprocessing=args.preprocessing,
        dark=image_options.dark_fraction(args),
        progress=not args.no_progress,
    )
    records = [
        {
            "path": r["path"],
            "illuminant": r["illuminant"],
            "rg": r["rg"],
            "ok": r["ok"],
            "status": STATUS_WORDS[r["status"]],
        }
        for r in run.records()
    ]
    out = table_stream(args)  # standard error when --json puts the data on standard output
    names = [printable(r["path"]) for r in records]
    width = max([40, *(len(name) + 2 for name in names)])
    print(f"{'image':<{width}}{'R':>10}{'G':>10}{'B':>10}{'r':>8}{'g':>8}  status", file=out)
    for name, r in zip(names, records, strict=True):
        print(
            f"{name:<{width}}"
            + "".join(" " + f"{v:.5f}".rjust(9) for v in r["illuminant"])
            + "".join(" " + f"{v:.4f}".rjust(7) for v in r["rg"])
            + f"  {r['status']}",
            file=out,
        )
    if args.json:
        write(args.json, json.dumps(records, indent=1), overwrite=args.overwrite)
    warn_not_estimated(records)
    raise_failures(list(run.failures.values()), len(source))
    return 0


STATUS_WORDS = {"estimated": "estimated", "relaxed": "relaxed", "empty_set": "fell back", "no_data": "no usable pixels"}
"""How ``ccjax estimate`` names each :class:`ccjax.Status` (its ``name.lower()``) in tables and JSON."""


def warn_not_estimated(records: list[dict]) -> None:
    """One warning line on stderr when any image's light was not estimated, counting each status.

    Arguments:
        records: ``ccjax estimate``'s records (with ``status`` in :data:`STATUS_WORDS`' words).
    """
    import collections
    import sys

    counts = collections.Counter(r["status"] for r in records if r["status"] != "estimated")
    if counts:
        listed = ", ".join(f"{word} {count}" for word, count in sorted(counts.items()))
        print(
            f"ccjax estimate: warning: {sum(counts.values())} of {len(records)} images not estimated ({listed}); "
            "see the status column (`ccjax estimate --help` says what each means)",
            file=sys.stderr,
        )


def printable(text: str) -> str:
    """``text`` with control characters (a newline in a file name) escaped, so each table row is
    one line.

    Arguments:
        text: a path or label.

    Returns:
        The text, with ``\\n``, ``\\t``, ``\\x1b`` ... in place of control characters.
    """
    return "".join(char if char.isprintable() else repr(char)[1:-1] for char in text)


COMMANDS = [add_estimate]
