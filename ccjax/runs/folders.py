"""Python calls over a folder of photographs: estimate each image's light, or correct each image to
the canonical light, through the one image loop (:func:`ccjax.runs.images.run_models`).

Each call takes a folder, a file, a list of them, or an :class:`~ccjax.runs.sources.ImageFolder`
already probed, and a registry label (fitted through :mod:`ccjax.runs.store`) or a fitted model.
Files that cannot be used do not stop the run: each has its failure record in the result.
"""

from __future__ import annotations

import dataclasses
import os
import uuid
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np

from ccjax import io
from ccjax._cache import atomic_write_files
from ccjax.estimators.base import AbstractEstimator, Estimate
from ccjax.io.jpeg import upright_exif
from ccjax.io.outputs import path_key
from ccjax.io.png import png_bytes
from ccjax.io.preview import srgb_preview_rows
from ccjax.io.raw import camera_to_srgb
from ccjax.io.reading import MAX_PIXELS, LinearImage
from ccjax.io.writing import row_slices
from ccjax.preprocessing import DEFAULT_DARK, Preprocessing
from ccjax.runs.images import ImageRun, run_models
from ccjax.runs.sources import ImageFolder, Images, image_folder
from ccjax.world import World

OUTPUT_SUFFIXES = (".png", ".tif", ".tiff")
"""Suffixes of corrected images (16-bit PNG or TIFF); other inputs (raw files) are written as ``.tiff``."""

PREVIEW_SIZE = 1024
"""Default longest side of a preview, in pixels (a screen's worth: a 12 MP image's preview at full
size is a 16 MB PNG beside its 2 MB JPEG)."""


def preview_path(output: str | os.PathLike) -> Path:
    """The default preview of an output, named after its full name so that two outputs of one stem
    (``a.png`` and ``a.jpg``) never share one: ``a.png`` gives ``a_preview.png``, any other suffix
    is kept in the name (``a.jpg`` gives ``a_jpg_preview.png``, ``a.tif`` ``a_tif_preview.png``).

    Arguments:
        output: the corrected image's path.

    Returns:
        The preview's path, beside the output.
    """
    output = Path(output)
    suffix = output.suffix.lower()
    tag = "" if suffix == ".png" else f"_{output.suffix.lstrip('.')}"
    return output.with_name(f"{output.stem}{tag}_preview.png")


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


