"""Arguments and helpers shared by the command groups: the world options, list parsing, output files."""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable, Iterable
from pathlib import Path

from ccjax import limits
from ccjax._numbers import decimal, whole
from ccjax.cli.number_lists import number_list
from ccjax.cli.option_checks import OptionError, data_folder


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
        type=data_folder,
        default=None,
        help="external data directory (else $CCJAX_DATA, else ../shared/data)",
    )
    parser.add_argument("--seed", type=seed, default=0, help="seed of the illuminant sets and scenes")


def pretrain_arguments(parser: argparse.ArgumentParser) -> None:
    """``--pretrain-camera`` and ``--pretrain-images``: pretraining from spectra
    (:func:`ccjax.training.pretrain`)."""
    parser.add_argument(
        "--pretrain-camera",
        default=None,
        metavar="CAMERA",
        help="pretrain on Mondrians rendered with this embedded camera's curves (the world's lights near its "
        "Planckian locus, highlights, noise, clipping, the photographs' preprocessing), then fine-tune on the "
        "photographs (FFCC: its regulariser centred on the pretrained model; the Adam loop: started from it)",
    )
    parser.add_argument(
        "--pretrain-images",
        type=count_within(limits.RENDERED_IMAGES),
        default=None,
        help="with --pretrain-camera: rendered images (default: 2000; cached)",
    )


def pretraining_setting(args):
    """The :class:`ccjax.training.Pretraining` of ``--pretrain-camera`` and
    ``--pretrain-images``, or None without them; refuses ``--pretrain-images`` alone and an
    unknown camera."""
    if args.pretrain_camera is None:
        if args.pretrain_images is not None:
            raise OptionError("--pretrain-images: applies with --pretrain-camera only")
        return None
    from ccjax.training import Pretraining

    # An unknown camera is named by its option before any work (the renderer would say "camera:").
    check_camera(args.pretrain_camera, getattr(args, "data_dir", None), option="--pretrain-camera")
    try:
        images = {} if args.pretrain_images is None else {"images": args.pretrain_images}
        return Pretraining(args.pretrain_camera, **images)
    except ValueError as error:
        raise OptionError(f"--pretrain-{error}") from None


def check_camera_option(args) -> None:
    if args.world == "barnard1999" and args.camera:
        raise OptionError("--camera: applies to --world default only (barnard1999 is the Sony DXC-930 world)")


def check_camera_name(args) -> None:
    """Refuse an unknown ``--camera`` before any work, pointing to ``ccjax cameras``.

    Arguments:
        args: the parsed arguments (``camera``, ``data_dir``).

    Returns:
        None.

    Raises:
        ValueError: the name is not one ccjax can build (close names suggested).
    """
    check_camera(getattr(args, "camera", None), getattr(args, "data_dir", None))


def check_camera(name: str | None, data_dir=None, option: str = "--camera") -> None:
    """Refuse an unknown camera name given by ``option`` before any work, pointing to ``ccjax cameras``.

    Arguments:
        name: the camera's name (None: not given, nothing to check).
        data_dir: the external data directory (its cameras are known too).
        option: the option that gave it, for the message.

    Returns:
        None.

    Raises:
        ValueError: the name is not one ccjax can build (close names suggested).
    """
    import difflib

    from ccjax.camera import cameras

    if name is None:
        return
    known = cameras(data_dir)
    if name not in known:
        close = difflib.get_close_matches(name, list(known), n=3, cutoff=0.6)
        hint = f"; did you mean {' or '.join(repr(c) for c in close)}?" if close else ";"
        raise ValueError(
            f"{option}: unknown camera {name!r}{hint} `ccjax cameras` lists the {len(known)} names "
            "('Sony DXC-930' and 'Jiang: <model>' need the external data, --data-dir)"
        )


def build_world(args):
    """The world of :func:`world_arguments`, through the store (:func:`ccjax.runs.store.world`)."""
    from ccjax.runs import store

    check_camera_option(args)
    return store.world(args.world, args.camera, seed=args.seed, data_dir=args.data_dir)


