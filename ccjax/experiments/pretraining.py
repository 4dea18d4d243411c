"""The pretraining curve: a learned estimator trained on a share of each training fold of a photo
set, from scratch and fine-tuned from its pretraining on rendered images
(:func:`ccjax.training.pretrain`), scored on the held-out fold.

For every fold, fraction and subset, the training images are a seeded random subset of the other
folds' images (never the scored fold's); both arms train on the same subset. Each subset's errors
are pooled over the folds (every image scored once), and the subsets' mean and median errors are
summarised by their mean and standard deviation.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from ccjax.io.ground_truth import match_ground_truth, read_ground_truth_file
from ccjax.preprocessing import resolve
from ccjax.runs import store
from ccjax.runs.sources import image_folder
from ccjax.training import (
    Pretraining,
    angular_errors,
    assign_folds,
    fine_tune,
    pretrain,
    source_examples,
    train_model,
)

__all__ = ["ARMS", "PretrainingCurve", "pretraining_curve"]

ARMS = ("not pretrained", "pretrained")
"""The two arms of every point of the curve."""


@dataclass
class PretrainingCurve:
    """Pooled errors per fraction, subset and arm.

    Attributes:
        method: the label trained.
        camera: the camera whose curves rendered the pretraining images.
        errors: ``{(fraction, subset, arm): (N,) pooled angular errors in degrees}``.
        zero_shot: the pretrained model's errors on every image, before any photograph.
        train_seconds: ``{arm: total training seconds}``.
    """

    method: str
    camera: str
    errors: dict[tuple[float, int, str], np.ndarray] = field(default_factory=dict)
    zero_shot: np.ndarray | None = None
    train_seconds: dict[str, float] = field(default_factory=dict)

    def summary(self) -> list[dict]:
        """One row per fraction and arm: the subsets' mean and median errors, their mean and
        standard deviation over the subsets.

        Returns:
            Rows ``{fraction, arm, subsets, mean, mean_sd, median, median_sd}``.
        """
        rows = []
        for fraction in sorted({key[0] for key in self.errors}):
            for arm in ARMS:
                runs = [errors for (f, _, a), errors in sorted(self.errors.items()) if f == fraction and a == arm]
                means = np.array([np.mean(e) for e in runs])
                medians = np.array([np.median(e) for e in runs])
                rows.append(
                    {
                        "fraction": fraction,
                        "arm": arm,
                        "subsets": len(runs),
                        "mean": float(np.mean(means)),
                        "mean_sd": float(np.std(means)),
                        "median": float(np.mean(medians)),
                        "median_sd": float(np.std(medians)),
                    }
                )
        return rows

    def table(self) -> str:
        """The curve as text.

        Returns:
            One line per fraction, both arms' mean and median (mean +- sd over the subsets).
        """
        lines = [
            f"{self.method} on photographs, pretrained on images rendered with {self.camera}'s curves: angular "
            "error (degrees), errors pooled over the folds, mean +- sd over the subsets",
            f"{'fraction':>9}{'subsets':>8}" + "".join(f"{arm + ' mean':>24}{arm + ' median':>24}" for arm in ARMS),
        ]
        rows = self.summary()
        for index in range(0, len(rows), len(ARMS)):
            pair = rows[index : index + len(ARMS)]
            spreads = [f"{r[name]:.3f} +- {r[name + '_sd']:.3f}" for r in pair for name in ("mean", "median")]
            cells = "".join(f"{cell:>24}" for cell in spreads)
            lines.append(f"{pair[0]['fraction']:>9.0%}{pair[0]['subsets']:>8}{cells}")
        if self.zero_shot is not None:
            lines.append(
                f"pretrained only (no photograph): mean {np.mean(self.zero_shot):.3f}, median "
                f"{np.median(self.zero_shot):.3f}"
            )
        seconds = ", ".join(f"{arm} {s:.0f} s" for arm, s in self.train_seconds.items())
        lines.append(f"training time in all: {seconds}")
        return "\n".join(lines)


def pretraining_curve(
    directory: str | os.PathLike,
    ground_truth: str | os.PathLike,
    pretraining: Pretraining,
    *,
    method: str = "FFCC",
    fractions: Sequence[float] = (0.1, 0.25, 0.5, 1.0),
    subsets: int = 3,
    folds: int = 3,
    seed: int = 0,
    read_options: dict | None = None,
    log: Callable[[str], None] | None = None,
) -> PretrainingCurve:
    """Train ``method`` on shares of each training fold, from scratch and fine-tuned from its
    pretraining (module docstring).

    Arguments:
        directory: the image folder.
        ground_truth: its CSV (``image,r,g,b[,fold]``; folds from the fold column when it has one).
        pretraining: what to render (its camera: the photographs' camera or a stand-in).
        method: a trainable registry label (``FFCC``, ``RGB-C-by-C-MMSE``, ...).
        fractions: shares of each training fold, in ``(0, 1]``.
        subsets: random subsets per fraction below 1 (a fraction of 1 has one).
        folds: the number of folds.
        seed: seed of the fold assignment and of the subsets.
        read_options: keyword arguments of :func:`ccjax.io.read_image` (e.g. ``{"saturation": 64224}``).
        log: called with a line of progress.

    Returns:
        The :class:`PretrainingCurve`.

    Raises:
        ValueError: a fraction outside ``(0, 1]`` or fewer than one subset.
    """
    if not all(0 < f <= 1 for f in fractions):
        raise ValueError(f"fractions: expected shares in (0, 1], got {list(fractions)}")
    if isinstance(subsets, bool) or not isinstance(subsets, int) or subsets < 1:
        raise ValueError(f"subsets: expected a positive integer, got {subsets!r}")
    say = log or (lambda line: None)
    start = store.fit(method, store.world("default", pretraining.camera))
    rule = resolve(start)
    table = read_ground_truth_file(ground_truth)
    pairs = match_ground_truth(table.lights, directory)
    source = image_folder([path for path, _ in pairs], read_options=read_options)
    lights = np.stack([light for _, light in pairs])
    examples, _ = source_examples(source, lights, list(table.lights), start.input_kind, rule)
    fold_of = assign_folds(examples.names, folds, seed=seed, given=table.folds)
    say(f"{len(examples)} photographs, {folds} folds; pretraining {method} on {pretraining.images} rendered images")
    pretrained, pre_log = pretrain(start, pretraining, rule)
    say(f"pretrained in {pre_log.seconds:.0f} s")
    curve = PretrainingCurve(method, pretraining.camera, zero_shot=angular_errors(pretrained, examples))
    curve.train_seconds = dict.fromkeys(ARMS, 0.0)
    pieces: dict[tuple[float, int, str], list[np.ndarray]] = {}
    for fold in range(folds):
        test = np.flatnonzero(fold_of == fold)
        train = np.flatnonzero(fold_of != fold)
        for f_index, fraction in enumerate(fractions):
            for subset in range(subsets if fraction < 1 else 1):
                rng = np.random.default_rng([seed, fold, f_index, subset])
                count = max(1, round(fraction * len(train)))
                chosen = np.sort(rng.choice(train, size=count, replace=False))
                part = examples.take(chosen)
                for arm in ARMS:
                    if arm == "pretrained":
                        model, train_log = fine_tune(pretrained, part)
                    else:
                        model, train_log = train_model(start, part, progress=False)
                    curve.train_seconds[arm] += train_log.seconds
                    errors = angular_errors(model, examples.take(test))
                    pieces.setdefault((fraction, subset, arm), []).append(errors)
                    say(
                        f"fold {fold} {fraction:.0%} subset {subset} {arm}: {count} images, median "
                        f"{np.median(errors):.3f}, mean {np.mean(errors):.3f}"
                    )
    curve.errors = {key: np.concatenate(parts) for key, parts in pieces.items()}
    return curve
