"""The options of a photo evaluation that are not its protocol: how images are read and prepared
(:class:`ReadOptions`) and how learned methods are trained (:class:`TrainingOptions`)."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any

from ccjax.io.reading import MAX_PIXELS
from ccjax.preprocessing import DEFAULT_DARK, Preprocessing

__all__ = ["ReadOptions", "TrainingOptions"]


@dataclass(frozen=True)
class ReadOptions:
    """How every folder's images are read, masked and prepared.

    Attributes:
        image: keyword arguments of :func:`ccjax.io.read_image` (black level, saturation, ...).
        masks: a folder of masks named by the images' stems (one folder only), or None.
        max_pixels: the pixel budget: a file whose header claims more pixels is a failure record
            before anything is allocated for it (None: no limit).
        allow_missing: score the listed images when other image files of a folder have no
            ground-truth row (they are named) instead of refusing.
        preprocessing: one preprocessing for every method (None: each method's default).
        dark: the surface lists' dark rule.
    """

    image: dict[str, Any] = field(default_factory=dict)
    masks: str | os.PathLike | None = None
    max_pixels: int | None = MAX_PIXELS
    allow_missing: bool = False
    preprocessing: str | Preprocessing | None = None
    dark: float = DEFAULT_DARK


@dataclass(frozen=True)
class TrainingOptions:
    """How the protocol's learned methods are trained.

    Attributes:
        seed: seed of the worlds, the folds' assignment, the training and the rendered images.
        epochs: training epochs at most (None: each family's schedule,
            :func:`ccjax.training.default_schedule`).
        pretraining: a :class:`ccjax.training.Pretraining`: each start is pretrained on images
            rendered from spectra, then fine-tuned (None: trained from its fit to the world).
    """

    seed: int = 0
    epochs: int | None = None
    pretraining: Any = None

    def __post_init__(self) -> None:
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise ValueError(f"seed: expected a non-negative integer, got {self.seed!r}")
        if self.epochs is not None and (isinstance(self.epochs, bool) or self.epochs < 1):
            raise ValueError(f"epochs: expected a positive integer, got {self.epochs}")

    def schedule_changes(self) -> dict[str, int]:
        """The fields of a family's schedule these options set (:func:`ccjax.training.default_schedule`).

        Returns:
            ``{field: value}`` of the options that are set.
        """
        return {"seed": self.seed} if self.epochs is None else {"seed": self.seed, "epochs": self.epochs}