int_list = number_list(whole, "comma-separated integers")
"""The argparse type of a list of integers: ``"4,8,16"`` -> ``(4, 8, 16)``."""


def label_list(text: str) -> list[str]:
    """``"GW, RETINEX"`` -> ``["GW", "RETINEX"]`` (an argparse type; an empty list is refused,
    never read as "the default set")."""
    labels = [part.strip() for part in text.split(",") if part.strip()]
    if not labels:
        raise argparse.ArgumentTypeError(f"expected comma-separated labels, got {text!r}")
    return labels


def count_within(limit: limits.Limit, low: int = 1) -> Callable[[str], int]:
    """An argparse type: an integer in ``[low, limit]`` (``1e6`` spelled as a float is accepted);
    past the limit the message names it and the option.

    Arguments:
        limit: the bound (:mod:`ccjax.limits`).
        low: the smallest accepted value.

    Returns:
        The type function.
    """

    def parse(text: str) -> int:
        try:
            value = decimal(text) if any(c in text.lower() for c in ".e") else whole(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if isinstance(value, float) and not value.is_integer():
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}")
        try:
            return limits.require_count(int(value), "value", low, limit)
        except ValueError as error:
            raise argparse.ArgumentTypeError(str(error).removeprefix("value: ")) from None

    parse.__name__ = "integer"  # argparse names the type in its own messages
    return parse


def number_within(limit: limits.Limit, low: float = 0.0) -> Callable[[str], float]:
    """An argparse type: a finite number in ``[low, limit]``.

    Arguments:
        limit: the bound (:mod:`ccjax.limits`).
        low: the smallest accepted value.

    Returns:
        The type function.
    """

    def parse(text: str) -> float:
        try:
            return limits.check_value(decimal(text), limit, "value", low=low)
        except ValueError as error:
            raise argparse.ArgumentTypeError(str(error).removeprefix("value: ")) from None

    parse.__name__ = "number"
    return parse


seed = count_within(limits.SEED, low=0)
"""The argparse type of ``--seed``: an integer in ``[0, 2^32 - 1]`` (:data:`ccjax.limits.SEED`)."""


def overwrite_argument(parser: argparse.ArgumentParser, what: str = "output files") -> None:
    """``--overwrite``: existing outputs are refused without it (:mod:`ccjax.io.outputs`)."""
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help=f"replace existing {what} (they are refused otherwise; inputs are never replaced)",
    )


def check_outputs(
    inputs: Iterable[str | os.PathLike],
    outputs: Iterable[tuple[str, str | os.PathLike | None]],
    *,
    overwrite: bool,
) -> None:
    """:func:`ccjax.io.outputs.check_outputs`, before any work (imported on use: the command
    modules import only the standard library until the command runs).

    Arguments:
        inputs: the files the command reads.
        outputs: ``(option, path)`` of the files it writes (None: not asked for; ``"-"``: standard output).
        overwrite: ``--overwrite``.

    Returns:
        None.

    Raises:
        ValueError: an output names an input or another output, is a folder or a symbolic link,
            exists without ``overwrite``, or its folder cannot be written.
    """
    from ccjax.io.outputs import check_outputs as check

    check(inputs, outputs, overwrite=overwrite)


def write(path: str, text: str, *, overwrite: bool) -> None:
    """Write ``text`` to ``path`` atomically (``"-"``: standard output), checked first with
    :func:`check_outputs`.

    Arguments:
        path: the file, or ``"-"``.
        text: the contents.
        overwrite: ``--overwrite``: replace a file that appeared at ``path`` since the check.

    Returns:
        None.
    """
    from ccjax.io.files import write_file

    if path == "-":
        sys.stdout.write(text + ("\n" if not text.endswith("\n") else ""))
    else:
        write_file(path, text, overwrite=overwrite)
        print(f"wrote {path}", file=sys.stderr)


PLOT_SUFFIX = ".png"


