"""Arguments and helpers shared by the command groups: the world options, list parsing, output files."""

from __future__ import annotations

import argparse
import sys


def world_arguments(parser: argparse.ArgumentParser, default: str = "default") -> None:
    """``--world``, ``--camera``, ``--data-dir`` and ``--seed``."""
    parser.add_argument(
        "--world",
        choices=["default", "barnard1999"],
        default=default,
        help="synthetic world (default: %(default)s)",
    )
    parser.add_argument(
        "--camera",
        default=None,
        help="camera name for the default world (see `ccjax cameras`)",
    )
    parser.add_argument(
        "--data-dir",
        default=None,
        help="external data directory (else $CCJAX_DATA, else ../shared/data)",
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of the illuminant sets and scenes")


def check_camera_option(args) -> None:
    if args.world == "barnard1999" and args.camera:
        raise SystemExit("--camera applies to --world default only (barnard1999 is the Sony DXC-930 world)")


def build_world(args):
    """The world of :func:`world_arguments`."""
    from ccjax.world import World

    check_camera_option(args)
    if args.world == "barnard1999":
        return World.barnard1999(args.data_dir, seed=args.seed)
    return World.default(args.camera or "Canon EOS 5D Mark II", seed=args.seed)


def int_list(text: str) -> list[int]:
    """``"4,8,16"`` -> ``[4, 8, 16]`` (an argparse type)."""
    try:
        values = [int(part) for part in text.split(",") if part.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated integers, got {text!r}") from None
    if not values:
        raise argparse.ArgumentTypeError("empty list")
    return values


def label_list(text: str) -> list[str]:
    """``"GW, RETINEX"`` -> ``["GW", "RETINEX"]`` (an argparse type)."""
    return [part.strip() for part in text.split(",") if part.strip()]


def write(path: str, text: str) -> None:
    """Write ``text`` to ``path`` (``"-"``: standard output)."""
    if path == "-":
        sys.stdout.write(text + ("\n" if not text.endswith("\n") else ""))
    else:
        with open(path, "w") as f:
            f.write(text)
        print(f"wrote {path}", file=sys.stderr)


def write_outputs(args, report) -> None:
    """Write ``report`` as JSON / CSV where ``--json`` / ``--csv`` name a file."""
    if getattr(args, "json", None):
        write(args.json, report.to_json())
    if getattr(args, "csv", None):
        write(args.csv, report.to_csv())
