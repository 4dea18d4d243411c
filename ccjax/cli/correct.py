"""``ccjax correct``: linear images corrected to the canonical light (Barnard 1999 §4.4)."""

from __future__ import annotations

from ccjax._numbers import decimal, whole
from ccjax.cli import image_options
from ccjax.cli.common import check_outputs, overwrite_argument, world_arguments
from ccjax.cli.number_lists import number_list

OUTPUT_SUFFIXES = (".png", ".tif", ".tiff")
JPEG_SUFFIXES = (".jpg", ".jpeg")


def add_correct(sub) -> None:
    p = sub.add_parser(
        "correct",
        help="correct linear images to the canonical light",
        description="Estimate each image's light (--method, or a trained --model), map it to the canonical light "
        "with a diagonal map and write the corrected image and an 8-bit sRGB preview (--preview none: no "
        "preview); pixels with a clipped channel (the clip level estimation uses: 0.98 of full scale, or "
        "--saturation) come out white. By default the corrected image is linear 16-bit camera RGB under the canonical "
        "light (the camera's view of daylight white, which is not grey: in an image viewer it looks green and "
        "dark), for further processing; --srgb 8 or 16 writes it for viewing (--srgb 8: .png or .jpg; a folder "
        "becomes JPEGs under the inputs' stems). IN and "
        "OUT are files, or folders (OUT and the folder of a single OUT are created). Inputs are never replaced; "
        "existing outputs need --overwrite; every file is written to a temporary name and renamed into place.",
    )
    p.add_argument("input", help="a linear image or a folder of them")
    p.add_argument(
        "output", help="output .png/.tif/.tiff file (.jpg/.jpeg with --srgb 8), or a folder when INPUT is a folder"
    )
    image_options.model_arguments(p, "correct")
    p.add_argument(
        "--light",
        type=light_values,
        default=None,
        metavar="R,G,B",
        help="correct with this known light instead of an estimate: camera RGB of white under it (a grey card "
        "read elsewhere; any scale), for every image",
    )
    p.add_argument(
        "--white-region",
        type=region_values,
        default=None,
        metavar="X,Y,W,H",
        help="correct with the light of a white or grey surface in each image (a grey card): the mean of the usable "
        "pixels of this rectangle, X,Y its top-left pixel (column, row) and W,H its size, in the image as read "
        "(upright; a raw file's half-size development, as estimation reads it)",
    )
    p.add_argument(
        "--preview",
        default=None,
        help="the 8-bit sRGB preview's path for a single image, or 'none' for no previews (default: beside "
        "each output, named after its full name: a.png gives a_preview.png, a.jpg a_jpg_preview.png)",
    )
    p.add_argument(
        "--preview-size",
        type=whole,
        default=None,
        metavar="PIXELS",
        help="a preview's longest side at most, reduced by block means in linear light (default 1024; 0: full size)",
    )
    p.add_argument(
        "--sharpening",
        default=None,
        help="3x3 sharpening transform T (text or .npy; rows = sharpened sensors) for a sharpened-diagonal map T^-1 "
        "diag(T w_C / T e) T",
    )
    p.add_argument(
        "--srgb",
        type=whole,
        choices=(8, 16),
        default=None,
        help="write OUTPUT as sRGB with 8 or 16 bits instead of linear camera RGB: full resolution, the "
        "camera-to-sRGB matrix of the world and the sRGB curve (colour-science), no exposure change",
    )
    overwrite_argument(p, "output images and previews")
    world_arguments(p)
    image_options.image_arguments(p)
    p.set_defaults(func=run_correct)