def folder_outputs(
    paths: Sequence[str | os.PathLike], target: str | os.PathLike, *, suffix: str | None = None
) -> tuple[list[Path], list[Path]]:
    """Output and preview paths in folder ``target`` for each input, no two alike (case-insensitively).

    ``a.png`` gives ``a.png`` and ``a_preview.png`` (:func:`preview_path`); a later input whose
    names are taken (``a.tif``, ``A.PNG`` beside it) gets its original suffix in the stem:
    ``a_tif.tif``, ``a_tif_tif_preview.png``, then a number (``A_PNG-2.png``).

    Arguments:
        paths: the input files.
        target: the output folder.
        suffix: every output's suffix (``".jpg"`` for JPEG outputs); None: the input's own when it
            is one of :data:`OUTPUT_SUFFIXES`, else ``.tiff``.

    Returns:
        ``(outputs, previews)``, lists of paths.
    """
    target = Path(target)
    used: set[str] = set()
    outputs, previews = [], []
    for path in map(Path, paths):
        own = path.suffix.lower() if path.suffix.lower() in OUTPUT_SUFFIXES else ".tiff"
        ending = own if suffix is None else suffix
        tags = ["", f"_{path.suffix.lstrip('.')}"]
        tags += [f"_{path.suffix.lstrip('.')}-{number}" for number in range(2, len(paths) + 3)]
        for tag in tags:
            output = target / f"{path.stem}{tag}{ending}"
            preview = preview_path(output)
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
    previews: Sequence[str | os.PathLike] | bool | None = None,
    preview_size: int | None = PREVIEW_SIZE,
    world: World | None = None,
    sharpening: np.ndarray | None = None,
    preprocessing: str | Preprocessing | None = None,
    dark: float = DEFAULT_DARK,
    read_options: dict | None = None,
    masks: str | os.PathLike | Sequence[str | os.PathLike | None] | None = None,
    progress: bool = False,
    each: Callable[[int, Estimate, Path, Path | None], None] | None = None,
    max_pixels: int | None = MAX_PIXELS,
    overwrite: bool = True,
    srgb: int | None = None,
) -> ImageRun:
    """Estimate each image's light and write it corrected to the canonical light (a diagonal map,
    or a sharpened-diagonal one) as a linear 16-bit image (or, with ``srgb``, an sRGB one) and an
    8-bit sRGB preview. Clipped pixels come out white (:func:`ccjax.correction.correct`).

    Every file is written atomically (a temporary name put in place,
    :func:`ccjax.io.outputs.put_in_place`); existing files are replaced unless ``overwrite`` is
    False (then a file found at an output's name is kept and that image fails: it is not done and
    its failure record names the file, and the other images are still corrected), so a caller
    that must not replace them checks first (:func:`ccjax.io.outputs.check_outputs`) and passes
    False.

    Arguments:
        images: a folder, a file, a list of them, or an :class:`~ccjax.runs.sources.ImageFolder`.
        method: a registry label (fitted to ``world`` through the store) or a fitted estimator.
        outputs: an output folder (names from :func:`folder_outputs`), or one output file
            (``.png``, ``.tif``, ``.tiff``) per image.
        previews: one preview file (``.png``) per image; None or True: :func:`preview_path` of each
            output; False: no previews.
        preview_size: a preview's longest side at most, in pixels (block means in linear light,
            :func:`ccjax.io.srgb_preview_rows`); None: full size.
        world: the world (default :func:`ccjax.runs.store.world`): labels are fitted to it, its
            canonical light is the target and its camera gives the sRGB colours of files that
            carry no colour matrix of their own. A raw file is estimated at half size and
            corrected at full size (:func:`ccjax.io.read_image`'s ``raw_full_size``).
        sharpening: optional invertible ``(3, 3)`` sharpening transform (:func:`ccjax.correction.correct`).
        preprocessing, dark, read_options, masks, progress, max_pixels: as :func:`estimate_folder`.
        each: called after each image is written with ``(index in the source, estimate, output,
            preview)`` (preview None without previews).
        overwrite: replace files already at the outputs' names.
        srgb: 8 or 16: write the output as sRGB with that many bits instead of linear camera RGB,
            at full resolution and without the preview's exposure change (the raw file's own
            colour matrix when it carries one, :func:`ccjax.io.raw.camera_to_srgb`, else the world
            camera's, :func:`ccjax.io.preview_matrix`; then the sRGB transfer curve: the canonical
            white at full scale is sRGB white); into a folder, ``srgb=8``
            writes JPEGs under the inputs' stems.

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
    if srgb not in (None, 8, 16):
        raise ValueError(f"srgb: expected 8 or 16 bits (or None for linear output), got {srgb!r}")
    if isinstance(outputs, (str, os.PathLike)):
        # 8-bit sRGB is what JPEG holds: a folder corrected for viewing becomes a folder of JPEGs.
        written, _ = folder_outputs(source.paths, outputs, suffix=".jpg" if srgb == 8 else None)
    else:
        written = [Path(output) for output in outputs]
    shown: list[Path | None] = [preview_path(output) for output in written]
    if previews is False:
        shown = [None] * len(written)
    elif previews is not None and previews is not True:
        shown = [Path(preview) for preview in previews]
    if len(written) != len(source) or len(shown) != len(source):
        raise ValueError(
            f"outputs, previews: expected one each per image ({len(source)}), got {len(written)} and {len(shown)}"
        )
    canonical = world.canonical_white
    matrix = io.preview_matrix_cached(world)
    appeared: dict[int, str] = {}  # index in the source -> failure record

    def write(index: int, image: LinearImage, estimates: dict[str, Estimate]) -> None:
        estimate = estimates[label]
        if Path(image.path).suffix.lower() in io.RAW_SUFFIXES:
            # Estimated on the half-size read (unmixed pixels, §2.7); corrected at the sensor's full
            # size, demosaiced, on the same unit scale (LibRaw's black and white levels).
            image = io.read_image(image.path, **source.read_options, raw_full_size=True)
        # A raw file's own colour matrix gives its sRGB colours; other files the world camera's.
        colours = matrix if image.camera_to_xyz is None else camera_to_srgb(image.camera_to_xyz, canonical)

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
            codes[rows] = io.quantise(piece) if srgb is None else io.encode_srgb(piece @ colours.T, srgb)
        # A JPEG output keeps its input's EXIF (camera, times), upright as its pixels are.
        exif = upright_exif(image.path) if written[index].suffix.lower() in (".jpg", ".jpeg") else None
        # The image and its preview are one pair: both are written whole to temporaries before
        # either replaces anything, then put in place together (atomic_write_files, with Ctrl-C
        # and SIGTERM held over the renames), and both carry this pair's identifier (io.file_run).
        run = uuid.uuid4().hex
        files = {written[index]: io.encoded_codes(written[index], codes, srgb=srgb is not None, exif=exif, run=run)}
        preview_file = shown[index]
        if preview_file is not None:
            preview = srgb_preview_rows(corrected, image.rgb.shape, colours, size=preview_size)
            files[preview_file] = png_bytes(preview, srgb=True, run=run)
        try:
            atomic_write_files(files, replace=overwrite)
        except FileExistsError as error:
            if overwrite:
                raise
            # Another process wrote one of this image's outputs after the run began: that file is
            # kept and this image fails, but the others are still corrected.
            appeared[index] = f"{image.path}: {error.filename} {error.strerror}"
            return
        del codes
        if each is not None:
            each(index, estimate, written[index], shown[index])

    run = run_models(source, {label: [model]}, preprocessing=preprocessing, dark=dark, progress=progress, each=write)
    return with_failures(run, appeared)


def with_failures(run: ImageRun, failed: Mapping[int, str]) -> ImageRun:
    """``run`` with more images failed after their estimate (an output that could not be written):
    each is marked not done and its failure record joins the others, in item order.

    Arguments:
        run: the run.
        failed: ``{index in the source: failure record}`` (items not in the run are ignored).

    Returns:
        A new :class:`~ccjax.runs.images.ImageRun` (``run`` itself when ``failed`` is empty).
    """
    if not failed:
        return run
    done = np.array(run.done, copy=True)
    records = dict(run.failures)
    for position, index in enumerate(np.asarray(run.items).tolist()):
        if index in failed:
            done[position] = False
            records[run.paths[position]] = failed[index]
    order = {path: position for position, path in enumerate(run.paths)}
    failures = dict(sorted(records.items(), key=lambda item: order.get(item[0], len(order))))
    return dataclasses.replace(run, done=done, failures=failures)
