"""Labelled photographs of several cameras seen through one target camera: each folder's images and
ground truth mapped into the target's raw space by a camera-to-camera map fitted from spectra
(:mod:`ccjax.transfer`), pooled as one image source.

A :class:`PooledImages` is a source like :class:`ccjax.runs.sources.ImageFolder` (the same
:meth:`~PooledImages.prepared` items, failure records and sizes), so the training readers
(:func:`ccjax.training.source_examples`) and the image loop (:func:`ccjax.runs.images.run_models`,
which gives each process its share of the items under ``jax.distributed``) take it unchanged.
An image and its ground truth are mapped alike: the image by the map of its own light
(:meth:`ccjax.transfer.AbstractCameraMap.map_rgb`), the light by the same matrix
(:meth:`~ccjax.transfer.AbstractCameraMap.map_light`).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from ccjax.preprocessing import DEFAULT_DARK, Preprocessing
from ccjax.runs.sources import ImageFolder, Prepared
from ccjax.transfer import AbstractCameraMap

__all__ = ["ImageSource", "MappedFolder", "PooledImages", "map_input"]


@eqx.filter_jit
def map_input(
    camera_map: AbstractCameraMap,
    rgb: Float[Array, "*shape 3"],
    mask: Bool[Array, "*shape"],
    light: Float[Array, "3"],
) -> tuple[Float[Array, "*shape 3"], Bool[Array, "*shape"]]:
    """One prepared input (an image or a surface list) seen through the target camera.

    A 3x3 map can send a colour outside the target's positive octant (a saturated colour near a
    sensor's edge): such an entry is no longer a physical response, so it leaves the mask (its
    value set to 0) rather than being clipped into a wrong colour.

    Arguments:
        camera_map: the map from the source camera to the target.
        rgb: the source camera's input (``(H, W, 3)`` or ``(P, 3)``).
        mask: its valid entries.
        light: the image's ground-truth light (source-camera RGB of white).

    Returns:
        ``(mapped rgb, mask of the entries still valid)``.
    """
    mapped = camera_map.map_rgb(rgb, light)
    valid = mask & jnp.all(mapped > 0, axis=-1)
    return jnp.where(valid[..., None], mapped, 0.0), valid


@dataclass
class MappedFolder:
    """One labelled folder and the map that takes its camera to the target's.

    Attributes:
        images: the folder's images (:func:`ccjax.runs.sources.image_folder`).
        lights: ``(N, 3)`` the ground-truth light of each of ``images.paths`` (its camera's RGB).
        names: the ground-truth name of each file.
        camera: the camera that took them (its curves, or a named stand-in's).
        camera_map: the map to the target camera; None when the folder's camera is the target.
        label: the folder's name in names and counts (default: the camera's).
    """

    images: ImageFolder
    lights: np.ndarray
    names: list[str]
    camera: str
    camera_map: AbstractCameraMap | None = None
    label: str = ""

    def __post_init__(self) -> None:
        lights = np.asarray(self.lights, np.float32)
        if lights.shape != (len(self.images), 3):
            raise ValueError(f"lights: expected ({len(self.images)}, 3), one per image, got {lights.shape}")
        if len(self.names) != len(self.images):
            raise ValueError(f"names: expected {len(self.images)}, one per image, got {len(self.names)}")
        self.lights = lights
        self.label = self.label or self.camera

    def mapped_lights(self) -> np.ndarray:
        """The ground truth in the target camera.

        Returns:
            ``(N, 3)`` the lights, brightest channel 1.
        """
        if self.camera_map is None:
            return self.lights / self.lights.max(axis=1, keepdims=True)
        return np.asarray(jax.vmap(self.camera_map.map_light)(jnp.asarray(self.lights)))


@dataclass
class PooledImages:
    """Several cameras' labelled folders mapped into one target camera, as one image source.

    Items are numbered across the parts in order (part 0's files first). Use it where an
    :class:`~ccjax.runs.sources.ImageFolder` is used: :meth:`prepared` yields the mapped inputs.

    Attributes:
        parts: the folders, each with its map.
        target: the target camera's name.
    """

    parts: list[MappedFolder]
    target: str
    _offsets: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not self.parts:
            raise ValueError("parts: expected at least one labelled folder to pool")
        self._offsets = np.cumsum([0, *(len(part.images) for part in self.parts)])

    def __len__(self) -> int:
        return int(self._offsets[-1])

    @property
    def paths(self) -> list[Path]:
        """Every part's files, in item order."""
        return [path for part in self.parts for path in part.images.paths]

    @property
    def sizes(self) -> list[tuple[int, int] | None]:
        """``(height, width)`` of every item from its header (None where it was bad)."""
        return [size for part in self.parts for size in part.images.sizes]

    @property
    def failures(self) -> dict[str, str]:
        """``{path: failure record}`` of the files whose header is bad."""
        return {path: line for part in self.parts for path, line in part.images.failures.items()}

    @property
    def names(self) -> list[str]:
        """Each item's ground-truth name, prefixed with its folder's label (names repeat across folders)."""
        return [f"{part.label}/{name}" for part in self.parts for name in part.names]

    def usable(self) -> list[int]:
        """The items whose header passed the checks.

        Returns:
            Their indices.
        """
        return [index for index, size in enumerate(self.sizes) if size is not None]

    def image_sizes(self, items: Iterable[int] | None = None) -> list[tuple[int, int]]:
        """The distinct image sizes among some items.

        Arguments:
            items: the items' indices (``None``: every item).

        Returns:
            The distinct ``(height, width)``.
        """
        sizes = self.sizes
        chosen = range(len(sizes)) if items is None else items
        return sorted({size for index in chosen if (size := sizes[index]) is not None})

    def lights(self) -> np.ndarray:
        """Every item's ground truth mapped into the target camera.

        Returns:
            ``(N, 3)`` the lights, brightest channel 1.
        """
        return np.concatenate([part.mapped_lights() for part in self.parts]).astype(np.float32)

    def counts(self) -> dict[str, int]:
        """The images of each part.

        Returns:
            ``{folder label: images}``.
        """
        return {part.label: len(part.images) for part in self.parts}

    def prepared(
        self,
        rules: Mapping[str, Preprocessing],
        items: Iterable[int] | None = None,
        *,
        dark: float = DEFAULT_DARK,
    ) -> Iterator[Prepared]:
        """Read, prepare (in the source camera, where its clipping and dark rules hold) and map
        each item, one at a time.

        Arguments:
            rules: ``{name: rule}`` the inputs to prepare.
            items: item indices (default: every one), in the order to visit them.
            dark: the dark rule of the surface-list inputs.

        Yields:
            A :class:`~ccjax.runs.sources.Prepared` per item (``index`` numbered across the
            parts), its inputs in the target camera.
        """
        chosen = range(len(self)) if items is None else items
        for index in chosen:
            part_index = int(np.searchsorted(self._offsets, index, side="right")) - 1
            part = self.parts[part_index]
            local = int(index - self._offsets[part_index])
            for item in part.images.prepared(rules, [local], dark=dark):
                item.index = int(index)
                if item.failure is None and part.camera_map is not None:
                    light = jnp.asarray(part.lights[local])
                    mapped = {}
                    for name, (rgb, mask) in item.inputs.items():
                        rgb_out, mask_out = map_input(part.camera_map, jnp.asarray(rgb), jnp.asarray(mask), light)
                        mapped[name] = (np.asarray(rgb_out), np.asarray(mask_out))
                    item.inputs = mapped
                yield item


ImageSource = ImageFolder | PooledImages
"""What the image loop and the training readers iterate: one folder, or several cameras' pooled."""
