"""``ccjax correct``: linear images corrected to the canonical light (Barnard 1999 §4.4)."""

from __future__ import annotations

from ccjax.cli import image_options
from ccjax.cli.common import check_outputs, overwrite_argument, world_arguments

OUTPUT_SUFFIXES = (".png", ".tif", ".tiff")
JPEG_SUFFIXES = (".jpg", ".jpeg")


def add_correct(sub) -> None:
    p = sub.add_parser(
        "correct",
        help="correct linear images to the canonical light",
        description="Estimate each image's light (--method, or a trained --model), map it to the canonical light "
        "with a diagonal map and write the corrected image and an 8-bit sRGB preview; pixels with a clipped "
        "channel come out white. By default the corrected image is linear 16-bit camera RGB under the canonical "
        "light (the camera's view of daylight white, which is not grey: in an image viewer it looks green and "
        "dark), for further processing; --srgb 8 or 16 writes it for viewing (--srgb 8: .png or .jpg). IN and "
        "OUT are files, or folders (OUT and the folder of a single OUT are created). Inputs are never replaced; "
        "existing outputs need --overwrite; every file is written to a temporary name and renamed into place.",
    )
    p.add_argument("input", help="a linear image or a folder of them")
    p.add_argument(
        "output", help="output .png/.tif/.tiff file (.jpg/.jpeg with --srgb 8), or a folder when INPUT is a folder"
    )
    image_options.model_arguments(p, "correct")
    p.add_argument(
        "--preview",
        default=None,
        help="preview path for a single image (default: OUTPUT stem + '_preview.png')",
    )
    p.add_argument(
        "--sharpening",
        default=None,
        help="3x3 sharpening transform T (text or .npy; rows = sharpened sensors) for a sharpened-diagonal map T^-1 "
        "diag(T w_C / T e) T",
    )
    p.add_argument(
        "--srgb",
        type=int,
        choices=(8, 16),
        default=None,
        help="write OUTPUT as sRGB with 8 or 16 bits instead of linear camera RGB: full resolution, the "
        "camera-to-sRGB matrix of the world and the sRGB curve (colour-science), no exposure change",
    )
    overwrite_argument(p, "output images and previews")
    world_arguments(p)
    image_options.image_arguments(p)
    p.set_defaults(func=run_correct)


def folder_outputs(paths, target):
    """Output and preview paths in folder ``target`` for each input, no two alike
    (:func:`ccjax.runs.folders.folder_outputs`).

    Arguments:
        paths: the input files.
        target: the output folder.

    Returns:
        ``(outputs, previews)``, lists of paths.
    """
    from ccjax.runs.folders import folder_outputs as outputs

    return outputs(paths, target)


def correct_outputs(args):
    """Validate ``ccjax correct``'s inputs and outputs before any work.

    Arguments:
        args: the parsed arguments (``input``, ``output``, ``preview``, ``overwrite``).

    Returns:
        ``(paths, outputs, previews)``: the input files and, for each, its output and preview.

    Raises:
        ValueError: an output would replace an input or another output, exists without
            ``--overwrite``, is a folder, or cannot be written.
    """
    from pathlib import Path

    from ccjax import io
    from ccjax.io.outputs import check_output_folder, path_key

    source, target = Path(args.input), Path(args.output)
    if source.is_dir():
        if path_key(source) == path_key(target):
            raise ValueError(f"output: {args.output} is the input folder {args.input}; its images would be replaced")
        if target.exists() and not target.is_dir():
            raise ValueError(f"output: {target} exists and is not a folder")
        if args.preview:
            raise ValueError("--preview: names one image's preview; with a folder the previews go beside the outputs")
        paths = io.list_images([source])
        outputs, previews = folder_outputs(paths, target)
        check_output_folder(target, "output")
    else:
        if not source.exists():
            raise FileNotFoundError(f"input: {source} does not exist")
        paths, outputs = [source], [target]
        previews = [Path(args.preview) if args.preview else target.with_name(f"{target.stem}_preview.png")]
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
        if previews[0].suffix.lower() != ".png":
            raise ValueError(f"--preview: {previews[0]} must end in .png")
    written = [("output", output) for output in outputs] + [("--preview", preview) for preview in previews]
    check_outputs(paths + sharpening_inputs(args), written, overwrite=args.overwrite)
    return paths, outputs, previews


def sharpening_inputs(args) -> list:
    """The ``--sharpening`` file as an input (outputs must not replace it), or nothing."""
    return [args.sharpening] if args.sharpening else []


SHARPENING_BYTES = 1 << 16
"""Largest ``--sharpening`` file read (a 3x3 matrix is a few hundred bytes as text or .npy)."""


def read_sharpening(path):
    """The ``--sharpening`` matrix (text or ``.npy``), or None. The file is read whole only when
    it is a regular file of at most :data:`SHARPENING_BYTES` (``/dev/zero`` is refused, not read
    until memory runs out); ``.npy`` is read without pickles.

    Arguments:
        path: the file, or None.

    Returns:
        ``(3, 3)`` float64, or None.

    Raises:
        ValueError: not a small regular file, not a text or ``.npy`` matrix, or not an
            invertible, finite 3x3 matrix.
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
        sharpening = np.asarray(sharpening, np.float64)
    except (ValueError, TypeError, OSError, EOFError) as error:
        raise ValueError(f"--sharpening: cannot read {path}: {error}") from None
    if sharpening.shape != (3, 3) or not np.all(np.isfinite(sharpening)) or abs(np.linalg.det(sharpening)) < 1e-9:
        raise ValueError(f"--sharpening: {path} must hold an invertible 3x3 matrix")
    return sharpening


def run_correct(args) -> int:
    import numpy as np

    from ccjax import runs
    from ccjax.cli.estimate import STATUS_WORDS, unit_light
    from ccjax.estimators import registry
    from ccjax.estimators.base import Status
    from ccjax.runs.sources import raise_failures

    if (args.method is None) == (args.model is None):
        raise ValueError("--method, --model: give exactly one (a method label, or a trained model file)")
    image_options.check_labels([] if args.method is None else [args.method], args)
    paths, outputs, previews = correct_outputs(args)
    if args.model is None:
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
    kind = "linear 16-bit camera RGB under the canonical light" if args.srgb is None else f"{args.srgb}-bit sRGB"

    def report(index, estimate, output, preview) -> None:
        from tqdm.auto import tqdm

        # The light as `ccjax estimate` prints it (five decimals, largest channel 1), written
        # above the progress bar rather than into it.
        rgb = ", ".join(f"{v:.5f}" for v in unit_light([float(v) for v in np.asarray(estimate.illuminant)]))
        status = STATUS_WORDS[Status(int(estimate.status)).name.lower()]
        line = f"({status}) -> {output} ({kind}), {preview} (sRGB preview)"
        tqdm.write(f"{source.paths[index]}: light [{rgb}] {line}")

    run = runs.correct_folder(
        source,
        method,
        outputs,
        previews=previews,
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
