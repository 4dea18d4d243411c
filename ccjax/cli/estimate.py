"""``ccjax estimate``: the light of each linear image (Barnard 1999 §4.4)."""

from __future__ import annotations

import json

from ccjax.cli import image_options
from ccjax.cli.common import world_arguments


def add_estimate(sub) -> None:
    p = sub.add_parser(
        "estimate",
        help="estimate the light of linear images",
        description="Estimate the illuminant of each image (files or folders); print its camera RGB (unit scale: "
        "saturation = 1) and (r,g).",
    )
    p.add_argument(
        "images",
        nargs="+",
        help="16-bit PNG/TIFF files, raw files (raw extra), or folders of them",
    )
    p.add_argument("--method", default=None, help="estimator label (see `ccjax methods`); or --model")
    p.add_argument(
        "--model",
        default=None,
        help="a trained model file (`ccjax train --out`, ccjax.runs.store.save_trained) instead of --method: the "
        "method and camera it was trained for come from its record",
    )
    world_arguments(p)
    image_options.image_arguments(p)
    p.add_argument(
        "--json",
        action="store_true",
        help="print a JSON list with one object per image: path, illuminant [R,G,B], rg, ok",
    )
    p.set_defaults(func=run_estimate)


def estimate_model(args):
    """``(label, model)`` of ``ccjax estimate``: ``--method`` (its model None: fitted once the
    images are checked), or the trained ``--model`` file (:func:`ccjax.load_model`).

    Raises:
        ValueError: neither or both given; a model file that cannot be read; a world-based
            ``--method`` without ``--camera``.
    """
    if (args.method is None) == (args.model is None):
        raise ValueError("--method, --model: give exactly one (a method label, or a trained model file)")
    if args.model is None:
        image_options.check_labels([args.method], args)
        image_options.require_camera([args.method], args)
        return args.method, None
    from pathlib import Path

    from ccjax.runs.store import load_model

    if not Path(args.model).is_file():
        raise ValueError(f"--model: no such model file: {args.model}")
    if args.world != "default" or args.camera is not None:
        raise ValueError("--model: the model's world comes from its file; leave out --world and --camera")
    image_options.check_labels([], args)
    model = load_model(args.model)
    return f"{Path(args.model).name}", model


def run_estimate(args) -> int:
    from ccjax import runs
    from ccjax.runs.sources import raise_failures

    label, model = estimate_model(args)
    source = image_options.image_source(args.images, args)
    run = runs.estimate_folder(
        source,
        model if model is not None else label,
        world=image_options.image_world(args) if model is None else None,
        preprocessing=args.preprocessing,
        dark=image_options.dark_fraction(args),
        progress=not args.no_progress,
    )
    records = [{k: r[k] for k in ("path", "illuminant", "rg", "ok")} for r in run.records()]
    if args.json:
        print(json.dumps(records, indent=1))
    else:
        names = [printable(r["path"]) for r in records]
        width = max([40, *(len(name) + 2 for name in names)])
        print(f"{'image':<{width}}{'R':>10}{'G':>10}{'B':>10}{'r':>8}{'g':>8}  ok")
        for name, r in zip(names, records, strict=True):
            # " " before every number: an estimate of 100 or more still stands apart.
            print(
                f"{name:<{width}}"
                + "".join(" " + f"{v:.5f}".rjust(9) for v in r["illuminant"])
                + "".join(" " + f"{v:.4f}".rjust(7) for v in r["rg"])
                + f"  {'yes' if r['ok'] else 'no'}"
            )
    raise_failures(list(run.failures.values()), len(source))
    return 0


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