def check_plot(path: str | os.PathLike | None, option: str = "--plot") -> None:
    """Refuse a plot path that is not a ``.png`` name (nothing for ``None``); the rest of its
    check is :func:`check_outputs`'.

    Arguments:
        path: the PNG to write, or None.
        option: the argument's name for the message.

    Returns:
        None.

    Raises:
        ValueError: not a ``.png`` name.
    """
    if path is not None and Path(path).suffix.lower() != PLOT_SUFFIX:
        raise ValueError(f"{option}: {path} must end in .png")


def write_plot(path: str | os.PathLike, draw, *, overwrite: bool, drawn_from: tuple | None = None) -> None:
    """Write a plot atomically: ``draw(buffer)`` renders the PNG into memory (matplotlib's
    ``savefig`` takes a file object), then :func:`ccjax.io.files.write_file` puts it in place
    through a temporary file, so an interrupted run never leaves a partial plot.

    With ``drawn_from``, the PNG is kept in the disk cache (``<cache>/plots``, verified by its
    digest when read) under a key of those parts, ccjax's code and matplotlib's version, and a
    later run drawing the same figure writes the stored bytes instead of importing matplotlib
    and drawing it again (about a second).

    Arguments:
        path: the ``.png`` file (checked first with :func:`check_plot` and :func:`check_outputs`).
        draw: a function of one binary file object that saves the figure there as PNG.
        overwrite: ``--overwrite``.
        drawn_from: everything the figure depends on (the plotted values, labels and title), or
            ``None`` to draw it every time.

    Returns:
        None.
    """
    import io

    from ccjax.io.files import write_file

    png = None
    if drawn_from is not None:
        from importlib.metadata import version

        import numpy as np

        from ccjax._cache import code_fingerprint, content_key
        from ccjax._entries import Expect, read_arrays, write_arrays

        key = content_key("plot", code_fingerprint(), version("matplotlib"), *drawn_from)
        facts = {"plot": str(drawn_from[0])}
        stored = read_arrays("plots", key, {"png": Expect((None,), "u", 0.0, 255.0)}, facts)
        png = None if stored is None else stored["png"].tobytes()
    if png is None:
        buffer = io.BytesIO()
        draw(buffer)
        png = buffer.getvalue()
        if drawn_from is not None:
            write_arrays("plots", key, {"png": np.frombuffer(png, np.uint8)}, facts)  # pyright: ignore[reportPossiblyUnboundVariable]
    write_file(path, png, overwrite=overwrite)
    print(f"wrote {path}", file=sys.stderr)


DATA_SUFFIXES = {"--json": ".json", "--csv": ".csv"}
"""The data options of :func:`data_output_argument` and the suffix a file they name must end in."""


def data_path(option: str) -> Callable[[str], str]:
    """The argparse type of ``--json`` / ``--csv``: ``-`` or a path ending in the option's suffix.

    Arguments:
        option: ``"--json"`` or ``"--csv"``.

    Returns:
        The type function (it raises ``argparse.ArgumentTypeError`` naming what is wrong).
    """
    suffix = DATA_SUFFIXES[option]

    def parse(text: str) -> str:
        if text == "-" or text.lower().endswith(suffix):
            return text
        raise argparse.ArgumentTypeError(
            f"expected '-' (standard output) or a file name ending in {suffix}, got {text!r}"
        )

    parse.__name__ = "path"
    return parse


def data_output_argument(parser: argparse.ArgumentParser, option: str, what: str) -> None:
    """``--json [PATH]`` or ``--csv [PATH]``, with one meaning on every command: no value or ``-``
    writes the data to standard output, data only (the tables for people go to standard error,
    :func:`table_stream`); a PATH (which must end in ``.json`` / ``.csv``) writes that file,
    checked with :func:`check_outputs` (``--overwrite``). A word after the option that is neither
    is never taken as PATH: it stays a positional argument (``reproduce --json 4.2`` is table 4.2
    as JSON), which :class:`CommandParser` arranges.

    Arguments:
        parser: the command's parser (a :class:`CommandParser`; a plain ``ArgumentParser`` gets the
            option without that look-ahead: there a word after it is its value, checked as PATH).
        option: ``"--json"`` or ``"--csv"``.
        what: what the data is, for the help (e.g. ``"the tidy table"``).

    Returns:
        None.

    Raises:
        KeyError: ``option`` is neither ``--json`` nor ``--csv``.
    """
    suffix = DATA_SUFFIXES[option]
    parser.add_argument(
        option,
        nargs="?",
        const="-",  # standard output
        default=None,
        type=data_path(option),
        metavar="PATH",
        help=f"write {what} as {suffix[1:].upper()}: to PATH (ending in {suffix}), or with no PATH or '-' to "
        "standard output (data only; the tables for people then go to standard error)",
    )
    if isinstance(parser, CommandParser):
        parser.data_options[option] = suffix


