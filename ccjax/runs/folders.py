"""Python calls over a folder of photographs: estimate each image's light, or correct each image to
the canonical light, through the one image loop (:func:`ccjax.runs.images.run_models`).

Each call takes a folder, a file, a list of them, or an :class:`~ccjax.runs.sources.ImageFolder`
already probed, and a registry label (fitted through :mod:`ccjax.runs.store`) or a fitted model.
Files that cannot be used do not stop the run: each has its failure record in the result.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from ccjax import io
from ccjax.estimators.base import AbstractEstimator, Estimate
from ccjax.io.jpeg import upright_exif
from ccjax.io.outputs import path_key
from ccjax.io.preview import srgb_preview_rows
from ccjax.io.reading import MAX_PIXELS, LinearImage
from ccjax.io.writing import row_slices
from ccjax.preprocessing import DEFAULT_DARK, Preprocessing
from ccjax.runs.images import ImageRun, run_models
from ccjax.runs.sources import ImageFolder, Images, image_folder
from ccjax.world import World

OUTPUT_SUFFIXES = (".png", ".tif", ".tiff")
"""Suffixes of corrected images (16-bit PNG or TIFF); other inputs (raw files) are written as ``.tiff``."""


def _source(images: Images | ImageFolder, masks, read_options: dict | None, max_pixels: int | None) -> ImageFolder:
    if isinstance(images, ImageFolder):
        if masks is not None or read_options is not None or max_pixels != MAX_PIXELS:
            raise ValueError("masks, read_options, max_pixels: an ImageFolder has its own; give them to image_folder")
        return images
    return image_folder(images, masks=masks, read_options=read_options, max_pixels=max_pixels)


def fitted(method: str | AbstractEstimator, world: World | None = None) -> tuple[str, AbstractEstimator]:
    """``(label, model)``: a registry label fitted to ``world`` through the store, or a fitted model
    (labelled by its class name).

    Arguments:
        method: a registry label or a fitted estimator.
        world: the world labels are fitted to (default: :func:`ccjax.runs.store.world`).

    Returns:
        The label and the model.

    Raises:
        ValueError: ``method`` is neither; an unknown label, or one whose fit is only training's
            starting point (:func:`ccjax.estimators.registry.refuse_untrained`).
    """
    if isinstance(method, str):
        from ccjax.estimators import registry
        from ccjax.runs import store

        registry.refuse_untrained(method)
        return method, store.fit(method, world if world is not None else store.world())
    if isinstance(method, AbstractEstimator):
        return type(method).__name__, method
    raise ValueError(f"method: expected a registry label or a fitted estimator, got {type(method).__name__}")


def estimate_folder(
    images: Images | ImageFolder,
    method: str | AbstractEstimator,
    *,
    world: World | None = None,
    preprocessing: str | Preprocessing | None = None,
    dark: float = DEFAULT_DARK,
    read_options: dict | None = None,
    masks: str | os.PathLike | Sequence[str | os.PathLike | None] | None = None,
    progress: bool = False,
    max_pixels: int | None = MAX_PIXELS,
) -> ImageRun:
    """Estimate the light of every image of a folder.

    Arguments:
        images: a folder, a file, a list of them, or an :class:`~ccjax.runs.sources.ImageFolder`.
        method: a registry label (fitted to ``world`` through the store) or a fitted estimator.
        world: the world a label is fitted to (default: :func:`ccjax.runs.store.world`, the
            default world of the Canon EOS 5D Mark II); world-based methods need the camera
            that took the images.
        preprocessing: the input preparation (None: the model's default,
            :func:`ccjax.preprocessing.prepare`).
        dark: the surface lists' dark rule.
        read_options: keyword arguments of :func:`ccjax.io.read_image` (black level, saturation, ...).
        masks: a folder of masks named by the images' stems, or one mask file (or None) per image.
        progress: show a progress bar on stderr.
        max_pixels: the pixel budget: a file whose header claims more pixels is refused (a
            failure record) before anything is allocated for it (default 100 MP; None: no limit).

    Returns:
        The :class:`~ccjax.runs.images.ImageRun`: per image its estimate, ok and status
        (``done`` False and a failure record for the files that could not be used).
    """
    source = _source(images, masks, read_options, max_pixels)
    label, model = fitted(method, world)
    return run_models(source, {label: [model]}, preprocessing=preprocessing, dark=dark, progress=progress)


def folder_outputs(paths: Sequence[str | os.PathLike], target: str | os.PathLike) -> tuple[list[Path], list[Path]]:
    """Output and preview paths in folder ``target`` for each input, no two alike (case-insensitively).

    ``a.png`` gives ``a.png`` and ``a_preview.png``; a later input whose names are taken (``a.tif``,
    ``A.PNG`` beside it) gets its original suffix in the stem: ``a_tif.tif``, ``a_tif_preview.png``,
    then a number (``A_PNG-2.png``).

    Arguments:
        paths: the input files.
        target: the output folder.

    Returns:
        ``(outputs, previews)``, lists of paths.
    """
    target = Path(target)
    used: set[str] = set()
    outputs, previews = [], []
    for path in map(Path, paths):
        suffix = path.suffix.lower() if path.suffix.lower() in OUTPUT_SUFFIXES else ".tiff"
        tags = ["", f"_{path.suffix.lstrip('.')}"]
        tags += [f"_{path.suffix.lstrip('.')}-{number}" for number in range(2, len(paths) + 3)]
        for tag in tags:
            output, preview = target / f"{path.stem}{tag}{suffix}", target / f"{path.stem}{tag}_preview.png"
            if path_key(output) not in used and path_key(preview) not in used:
                break
        used.update((path_key(output), path_key(preview)))
        outputs.append(output)
        previews.append(preview)
    return outputs, previews


def correct_folder(
    images: Images | ImageFolder,
    method: str | AbstractEstimator,
    outputs: str | os.PathLike | Sequence[str | os.PathLike],
    *,
    previews: Sequence[str | os.PathLike] | None = None,
    world: World | None = None,
    sharpening: np.ndarray | None = None,
    preprocessing: str | Preprocessing | None = None,
    dark: float = DEFAULT_DARK,
    read_options: dict | None = None,
    masks: str | os.PathLike | Sequence[str | os.PathLike | None] | None = None,
    progress: bool = False,
    each: Callable[[int, Estimate, Path, Path], None] | None = None,
    max_pixels: int | None = MAX_PIXELS,
    overwrite: bool = True,
    srgb: int | None = None,
) -> ImageRun:
    """Estimate each image's light and write it corrected to the canonical light (a diagonal map,
    or a sharpened-diagonal one) as a linear 16-bit image (or, with ``srgb``, an sRGB one) and an
    8-bit sRGB preview. Clipped pixels come out white (:func:`ccjax.correction.correct`).

    Every file is written atomically (a temporary name put in place,
    :func:`ccjax.io.outputs.put_in_place`); existing files are replaced unless ``overwrite`` is
    False (then a file found at an output's name is kept and that image fails with
    ``FileExistsError``), so a caller that must not replace them checks first
    (:func:`ccjax.io.outputs.check_outputs`) and passes False.

    Arguments:
        images: a folder, a file, a list of them, or an :class:`~ccjax.runs.sources.ImageFolder`.
        method: a registry label (fitted to ``world`` through the store) or a fitted estimator.
        outputs: an output folder (names from :func:`folder_outputs`), or one output file
            (``.png``, ``.tif``, ``.tiff``) per image.
        previews: one preview file (``.png``) per image (default: the output's stem + ``_preview.png``).
        world: the world (default :func:`ccjax.runs.store.world`): labels are fitted to it, its
            canonical light is the target and its camera gives the preview colours.
        sharpening: optional invertible ``(3, 3)`` sharpening transform (:func:`ccjax.correction.correct`).
        preprocessing, dark, read_options, masks, progress, max_pixels: as :func:`estimate_folder`.
        each: called after each image is written with ``(index in the source, estimate, output,
            preview)``.
        overwrite: replace files already at the outputs' names.
        srgb: 8 or 16: write the output as sRGB with that many bits instead of linear camera RGB,
            at full resolution and without the preview's exposure change (the world's
            camera-to-sRGB matrix, :func:`ccjax.io.preview_matrix`, then the sRGB transfer
            curve: the canonical white at full scale is sRGB white).

    Returns:
        The :class:`~ccjax.runs.images.ImageRun`.

    Raises:
        ValueError: outputs or previews that do not give one file per image.
    """
    from ccjax import correction
    from ccjax.runs import store

    source = _source(images, masks, read_options, max_pixels)
    world = world if world is not None else store.world()
    label, model = fitted(method, world)
    if isinstance(outputs, (str, os.PathLike)):
        written, shown = folder_outputs(source.paths, outputs)
    else:
        written = [Path(output) for output in outputs]
        shown = [output.with_name(f"{output.stem}_preview.png") for output in written]
    if previews is not None:
        shown = [Path(preview) for preview in previews]
    if srgb not in (None, 8, 16):
        raise ValueError(f"srgb: expected 8 or 16 bits (or None for linear output), got {srgb!r}")
    if len(written) != len(source) or len(shown) != len(source):
        raise ValueError(
            f"outputs, previews: expected one each per image ({len(source)}), got {len(written)} and {len(shown)}"
        )
    canonical = world.canonical_white
    matrix = io.preview_matrix_cached(world)

    def write(index: int, image: LinearImage, estimates: dict[str, Estimate]) -> None:
        estimate = estimates[label]

        # The pixels estimation left out as clipped come out white (one clip rule: the reader's level,
        # 0.98 of saturation by default or the saturation given); transparent ones are mapped as read.
        whitened = image.clipped if image.transparent is None else image.clipped & ~image.transparent

        def corrected(rows: slice) -> np.ndarray:
            return np.asarray(
                correction.correct(
                    image.rgb[rows], estimate.illuminant, canonical, sharpening, 1.0, clipped=whitened[rows]
                )
            )

        # Corrected a piece of rows at a time (twice: once for the file, once for the preview),
        # so no float copy of a camera-sized image is made beside the image itself.
        codes = np.empty(image.rgb.shape, np.uint16 if srgb != 8 else np.uint8)
        for rows in row_slices(image.rgb.shape):
            piece = corrected(rows)
            codes[rows] = io.quantise(piece) if srgb is None else io.encode_srgb(piece @ matrix.T, srgb)
        # A JPEG output keeps its input's EXIF (camera, times), upright as its pixels are.
        exif = upright_exif(image.path) if written[index].suffix.lower() in (".jpg", ".jpeg") else None
        io.write_codes(written[index], codes, overwrite=overwrite, srgb=srgb is not None, exif=exif)
        del codes
        try:
            preview = srgb_preview_rows(corrected, image.rgb.shape, matrix)
            io.write_png(shown[index], preview, overwrite=overwrite, srgb=True)
        except BaseException:
            # An output without its preview (a full disk) would make a rerun refuse the output.
            written[index].unlink(missing_ok=True)
            raise
        if each is not None:
            each(index, estimate, written[index], shown[index])

    return run_models(source, {label: [model]}, preprocessing=preprocessing, dark=dark, progress=progress, each=write)