def correct_outputs(args):
    """Validate ``ccjax correct``'s inputs and outputs before any work.

    Arguments:
        args: the parsed arguments (``input``, ``output``, ``preview``, ``overwrite``).

    Returns:
        ``(paths, outputs, previews)``: the input files and, for each, its output and preview
        (previews None with ``--preview none``).

    Raises:
        ValueError: an output would replace an input or another output, exists without
            ``--overwrite``, is a folder, or cannot be written.
    """
    from pathlib import Path

    from ccjax import io
    from ccjax.io.outputs import check_output_folder, path_key
    from ccjax.runs.folders import folder_outputs, preview_path

    source, target = Path(args.input), Path(args.output)
    no_preview = args.preview is not None and args.preview.lower() == "none"
    if source.is_dir():
        if path_key(source) == path_key(target):
            raise ValueError(f"output: {args.output} is the input folder {args.input}; its images would be replaced")
        if target.exists() and not target.is_dir():
            raise ValueError(f"output: {target} exists and is not a folder")
        if args.preview and not no_preview:
            raise ValueError(
                "--preview: names one image's preview; with a folder the previews go beside the outputs (or give "
                "--preview none)"
            )
        paths = io.list_images([source])
        outputs, previews = folder_outputs(paths, target, suffix=".jpg" if args.srgb == 8 else None)
        check_output_folder(target, "output")
    else:
        if not source.exists():
            raise FileNotFoundError(f"input: {source} does not exist")
        paths, outputs = [source], [target]
        previews = [Path(args.preview) if args.preview else preview_path(target)]
        if target.is_dir():
            raise ValueError(f"output: {target} is a folder; give a .png, .tif or .tiff file name")
        if target.suffix.lower() in JPEG_SUFFIXES and args.srgb != 8:
            raise ValueError(
                f"output: {target} is a JPEG, 8-bit sRGB for viewing; give --srgb 8, or a .png/.tif/.tiff for the "
                "linear 16-bit (or --srgb 16) image"
            )
        if target.suffix.lower() not in OUTPUT_SUFFIXES + JPEG_SUFFIXES:
            raise ValueError(f"output: {target} must end in .png, .tif or .tiff (or .jpg/.jpeg with --srgb 8)")
        check_output_folder(target.parent, "output", written=target)  # created when missing, as OUT folders are
        if not no_preview and previews[0].suffix.lower() != ".png":
            raise ValueError(f"--preview: {previews[0]} must end in .png (or give --preview none)")
    if args.preview_size is not None and args.preview_size < 0:
        raise ValueError(f"--preview-size: expected a number of pixels >= 0 (0: full size), got {args.preview_size}")
    shown = [] if no_preview else previews
    written = [("output", output) for output in outputs] + [("--preview", preview) for preview in shown]
    check_outputs(paths + sharpening_inputs(args), written, overwrite=args.overwrite)
    return paths, outputs, None if no_preview else previews


def sharpening_inputs(args) -> list:
    """The ``--sharpening`` file as an input (outputs must not replace it), or nothing."""
    return [args.sharpening] if args.sharpening else []


SHARPENING_BYTES = 1 << 16
"""Largest ``--sharpening`` file read (a 3x3 matrix is a few hundred bytes as text or .npy)."""


def _light_fault(rgb: tuple[float, ...]) -> str | None:
    """What a ``--light`` with a negative or no positive number should be (None: in range)."""
    return "non-negative numbers, not all zero" if min(rgb) < 0 or max(rgb) <= 0 else None


def _region_fault(xywh: tuple[int, ...]) -> str | None:
    """What a ``--white-region`` with a negative corner or an empty size should be (None: in range)."""
    if min(xywh) < 0:
        return "four whole numbers X,Y,W,H"
    return "a width and height of at least 1 pixel" if min(xywh[2:]) < 1 else None


light_values = number_list(decimal, "three numbers R,G,B", 3, check=_light_fault)
"""The argparse type of ``--light R,G,B``: three non-negative decimal numbers, not all zero."""

region_values = number_list(whole, "four whole numbers X,Y,W,H", 4, check=_region_fault)
"""The argparse type of ``--white-region X,Y,W,H``: four integers, X,Y >= 0 and W,H >= 1."""


def read_sharpening(path):
    """The ``--sharpening`` matrix (text or ``.npy``), or None. The file is read whole only when
    it is a regular file of at most :data:`SHARPENING_BYTES` (``/dev/zero`` is refused, not read
    until memory runs out); ``.npy`` is read without pickles.

    Arguments:
        path: the file, or None.

    Returns:
        ``(3, 3)`` float64, or None.

    Raises:
        ValueError: not a small regular file, not a text or ``.npy`` matrix, a ``.npy`` array
            of numbers that are not real (complex, say; its dtype is named), or not an invertible,
            finite 3x3 matrix.
    """
    import io
    import os

    import numpy as np

    if not path:
        return None
    if not os.path.isfile(path):
        raise ValueError(f"--sharpening: {path} is not a regular file")
    if os.path.getsize(path) > SHARPENING_BYTES:
        raise ValueError(f"--sharpening: {path} is over {SHARPENING_BYTES} bytes; a 3x3 matrix is far smaller")
    with open(path, "rb") as handle:
        blob = handle.read(SHARPENING_BYTES + 1)
    try:
        if path.endswith(".npy"):
            sharpening = np.load(io.BytesIO(blob), allow_pickle=False)
            if not isinstance(sharpening, np.ndarray):
                raise ValueError("not a single .npy array (an .npz archive?)")
        else:
            sharpening = np.loadtxt(io.StringIO(blob.decode("utf-8")), ndmin=2)
    except (ValueError, TypeError, OSError, EOFError) as error:
        raise ValueError(f"--sharpening: cannot read {path}: {error}") from None
    if sharpening.dtype.kind not in "iuf":
        # A complex matrix would lose its imaginary part in the cast to float (NumPy only warns).
        raise ValueError(f"--sharpening: {path} holds {sharpening.dtype} values; expected real numbers")
    try:
        sharpening = np.asarray(sharpening, np.float64)
    except (ValueError, TypeError) as error:
        raise ValueError(f"--sharpening: cannot read {path}: {error}") from None
    if sharpening.shape != (3, 3) or not np.all(np.isfinite(sharpening)) or abs(np.linalg.det(sharpening)) < 1e-9:
        raise ValueError(f"--sharpening: {path} must hold an invertible 3x3 matrix")
    return sharpening


