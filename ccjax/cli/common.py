"""Arguments and helpers shared by the command groups: the world options, list parsing, output files."""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Iterable
from pathlib import Path


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


def check_camera_name(args) -> None:
    """Refuse an unknown ``--camera`` before any work, pointing to ``ccjax cameras``.

    Arguments:
        args: the parsed arguments (``camera``, ``data_dir``).

    Returns:
        None.

    Raises:
        ValueError: the name is not one ccjax can build (close names suggested).
    """
    import difflib

    from ccjax.camera import cameras

    name = getattr(args, "camera", None)
    if name is None:
        return
    known = cameras(getattr(args, "data_dir", None))
    if name not in known:
        close = difflib.get_close_matches(name, list(known), n=3, cutoff=0.6)
        hint = f"; did you mean {' or '.join(repr(c) for c in close)}?" if close else ""
        raise ValueError(
            f"--camera: unknown camera {name!r}{hint} `ccjax cameras` lists the {len(known)} names "
            "('Sony DXC-930' and 'Jiang: <model>' need the external data, --data-dir)"
        )


def build_world(args):
    """The world of :func:`world_arguments`, through the store (:func:`ccjax.runs.store.world`)."""
    from ccjax.runs import store

    check_camera_option(args)
    return store.world(args.world, args.camera, seed=args.seed, data_dir=args.data_dir)


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
    """Write ``text`` to ``path`` atomically (``"-"``: standard output).

    Arguments:
        path: the file, or ``"-"``.
        text: the contents.

    Returns:
        None.
    """
    from ccjax.io.files import write_file

    if path == "-":
        sys.stdout.write(text + ("\n" if not text.endswith("\n") else ""))
    else:
        write_file(path, text)
        print(f"wrote {path}", file=sys.stderr)


def path_key(path: str | os.PathLike) -> str:
    """:func:`ccjax.io.files.path_key` (imported on use: the command modules import only the
    standard library until the command runs).

    Arguments:
        path: any path.

    Returns:
        The key.
    """
    from ccjax.io.files import path_key as key

    return key(path)


def check_output_file(path: str | os.PathLike, option: str, *, overwrite: bool = True) -> None:
    """Refuse an output file that cannot be written, before any work is done.

    Arguments:
        path: the output file (``"-"``, standard output, is always accepted).
        option: the argument's name for the message (``"--json"``, ``"OUT"``).
        overwrite: whether an existing file may be replaced.

    Returns:
        None.

    Raises:
        ValueError: ``path`` is a folder, exists while ``overwrite`` is false, or its folder is
            missing or not writable.
    """
    if str(path) == "-":
        return
    path = Path(path)
    if path.is_dir():
        raise ValueError(f"{option}: {path} is a folder; give a file name")
    if path.exists() and not overwrite:
        raise ValueError(f"{option}: {path} exists (use --overwrite to replace it)")
    check_output_folder(path.parent, option, written=path)


def check_output_folder(folder: str | os.PathLike, option: str, *, written: str | os.PathLike | None = None) -> None:
    """Refuse an output folder that cannot be written (or created), before any work is done.

    Arguments:
        folder: the folder (may not exist yet if its nearest existing ancestor is writable).
        option: the argument's name for the message.
        written: the file to be written there, for the message (default: the folder).

    Returns:
        None.

    Raises:
        ValueError: ``folder`` or an ancestor is a file, or the nearest existing one is not writable.
    """
    folder = Path(folder).absolute()
    written = folder if written is None else written
    existing = folder
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise ValueError(f"{option}: {written} cannot be written: {existing} is not a folder")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise ValueError(f"{option}: {written} cannot be written: folder {existing} is not writable")


def check_distinct(inputs: Iterable[str | os.PathLike], outputs: Iterable[tuple[str, str | os.PathLike]]) -> None:
    """Refuse outputs that would replace an input or each other (case-insensitively).

    Arguments:
        inputs: the files read.
        outputs: ``(option, path)`` pairs of the files written.

    Returns:
        None.

    Raises:
        ValueError: naming both paths.
    """
    read = {path_key(path): Path(path) for path in inputs}
    written: dict[str, tuple[str, Path]] = {}
    for option, path in outputs:
        key = path_key(path)
        if key in read:
            raise ValueError(f"{option}: {path} would overwrite the input {read[key]}")
        if key in written:
            other, first = written[key]
            raise ValueError(f"{option}: {path} and {other} {first} are the same file")
        written[key] = (option, Path(path))


PLOT_SUFFIX = ".png"


def check_plot(path: str | os.PathLike | None, option: str = "--plot") -> None:
    """Refuse a plot path that cannot be written, before any work (nothing for ``None``).

    Arguments:
        path: the PNG to write, or None.
        option: the argument's name for the message.

    Returns:
        None.

    Raises:
        ValueError: not a ``.png`` name, a folder, or its folder is missing or not writable.
    """
    if path is None:
        return
    check_output_file(path, option)
    if Path(path).suffix.lower() != PLOT_SUFFIX:
        raise ValueError(f"{option}: {path} must end in .png")


def write_plot(path: str | os.PathLike, draw) -> None:
    """Write a plot and say so: ``draw(path)`` saves it (the plotting functions write through
    :func:`ccjax.io.files.write_figure`, atomically), then the path is reported on stderr.

    Arguments:
        path: the ``.png`` file (checked first with :func:`check_plot`).
        draw: a function of the path that saves the figure there.

    Returns:
        None.
    """
    draw(path)
    print(f"wrote {path}", file=sys.stderr)


def write_outputs(args, report) -> None:
    """Write ``report`` as JSON / CSV where ``--json`` / ``--csv`` name a file."""
    if getattr(args, "json", None):
        write(args.json, report.to_json())
    if getattr(args, "csv", None):
        write(args.csv, report.to_csv())


def start_processes() -> bool:
    """Join a multi-process run when JAX's standard distributed environment says so
    (:func:`ccjax.runs.hosts.initialize_from_environment`: ``JAX_COORDINATOR_ADDRESS``,
    ``JAX_NUM_PROCESSES``, ``JAX_PROCESS_ID``, or a Slurm / Open MPI launch), before any JAX work.

    Returns:
        True when this process writes the outputs (process 0, or the only process).
    """
    import jax

    from ccjax.runs import hosts

    hosts.initialize_from_environment()
    return jax.process_index() == 0


def item_mesh_if_distributed():
    """The item mesh over every process's devices when several processes run, else ``None``
    (one process keeps its default device, as without the distributed environment)."""
    import jax

    from ccjax.runs import hosts

    return hosts.item_mesh() if jax.process_count() > 1 else None
