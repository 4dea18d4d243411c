"""Image sources: a folder (or list) of photographs listed once, every header probed once, each
image read, masked with its optional mask file and prepared per each model's input rule, with one
failure record per file that cannot be used.

The execution layer's image loop (:func:`ccjax.runs.images.run_models`) and the training readers
(:func:`ccjax.training.read_examples`) both iterate :meth:`ImageFolder.prepared`, so a model is
given the same input wherever it meets a photograph.
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ccjax import io
from ccjax.estimators.base import AbstractEstimator
from ccjax.io.reading import MAX_PIXELS, LinearImage
from ccjax.preprocessing import DEFAULT_DARK, Preprocessing, as_preprocessing, prepare_input, resolve

MASK_SUFFIXES = (".png", ".tif", ".tiff")
"""Suffixes a mask file may have (``<mask folder>/<image stem><suffix>``)."""

Images = str | os.PathLike | Iterable[str | os.PathLike]
"""A folder, an image file, or a list of files and folders (:func:`ccjax.io.list_images`)."""


def failure_line(path: str | os.PathLike, error: BaseException) -> str:
    """The failure record of one file: the error's message, prefixed with the path unless the
    message names it already.

    Arguments:
        path: the file.
        error: why it cannot be used.

    Returns:
        One line.
    """
    message = str(error)
    return message if str(path) in message else f"{path}: {message}"


def raise_failures(lines: Sequence[str], total: int) -> None:
    """Raise one ``ValueError`` naming every file that could not be used (nothing if none).

    Arguments:
        lines: one failure record per bad file (:func:`failure_line`).
        total: how many files the run was given.

    Returns:
        None.

    Raises:
        ValueError: when ``lines`` is not empty: the line itself for a run of one file, else
            ``"<n> of <total> images cannot be used:"`` and one indented line per file.
    """
    if len(lines) == 1 and total == 1:
        raise ValueError(lines[0])
    if lines:
        raise ValueError(f"{len(lines)} of {total} images cannot be used:\n  " + "\n  ".join(lines))


def list_images(images: Images) -> list[Path]:
    """The image files of ``images``: a folder's image files (sorted), a file, or a list of both
    expanded in order (:func:`ccjax.io.list_images`).

    Arguments:
        images: a folder, a file, or a list of files and folders.

    Returns:
        The files.
    """
    if isinstance(images, (str, os.PathLike)):
        images = [images]
    return io.list_images(images)


def mask_files(
    paths: Sequence[str | os.PathLike], folder: str | os.PathLike | None, *, argument: str = "masks"
) -> list[Path] | None:
    """The mask file of each image: ``folder/<stem>.png`` (or ``.tif``, ``.tiff``).

    Arguments:
        paths: the image files.
        folder: the mask folder (None: no masks).
        argument: the name the errors give the folder (e.g. a command's ``--mask``).

    Returns:
        One path per image, or None without ``folder``.

    Raises:
        ValueError: ``folder`` is not a folder, or an image has no mask (every such image named),
            or two mask files fit one image.
    """
    if folder is None:
        return None
    folder = Path(folder)
    if not folder.is_dir():
        raise ValueError(f"{argument}: {folder} is not a folder")
    found, missing = [], []
    for path in paths:
        candidates = [folder / f"{Path(path).stem}{suffix}" for suffix in MASK_SUFFIXES]
        present = [candidate for candidate in candidates if candidate.is_file()]
        if len(present) > 1:
            raise ValueError(f"{argument}: {' and '.join(map(str, present))} both fit image {path}; keep one")
        if not present:
            missing.append(str(path))
        else:
            found.append(present[0])
    if missing:
        names = ", ".join(missing[:5]) + (f" and {len(missing) - 5} more" if len(missing) > 5 else "")
        raise ValueError(
            f"{argument}: no mask in {folder} for {names} (looked for <stem>.png, <stem>.tif, <stem>.tiff)"
        )
    return found


def input_rules(
    models: Mapping[str, AbstractEstimator], preprocessing: str | Preprocessing | None = None
) -> tuple[dict[str, str], dict[str, Preprocessing]]:
    """Each model's input rule (:func:`ccjax.preprocessing.resolve`), shared between the models
    that get the same input.

    Arguments:
        models: ``{label: model}``.
        preprocessing: one preprocessing for every model; None: each model's default.

    Returns:
        ``({label: key}, {key: Preprocessing})``; the key is the rule's name.
    """
    rules = {label: resolve(model, preprocessing) for label, model in models.items()}
    return {label: rule.name for label, rule in rules.items()}, {rule.name: rule for rule in rules.values()}


@dataclass
class Prepared:
    """One image of a source, read and prepared (or the reason it could not be).

    Attributes:
        index: its index in the source.
        path: the file.
        image: the image (None when it failed).
        inputs: ``{rule name: (rgb, mask)}`` what :func:`ccjax.preprocessing.prepare` gives each rule.
        failure: the failure record (:func:`failure_line`), None when the image was prepared.
        error: the exception behind ``failure``.
        read_seconds: time spent decoding the file and its mask.
        prepare_seconds: ``{rule name: s}`` time spent preparing each input.
    """

    index: int
    path: Path
    image: LinearImage | None = None
    inputs: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    failure: str | None = None
    error: BaseException | None = None
    read_seconds: float = 0.0
    prepare_seconds: dict[str, float] = field(default_factory=dict)


@dataclass
class ImageFolder:
    """Image files with their optional masks, each header probed once (:func:`image_folder`).

    Attributes:
        paths: the files, in order (an item of the source is an index into them).
        masks: one mask file (or None) per file, or None without masks.
        read_options: keyword arguments of :func:`ccjax.io.read_image`.
        sizes: ``(height, width)`` of each file from its header; None where the header is bad.
        failures: ``{path: failure record}`` of the files whose header is bad.
        errors: ``{path: exception}`` behind ``failures``.
    """

    paths: list[Path]
    masks: list[Path | None] | None = None
    read_options: dict = field(default_factory=dict)
    sizes: list[tuple[int, int] | None] = field(default_factory=list)
    failures: dict[str, str] = field(default_factory=dict)
    errors: dict[str, BaseException] = field(default_factory=dict, repr=False)

    def __len__(self) -> int:
        return len(self.paths)

    def usable(self) -> list[int]:
        """The indices of the files whose header passed the checks.

        Returns:
            Indices into :attr:`paths`, in order.
        """
        return [index for index, size in enumerate(self.sizes) if size is not None]

    def image_sizes(self, items: Iterable[int] | None = None) -> list[tuple[int, int]]:
        """The distinct image sizes among ``items`` (default: every file), from the headers.

        Arguments:
            items: indices into :attr:`paths`.

        Returns:
            Sorted ``(height, width)`` pairs.
        """
        chosen = range(len(self.paths)) if items is None else items
        return sorted({size for index in chosen if (size := self.sizes[index]) is not None})

    def read(self, index: int) -> tuple[LinearImage, np.ndarray | None]:
        """Decode file ``index`` and its mask.

        Arguments:
            index: an index into :attr:`paths`.

        Returns:
            ``(image, (H, W) bool mask or None)``.
        """
        image = io.read_image(self.paths[index], **self.read_options)
        mask_file = None if self.masks is None else self.masks[index]
        return image, None if mask_file is None else io.read_mask(mask_file, image.shape)

    def prepared(
        self,
        rules: Mapping[str, Preprocessing],
        items: Iterable[int] | None = None,
        *,
        dark: float = DEFAULT_DARK,
    ) -> Iterator[Prepared]:
        """Read and prepare each item, one at a time (one image in memory).

        Arguments:
            rules: ``{name: rule}`` the inputs to prepare (:func:`input_rules`).
            items: indices into :attr:`paths` (default: every file), in the order to visit them.
            dark: the dark rule of the surface-list inputs.

        Yields:
            A :class:`Prepared` per item; a file whose header was bad, or that cannot be decoded
            or prepared (NaN, every pixel clipped, truncated data, a bad mask), has its failure
            record and no inputs.
        """
        for index in range(len(self.paths)) if items is None else items:
            path = self.paths[index]
            if str(path) in self.failures:
                error = self.errors[str(path)]
                yield Prepared(index, path, failure=self.failures[str(path)], error=error)
                continue
            item = Prepared(index, path)
            try:
                start = time.perf_counter()
                item.image, mask = self.read(index)
                item.read_seconds = time.perf_counter() - start
                for name, rule in rules.items():
                    start = time.perf_counter()
                    item.inputs[name] = prepare_input(rule, item.image, dark=dark, mask=mask)
                    item.prepare_seconds[name] = time.perf_counter() - start
            except (ValueError, OSError) as error:
                item = Prepared(index, path, failure=failure_line(path, error), error=error)
            yield item


def image_folder(
    images: Images,
    *,
    masks: str | os.PathLike | Sequence[str | os.PathLike | None] | None = None,
    read_options: dict | None = None,
    keep_going: bool = True,
    mask_argument: str = "masks",
    max_pixels: int | None = MAX_PIXELS,
) -> ImageFolder:
    """List the image files once and probe every header once (:func:`ccjax.io.probe_image`).

    Arguments:
        images: a folder, a file, or a list of files and folders.
        masks: a folder of masks named by the images' stems (:func:`mask_files`), or one mask
            file (or None) per image, or None.
        read_options: keyword arguments of :func:`ccjax.io.read_image` and
            :func:`ccjax.io.probe_image`.
        keep_going: record a file whose header is bad in :attr:`ImageFolder.failures` and go on;
            otherwise its error is raised.
        mask_argument: the name the mask errors give ``masks``.
        max_pixels: the pixel budget (:func:`ccjax.io.probe_image`): a file whose header claims
            more pixels is a failure record like any bad header, and nothing is allocated for it
            (a ``max_pixels`` in ``read_options`` wins; None: no limit).

    Returns:
        The :class:`ImageFolder`.

    Raises:
        ValueError: no image files; masks that do not fit the images.
    """
    paths = list_images(images)
    if not paths:
        raise ValueError("images: no image files given (folders are searched for .png, .tif, .tiff and raw files)")
    if masks is None or isinstance(masks, (str, os.PathLike)):
        mask_list: list[Path | None] | None = mask_files(paths, masks, argument=mask_argument)  # type: ignore[assignment]
    else:
        mask_list = [None if mask is None else Path(mask) for mask in masks]
        if len(mask_list) != len(paths):
            raise ValueError(f"{mask_argument}: expected one entry per image ({len(paths)}), got {len(mask_list)}")
    source = ImageFolder(paths, mask_list, {"max_pixels": max_pixels} | dict(read_options or {}))
    for path in paths:
        try:
            info = io.probe_image(path, **source.read_options)
        except (ValueError, OSError) as error:
            if not keep_going:
                raise
            source.sizes.append(None)
            source.failures[str(path)] = failure_line(path, error)
            source.errors[str(path)] = error
            continue
        source.sizes.append((info.height, info.width))
    return source


def check_preprocessing(preprocessing: str | Preprocessing | None) -> None:
    """Refuse an unknown preprocessing name before any work (None: each model's default).

    Arguments:
        preprocessing: a name or a :class:`Preprocessing`.

    Returns:
        None.

    Raises:
        ValueError: naming ``preprocessing`` and the known grammars.
    """
    if preprocessing is not None:
        as_preprocessing(preprocessing)