def notice_colours(world, paths, args, model_camera: str | None) -> None:
    """One line on stderr when the sRGB colours (an sRGB output, the previews) of files without a
    colour matrix of their own come from a camera nobody named: the default camera's curves.

    Arguments:
        world: the world the correction uses.
        paths: the input files (raw files carry their own matrix).
        args: the parsed arguments (``--camera``, ``--world``, ``--srgb``, ``--preview``).
        model_camera: the camera a ``--model`` file's record names (None: none, or ``--method``).
    """
    import sys
    from pathlib import Path

    from ccjax.io import RAW_SUFFIXES

    shown = args.srgb is not None or not (args.preview is not None and args.preview.lower() == "none")
    plain = [path for path in paths if Path(path).suffix.lower() not in RAW_SUFFIXES]
    if shown and plain and args.camera is None and model_camera is None and args.world == "default":
        print(
            f"ccjax correct: notice: the sRGB colours (--srgb output, previews) use the curves of "
            f"{world.camera.name}, the default camera; give --camera NAME for the camera that took the images "
            "(raw files use their own colour matrix)",
            file=sys.stderr,
        )


def run_correct(args) -> int:
    import numpy as np

    from ccjax import runs
    from ccjax._colour import unit_light
    from ccjax.cli.estimate import STATUS_WORDS
    from ccjax.estimators import known, registry
    from ccjax.estimators.base import Status
    from ccjax.runs.folders import PREVIEW_SIZE
    from ccjax.runs.sources import raise_failures

    given = [args.method, args.model, args.light, args.white_region]
    if sum(value is not None for value in given) != 1:
        raise ValueError(
            "--method, --model, --light, --white-region: give exactly one (a method label, a trained model file, "
            "a known light, or a grey card's rectangle)"
        )
    image_options.check_labels([] if args.method is None else [args.method], args)
    paths, outputs, previews = correct_outputs(args)
    camera = None
    if args.light is not None or args.white_region is not None:
        world = image_options.image_world(args)
        if args.light is not None:
            method = known.known_light(args.light)
        else:
            method = known.white_region(args.white_region, world.canonical_white)
    elif args.model is None:
        registry.refuse_untrained(args.method, "--method")
        image_options.require_camera([args.method], args)
        method, world = str(args.method), image_options.image_world(args)
    else:
        from ccjax.runs import store

        # The model's camera gives the canonical light and the preview's colours.
        _, method, camera = image_options.trained_model(args)
        world = store.world("default", camera, seed=args.seed)
    sharpening = read_sharpening(args.sharpening)
    source = image_options.image_source(paths, args)
    if isinstance(method, known.WhiteRegion):
        for path, size in zip(source.paths, source.sizes, strict=True):
            if size is not None:  # a bad header is the file's own failure
                known.check_region(method, size[0], size[1], str(path))
    notice_colours(world, paths, args, model_camera=None if args.model is None else camera)
    kind = "linear 16-bit camera RGB under the canonical light" if args.srgb is None else f"{args.srgb}-bit sRGB"

    def report(index, estimate, output, preview) -> None:
        from tqdm.auto import tqdm

        # The light as `ccjax estimate` prints it (five decimals, largest channel 1), written
        # above the progress bar rather than into it.
        rgb = ", ".join(f"{v:.5f}" for v in unit_light([float(v) for v in np.asarray(estimate.illuminant)]))
        status = STATUS_WORDS[Status(int(estimate.status)).name.lower()]
        if status == "estimated" and args.light is not None:
            status = "given"
        elif status == "estimated" and args.white_region is not None:
            status = "from the white region"
        line = f"({status}) -> {output} ({kind})" + ("" if preview is None else f", {preview} (sRGB preview)")
        tqdm.write(f"{source.paths[index]}: light [{rgb}] {line}")

    run = runs.correct_folder(
        source,
        method,
        outputs,
        previews=False if previews is None else previews,
        preview_size=PREVIEW_SIZE if args.preview_size is None else args.preview_size or None,
        world=world,
        sharpening=sharpening,
        preprocessing=args.preprocessing,
        dark=image_options.dark_fraction(args),
        progress=not args.no_progress,
        each=report,
        overwrite=args.overwrite,
        srgb=args.srgb,
    )
    raise_failures(list(run.failures.values()), len(paths))
    return 0


COMMANDS = [add_correct]
