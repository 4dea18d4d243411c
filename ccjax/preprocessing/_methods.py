"""The preprocessing methods by name (Table 4.6 and the extensions) and the surface list of an image."""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from ccjax.io.reading import LinearImage
from ccjax.preprocessing._reduction import block_average, cluster_rgb, hull_reduce, segment
from ccjax.preprocessing._rules import DEFAULT_DARK, DEFAULT_PERCENTILE, DEFAULT_PREPROCESSING, PIXELS, usable_pixels


@dataclass(frozen=True)
class Preprocessing:
    """One of the thesis' preprocessing methods (Table 4.6), parsed from a name, or ``pixels``.

    ``ave<b>`` (block averaging, ``ave1`` = single pixels), ``ave<b>-cluster`` (+ RGB clustering,
    100 divisions), ``ave<b>-hull`` (+ convex-hull reduction), ``seg-<min size>-<rg tol>-<rel
    R+G+B tol>`` (segmentation, e.g. ``seg-5-0.005-0.2``), ``seg-...-hull``, and ``generic``
    (Table 4.5's segmentation, ``seg-5-0.05-0.1``). These use the dark rule of
    :func:`usable_pixels`.

    Extensions: ``pixels``, every usable pixel with no dark rule (the image and its mask, as the
    field evaluates statistics methods: :func:`prepare`); ``ave<b>-edges`` also keeps the partial
    tiles of the right and bottom edges (:func:`block_average`); ``ave<b>-u<spread>`` keeps only
    blocks whose (r,g) spread is at most ``<spread>`` (e.g. ``ave5-u0.04``). They combine in the
    order ``ave<b>[-edges][-u<spread>][-cluster|-hull]``, e.g. ``ave5-edges-hull``.

    Attributes:
        name: the name it was parsed from.
        block: block side in pixels (1 for segmentation and ``pixels``).
        segmentation: ``(min size, rg tolerance, relative R+G+B tolerance)``, or None.
        reduction: None, ``"cluster"`` or ``"hull"``.
        max_rg_spread: the largest (r,g) spread of a kept block, or None.
        edges: keep the partial tiles of the right and bottom edges.
        pixels: every usable pixel (``pixels``).
    """

    name: str
    block: int = 5
    segmentation: tuple[int, float, float] | None = None
    reduction: str | None = None  # None, "cluster" or "hull"
    max_rg_spread: float | None = None
    edges: bool = False
    pixels: bool = False

    @classmethod
    def parse(cls, name: str) -> Preprocessing:
        """The method called ``name`` (class docstring).

        Arguments:
            name: the method's name.

        Returns:
            The :class:`Preprocessing`.

        Raises:
            ValueError: an unknown name.
        """
        if name == PIXELS:
            return cls(name=name, block=1, pixels=True)
        text = "seg-5-0.05-0.1" if name == "generic" else name
        number = r"(\d+(?:\.\d*)?|\.\d+)"
        match = re.fullmatch(rf"ave(\d+)(-edges)?(?:-u{number})?(?:-(cluster|hull))?", text)
        if match and int(match[1]) >= 1:
            spread = None if match[3] is None else float(match[3])
            return cls(
                name=name,
                block=int(match[1]),
                reduction=match[4],
                max_rg_spread=spread,
                edges=match[2] is not None,
            )
        match = re.fullmatch(rf"seg-(\d+)-{number}-{number}(?:-(hull))?", text)
        if match:
            return cls(
                name=name, block=1, segmentation=(int(match[1]), float(match[2]), float(match[3])), reduction=match[4]
            )
        raise ValueError(
            f"preprocessing: unknown method {name!r}; expected pixels, ave<b>[-edges][-u<spread>][-cluster|-hull], "
            "seg-<min>-<rg>-<rel>[-hull] or generic"
        )

    def apply(self, rgb: np.ndarray, usable: np.ndarray) -> np.ndarray:
        """The surface list of one image.

        Arguments:
            rgb: ``(H, W, 3)`` the image.
            usable: ``(H, W)`` its usable pixels (:func:`usable_pixels`).

        Returns:
            ``(n, 3)`` the surfaces (``pixels``: the usable pixels themselves, in scan order).
        """
        if self.pixels:
            return rgb[usable]
        if self.segmentation is not None:
            data = segment(rgb, usable, *self.segmentation)
        else:
            data = block_average(rgb, usable, self.block, self.max_rg_spread, edges=self.edges)
        if self.reduction == "cluster":
            data = cluster_rgb(data)
        elif self.reduction == "hull":
            data = hull_reduce(data)
        return data

    def max_count(self, height: int, width: int) -> int:
        """The most surfaces :meth:`apply` can return for an image of this size.

        Arguments:
            height: the image's height in pixels.
            width: its width.

        Returns:
            The largest surface count.
        """
        if self.pixels:
            return height * width
        if self.segmentation is not None:
            return (height * width) // max(self.segmentation[0], 1)
        if self.edges:
            return -(-height // self.block) * -(-width // self.block)
        return (height // self.block) * (width // self.block)


def as_preprocessing(preprocessing: str | Preprocessing) -> Preprocessing:
    """``preprocessing`` as a :class:`Preprocessing` (names are parsed; ``ValueError`` if unknown).

    Arguments:
        preprocessing: a name or a :class:`Preprocessing`.

    Returns:
        The :class:`Preprocessing`.
    """
    return preprocessing if isinstance(preprocessing, Preprocessing) else Preprocessing.parse(preprocessing)


TABLE_4_6 = (
    [f"seg-{m}-{t}-{b}" for t in (0.0025, 0.005, 0.01, 0.02) for b in (0.1, 0.2, 0.3, 0.4) for m in (5, 10, 20)]
    + [f"ave{b}" for b in (1, 2, 3, 5, 7)]
    + [f"ave{b}-cluster" for b in (1, 2, 3, 5, 7)]
    + [f"ave{b}-hull" for b in (1, 2, 3, 5, 7)]
)
"""The 63 well-defined preprocessing methods of Table 4.6 (48 segmentations, 5 block sizes, 5 with
RGB clustering, 5 with hull reduction). The thesis' remaining two ("two selected segmentations +
hull reduction") do not say which segmentations; any ``seg-...-hull`` name runs such a variant."""


def padded_size(count: int | np.integer) -> int:
    """The length surface lists of ``count`` rows are padded to: a power of two, at least 64, so
    jit compiles once per size class, not once per image.

    Arguments:
        count: the number of surfaces.

    Returns:
        The padded length.
    """
    return max(64, 1 << int(np.ceil(np.log2(max(count, 1)))))


def surfaces(
    image: LinearImage,
    preprocessing: str | Preprocessing = DEFAULT_PREPROCESSING,
    *,
    dark: float = DEFAULT_DARK,
    pad: bool = True,
    mask: np.ndarray | None = None,
    percentile: float = DEFAULT_PERCENTILE,
) -> tuple[np.ndarray, np.ndarray]:
    """Estimator input of a surface-list method.

    Arguments:
        image: a :class:`ccjax.io.LinearImage`.
        preprocessing: a :class:`Preprocessing` or its name (default ``ave5``). ``pixels`` gives
            the list of usable pixels (no dark rule); :func:`prepare` gives the image instead,
            which is smaller and faster.
        dark, percentile, mask: the usable-pixel rules (:func:`usable_pixels`).
        pad: pad to :func:`padded_size` with masked zero rows, so batches share compiled code.

    Returns:
        ``(rgb (N, 3) float32, mask (N,) bool)``.
    """
    method = as_preprocessing(preprocessing)
    usable = usable_pixels(image.rgb, image.clipped, 0.0 if method.pixels else dark, percentile=percentile, mask=mask)
    data = method.apply(image.rgb, usable)
    size = padded_size(len(data)) if pad else len(data)
    rgb = np.zeros((size, 3), np.float32)
    rgb[: len(data)] = data
    valid = np.arange(size) < len(data)
    return rgb, valid
