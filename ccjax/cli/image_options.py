"""The options and checks shared by the image commands (``estimate``, ``correct``, ``evaluate``):
input preparation, pixel rules, masks, file levels, progress, the world and the camera check."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from ccjax._numbers import decimal, whole
from ccjax.cli.common import check_camera_name, check_camera_option

if TYPE_CHECKING:
    from ccjax.estimators.base import AbstractEstimator

OPTION_NAMES = {
    "folds": "--folds",
    "train": "--train",
    "epochs": "--epochs",
    "masks": "--mask",
    "ground_truth": "--ground-truth",
    "allow_missing": "--allow-missing",
    "methods": "--methods",
    "camera": "--camera",
    "camera_map": "--camera-map",
    "rendered": "--rendered",
    "seed": "--seed",
}
"""The command-line option of each library argument that errors name (see :func:`as_option_error`)."""


def image_arguments(parser: argparse.ArgumentParser) -> None:
    """The image options of ``estimate``, ``correct`` and ``evaluate``: preparation, pixel rules,
    masks, file levels, progress."""
    parser.add_argument(
        "--preprocessing",
        default=None,
        help="input preparation for every method: pixels (every usable pixel), ave<b>[-edges][-cluster|-hull] "
        "(block averages, Table 4.6), seg-<min>-<rg>-<rel>[-hull], generic (default: each method's own: pixels "
        "for grey world, shades of grey, max-RGB and grey edge, ave5 for the world-based methods)",
    )
    parser.add_argument(
        "--dark",
        type=decimal,
        default=None,
        help="surface-list preprocessing: drop pixels with R+G+B below this fraction of the 99th percentile "
        "of the usable pixels' (default: 0.02; pixels inputs have no dark rule)",
    )
    parser.add_argument(
        "--mask",
        default=None,
        metavar="DIR",
        help="folder of mask images, one per image named by its stem (DIR/<stem>.png, .tif or .tiff); "
        "nonzero = usable pixel, zero = excluded (e.g. the colour checker)",
    )
    file_arguments(parser)
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")


def file_arguments(parser: argparse.ArgumentParser) -> None:
    """How image files are read (black level, saturation, 8-bit and sRGB files, the pixel budget):
    the options of :func:`read_options`, shared by every command that reads photographs."""
    parser.add_argument(
        "--black-level",
        type=level_value,
        default=0.0,
        help="black level in file units (default: 0)",
    )
    parser.add_argument(
        "--saturation",
        type=level_value,
        default=None,
        help="saturation level in file units: pixels with a channel at or above it are clipped (default: 0.98 "
        "of the format maximum, e.g. 64224 for 16-bit)",
    )
    parser.add_argument(
        "--assume-linear",
        action="store_true",
        help="accept 8-bit files as linear data (they are refused otherwise)",
    )
    max_pixels_argument(parser)
    parser.add_argument(
        "--decode-srgb",
        action="store_true",
        help="undo the sRGB curve (colour-science) of the sRGB-encoded images before estimating: 8-bit files, "
        "JPEG, and PNG/TIFF files tagged as gamma-encoded (an sRGB or gAMA chunk, an sRGB ICC profile), which are "
        "refused without it; 16-bit and float files without such a tag, and raw files, are read as linear all the same",
    )


def level_value(text: str) -> float:
    """A file level (``--black-level``, ``--saturation``): a decimal number at or above 0, in
    file units (an argparse type).

    Arguments:
        text: the option's value.

    Returns:
        The level.

    Raises:
        argparse.ArgumentTypeError: not a decimal number, or negative.
    """
    try:
        value = decimal(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected a level at or above 0 in file units, got {text!r}")
    return value


def positive_int(text: str) -> int:
    """A positive integer (an argparse type)."""
    try:
        value = whole(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return value


def max_pixels_argument(parser: argparse.ArgumentParser) -> None:
    """``--max-pixels``: the pixel budget checked from each image's header (:data:`ccjax.io.reading.MAX_PIXELS`)."""
    parser.add_argument(
        "--max-pixels",
        type=positive_int,
        default=100_000_000,
        help="refuse (as a failed file) an image whose header claims more pixels than this, before anything "
        "is allocated for it (default: %(default)s, 100 MP)",
    )


def read_options(args) -> dict:
    """The keyword arguments of :func:`ccjax.io.read_image` given on the command line.

    Arguments:
        args: the parsed arguments (:func:`file_arguments`).

    Returns:
        The keyword arguments.

    Raises:
        ValueError: ``--assume-linear`` with ``--decode-srgb`` (8-bit files are read one way or
            the other, not both).
    """
    if args.assume_linear and args.decode_srgb:
        raise ValueError(
            "--assume-linear, --decode-srgb: give one (8-bit files read as linear data, or decoded from sRGB)"
        )
    return {
        "black_level": args.black_level,
        "saturation": args.saturation,
        "assume_linear": args.assume_linear,
        "max_pixels": args.max_pixels,
        "decode_srgb": args.decode_srgb,
    }


def dark_fraction(args) -> float:
    """``--dark``, or the library default."""
    from ccjax.preprocessing import DEFAULT_DARK

    return DEFAULT_DARK if args.dark is None else args.dark


def image_world(args):
    """The world of the image commands (:func:`ccjax.runs.store.world`, cached on disk)."""
    from ccjax import _cache
    from ccjax.runs import store

    check_camera_option(args)
    _cache.enable_compilation_cache()
    return store.world(args.world, args.camera, seed=args.seed, data_dir=args.data_dir)