class CommandParser(argparse.ArgumentParser):
    """The ``ccjax`` parsers: an ``argparse.ArgumentParser`` whose ``--json`` / ``--csv`` options
    (:func:`data_output_argument`) take the next word as their PATH only when it is ``-`` or ends
    in their suffix; any other word stays where it is, a positional argument.

    Attributes:
        data_options: the data options of this parser and their suffixes.
        commands: the sub-commands' parsers by name (for their usage lines, :class:`OptionError`).
    """

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.data_options: dict[str, str] = {}
        # The sub-commands' parsers by name (filled by ccjax.cli.build_parser): their usage lines
        # go before an OptionError found after parsing.
        self.commands: dict[str, argparse.ArgumentParser] = {}

    def parse_known_args(self, args=None, namespace=None):  # pyright: ignore[reportIncompatibleMethodOverride]
        """``argparse.ArgumentParser.parse_known_args``, with each data option followed by a word
        that is not its PATH given ``-`` explicitly (``--json=-``), so the word stays positional,
        and a word holding a NUL byte refused (exit 2, the usage line).

        Arguments:
            args: the arguments (default: the process arguments).
            namespace: the namespace to fill.

        Returns:
            ``(namespace, the arguments not recognised)``.
        """
        words = list(sys.argv[1:] if args is None else args)
        if not self.commands:  # a sub-command's parser: its usage line and prefix name the command
            # Only in-process calls can pass a NUL byte (process arguments are C strings); a path
            # holding one would fail later as "embedded null byte", naming no argument.
            for word in (word for word in words if "\0" in word):
                self.error(f"{word!r} contains a NUL byte, which no file name or value may hold")
        kept: dict[str, str] = {}  # word -> the option it followed
        for index, word in enumerate(words[:-1]):
            if word == "--":
                break
            following = words[index + 1]
            suffix = self.data_options.get(word)
            if suffix is None or following.startswith("-"):
                continue  # '-' (standard output) and a next option are argparse's to read
            if not following.lower().endswith(suffix):
                words[index] = f"{word}=-"
                kept[following] = word
        namespace, extras = super().parse_known_args(words, namespace)
        for word in extras:
            if word in kept:
                option = kept[word]
                self.error(
                    f"{option}: {word!r} is neither '-' nor a file name ending in {self.data_options[option]} "
                    "(a word after the option is its PATH only then)"
                )
        return namespace, extras


def table_stream(args):
    """Where a command prints its tables for people: standard output, or standard error when
    ``--json -`` or ``--csv -`` puts the data there, so that standard output holds only the data
    (``json.load`` of it works).

    Arguments:
        args: the parsed arguments (``json``, ``csv``; either may be absent).

    Returns:
        ``sys.stdout`` or ``sys.stderr``.

    Raises:
        ValueError: both ``--json -`` and ``--csv -`` (one standard output cannot hold both).
    """
    to_stdout = [f"--{name}" for name in ("json", "csv") if getattr(args, name, None) == "-"]
    if len(to_stdout) > 1:
        raise ValueError("--json, --csv: give '-' (standard output) to one of them; write the other to a file")
    return sys.stderr if to_stdout else sys.stdout


def write_outputs(args, report) -> None:
    """Write ``report`` as JSON / CSV where ``--json`` / ``--csv`` name a file."""
    if args.json:
        write(args.json, report.to_json(), overwrite=args.overwrite)
    if args.csv:
        write(args.csv, report.to_csv(), overwrite=args.overwrite)


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