def check_labels(labels, args=None) -> None:
    """Refuse unknown method labels, a bad ``--preprocessing`` or ``--dark`` and an unknown
    ``--camera`` before any work.

    Arguments:
        labels: estimator labels.
        args: the parsed arguments (``--preprocessing``, ``--dark``, ``--camera``); None checks
            the labels only.

    Returns:
        None.

    Raises:
        ValueError: naming the first unknown label and the known grammars, or the bad option.
    """
    from ccjax.estimators import registry
    from ccjax.preprocessing import as_preprocessing

    for label in labels:
        registry.lookup(label)
    if args is None:
        return
    if args.preprocessing is not None:
        as_preprocessing(args.preprocessing)
    if args.dark is not None and not 0 <= args.dark < 1:
        raise ValueError(f"--dark: expected a fraction in [0, 1), got {args.dark!r}")
    check_camera_name(args)


def require_camera(labels, args, *, other_world: bool = True) -> None:
    """Refuse world-based methods (``model.world_based``: fitted to a world seen through a camera's
    curves) when the camera is not given, before any image is read. Without ``--camera`` the
    labels are fitted (through the store) to the default world, which the command then uses.

    Arguments:
        labels: estimator labels (known to the registry).
        args: the parsed arguments (``--world``, ``--camera``).
        other_world: the command takes ``--world barnard1999`` for these methods (the message
            offers it).

    Returns:
        None.

    Raises:
        ValueError: naming the world-based methods, ``--camera`` and ``ccjax cameras``.
    """
    if args.world != "default" or args.camera is not None or not labels:
        return
    from ccjax.runs import store

    world = image_world(args)
    fitted = [label for label in labels if store.fit(label, world).world_based]
    if fitted:
        raise ValueError(
            f"--camera: {', '.join(fitted)} {'is' if len(fitted) == 1 else 'are'} fitted to a world seen through "
            "a camera's curves; give the camera that took the images with --camera NAME (`ccjax cameras` lists "
            "the names, `ccjax cameras --check GT.csv --camera NAME` tests a guess against the ground truth)"
            + (" or use --world barnard1999" if other_world else "")
        )


def model_arguments(parser: argparse.ArgumentParser, verb: str) -> None:
    """``--method`` and ``--model`` of ``estimate`` and ``correct`` (exactly one is given).

    Arguments:
        parser: the command's parser.
        verb: what the command does with the light, for the help (``"estimate"``, ``"correct"``).
    """
    parser.add_argument("--method", default=None, help="estimator label (see `ccjax methods`); or --model")
    parser.add_argument(
        "--model",
        default=None,
        help=f"a trained model file (`ccjax train --out`, ccjax.runs.store.save_trained) to {verb} with, instead of "
        "--method: the method and the camera it was trained for come from its record (a --camera given must be "
        "that camera)",
    )


def trained_model(args) -> tuple[str, AbstractEstimator, str | None]:
    """``(name, model, camera)`` of ``--model``: the model file's name, the model
    (:func:`ccjax.load_model`) and the camera its record names, or ``--camera`` when the record
    names none (a model that used no camera's curves), or None.

    Arguments:
        args: the parsed arguments (``--model``, ``--world``, ``--camera``).

    Returns:
        The name, the model and the camera.

    Raises:
        ValueError: no such file, ``--world`` given, an unknown ``--camera`` or one that is not the
            camera of the model's record (naming both), or a model that cannot be read.
    """
    from pathlib import Path

    from ccjax.runs import store

    if not Path(args.model).is_file():
        raise ValueError(f"--model: no such model file: {args.model}")
    if args.world != "default":
        raise ValueError("--model: the model's world comes from its record; leave out --world")
    check_camera_name(args)
    record = store.trained_record(args.model)
    camera = record.get("camera")
    if record.get("conditioned") is True:
        if args.camera is None:
            raise ValueError(
                f"--camera: the model {args.model} serves any camera given its name (any-camera); name the camera "
                "of the images (`ccjax cameras` lists them)"
            )
        return Path(args.model).name, store.load_model(args.model, camera=args.camera), args.camera
    if args.camera is not None and camera is not None and args.camera != camera:
        raise ValueError(
            f"--camera: {args.camera!r} is not the camera of the model {args.model} ({camera!r}, from its record); "
            "a model trained for one camera gives wrong lights for another: leave out --camera or train for it"
        )
    return Path(args.model).name, store.load_model(args.model), camera if camera is not None else args.camera


def image_source(paths_or_folders, args):
    """The images of a command (:func:`ccjax.runs.sources.image_folder`): listed, ``--mask`` files
    found, every header probed once.

    Arguments:
        paths_or_folders: files and folders.
        args: the parsed arguments (``--mask`` and the read options).

    Returns:
        The :class:`~ccjax.runs.sources.ImageFolder`.

    Raises:
        ValueError: no files, a mask missing, or not one file can be used (one line per file).
    """
    from ccjax.runs.sources import image_folder, raise_failures

    source = image_folder(paths_or_folders, masks=args.mask, read_options=read_options(args), mask_argument="--mask")
    if not source.usable():
        raise_failures(list(source.failures.values()), len(source))
    return source


def as_option_error(error: ValueError) -> ValueError:
    """A library error that names an argument (``"folds: ..."``) as the option that gave it
    (``"--folds: ..."``, :data:`OPTION_NAMES`); other errors unchanged.

    Arguments:
        error: the library's error.

    Returns:
        The error for the command line.
    """
    message = str(error)
    name = message.split(":", 1)[0]
    if name in OPTION_NAMES:
        return ValueError(OPTION_NAMES[name] + message[len(name) :])
    return error
