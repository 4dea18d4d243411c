"""Evaluating estimators on a folder of images with ground truth (Barnard 1999 §4.6, ch. 5).

:func:`run_images` runs methods over image files through the execution layer's image loop
(:func:`ccjax.runs.images.run_models`: each image read once, each method on its own input,
compilation timed apart) and gives :class:`ImageResults`, the field's statistics and tables;
:func:`fold_worlds` builds the worlds of a K-fold cross-validation whose trained methods learn the
lights of the other folds' ground truth. Whole-folder evaluation with folds and training
within them is :func:`ccjax.evaluation.evaluate`. Worlds and fitted models come
from :mod:`ccjax.runs.store`.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ccjax.estimators.base import AbstractEstimator, Status
from ccjax.preprocessing import DEFAULT_DARK, Preprocessing
from ccjax.runs.images import ImageRun, run_models
from ccjax.runs.sources import ImageFolder, image_folder
from ccjax.world import World


@dataclass
class ImageResults:
    """Estimates of several methods over a list of images, with timings and failures.

    Attributes:
        paths: the images that were estimated, in order (unreadable ones are in ``failures``).
        estimates: ``{method: (N, 3)}`` illuminant RGB (unit scale of each image).
        ok: ``{method: (N,)}`` False where the method fell back or relaxed its constraints.
        truth: ``(N, 3)`` ground truth of ``paths`` when known.
        status: ``{method: (N,)}`` :class:`ccjax.estimators.base.Status` codes (why not ok).
        seconds: ``{method: s}`` time spent estimating, warm-up compilation excluded.
        warmup: ``{method: s}`` compilation (the first call per input shape, timed apart).
        preprocessing: ``{method: name}`` the input each method got (:func:`ccjax.preprocessing.resolve`).
        preparation: ``{preprocessing name: s}`` time spent preparing inputs (shared by the
            methods that get the same input), and ``"read"``: decoding the files.
        failures: ``{path: reason}`` images that could not be used (``keep_going``).
    """

    paths: list[str]
    estimates: dict[str, np.ndarray]
    ok: dict[str, np.ndarray]
    truth: np.ndarray | None = None
    status: dict[str, np.ndarray] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)
    warmup: dict[str, float] = field(default_factory=dict)
    preprocessing: dict[str, str] = field(default_factory=dict)
    preparation: dict[str, float] = field(default_factory=dict)
    failures: dict[str, str] = field(default_factory=dict)

    @classmethod
    def from_run(cls, run: ImageRun, truth: np.ndarray | None = None) -> ImageResults:
        """The results of the images a run estimated (:class:`ccjax.runs.images.ImageRun`).

        Arguments:
            run: the run.
            truth: optional ground truth of each item run, ``(N, 3)``.

        Returns:
            The :class:`ImageResults` (failed items left out, their reasons in ``failures``).
        """
        good = np.flatnonzero(run.done)
        return cls(
            paths=[run.paths[i] for i in good],
            estimates={label: values[good] for label, values in run.estimates.items()},
            ok={label: values[good] for label, values in run.ok.items()},
            truth=None if truth is None else np.asarray(truth)[good],
            status={label: values[good] for label, values in run.status.items()},
            seconds=dict(run.seconds),
            warmup=dict(run.warmup),
            preprocessing=dict(run.preprocessing),
            preparation=dict(run.preparation),
            failures=dict(run.failures),
        )

    def angular(self, method: str) -> np.ndarray:
        """The angular errors of one method against the ground truth.

        Arguments:
            method: a method of these results.

        Returns:
            ``(N,)`` the errors in degrees, one per image.
        """
        from ccjax.metrics import angular_error

        return np.asarray(
            angular_error(jnp.asarray(self.estimates[method]), jnp.asarray(self.truth, jnp.float32)), np.float64
        )

    def status_counts(self, method: str) -> dict[str, int]:
        """How many images got each :class:`~ccjax.estimators.base.Status` other than ``ESTIMATED``.

        Arguments:
            method: a method of these results.

        Returns:
            ``{"relaxed": n, "no_data": n, "empty_set": n}``, zero counts left out.
        """
        codes = self.status.get(method)
        if codes is None:  # results built without status codes: only ok is known
            return {"not_ok": int(np.sum(~self.ok[method]))} if not np.all(self.ok[method]) else {}
        counts = {}
        for status in Status:
            number = int(np.sum(codes == status.value))
            if status is not Status.ESTIMATED and number:
                counts[status.name.lower()] = number
        return counts

    def summary(self, method: str, *, seed: int = 0) -> dict:
        """One method's summary.

        Arguments:
            method: a method of these results.
            seed: seed of the bootstrap intervals.

        Returns:
            The field's statistics of the angular error (:func:`ccjax.metrics.error_statistics`:
            mean, median, trimean, best/worst 25 %, 95th percentile, max, bootstrap 95 % intervals
            of mean and median), the not-ok share, the status counts, seconds and warm-up seconds.
        """
        from ccjax.metrics import error_statistics

        row: dict = error_statistics(self.angular(method), seed=seed) if len(self.paths) else {}
        row["not_ok"] = float(1.0 - np.mean(self.ok[method])) if len(self.paths) else 0.0
        row["status"] = self.status_counts(method)
        row["preprocessing"] = self.preprocessing.get(method)
        row["seconds"] = self.seconds.get(method)
        row["warmup_seconds"] = self.warmup.get(method)
        return row

    def table(self) -> str:
        """The results as text, for pasting into a report.

        Returns:
            Angular error statistics (degrees) per method, then each method's input, time and
            fallbacks.
        """
        width = max([24, *(len(method) + 2 for method in self.estimates)])
        header = (
            f"{'method':<{width}}{'mean':>8}{'median':>8}{'trimean':>9}{'best25':>8}{'worst25':>9}{'p95':>8}"
            f"{'max':>8}{'mean 95% CI':>18}{'median 95% CI':>18}"
        )
        lines = [f"angular error (degrees) over {len(self.paths)} images", header]
        summaries = {method: self.summary(method) for method in self.estimates}
        for method, row in summaries.items():
            if not len(self.paths):
                continue
            lines.append(
                f"{method:<{width}}{row['mean']:8.3f}{row['median']:8.3f}{row['trimean']:9.3f}{row['best25']:8.3f}"
                f"{row['worst25']:9.3f}{row['p95']:8.3f}{row['max']:8.3f}"
                + "".join(
                    f"{row[f'{name}_low']:.3f}-{row[f'{name}_high']:.3f}".rjust(18) for name in ("mean", "median")
                )
            )
        lines += ["", f"{'method':<{width}}{'input':<14}{'seconds':>9}{'ms/image':>10}{'warm-up s':>11}  not ok (why)"]
        for method, row in summaries.items():
            seconds, warm = row["seconds"] or 0.0, row["warmup_seconds"] or 0.0
            per_image = 1000 * seconds / max(len(self.paths), 1)
            reasons = ", ".join(f"{name.replace('_', ' ')} {count}" for name, count in row["status"].items())
            count = int(np.sum(~self.ok[method]))
            lines.append(
                f"{method:<{width}}{row['preprocessing'] or '-':<14}{seconds:9.2f}{per_image:10.2f}{warm:11.2f}  "
                f"{count} ({100 * row['not_ok']:.1f}%)" + (f": {reasons}" if reasons else "")
            )
        if self.preparation:
            parts = ", ".join(f"{name} {seconds:.2f} s" for name, seconds in self.preparation.items())
            lines.append(f"input preparation (shared between methods): {parts}")
        return "\n".join(lines)

    def records(self) -> list[dict]:
        """The results as records.

        Returns:
            One dict per image and method (path, method, illuminant with its largest channel 1, rg, ok,
            status, angular error).
        """
        from ccjax._colour import rg_numpy, unit_light

        rows = []
        for method, estimates in self.estimates.items():
            errors = self.angular(method) if self.truth is not None else [None] * len(self.paths)
            codes = self.status.get(method)
            for index, (path, rgb, ok, error) in enumerate(zip(self.paths, estimates, self.ok[method], errors)):
                status = Status(int(codes[index])).name.lower() if codes is not None else None
                rows.append(
                    {
                        "path": path,
                        "method": method,
                        "illuminant": unit_light([float(v) for v in rgb]),
                        "rg": [float(v) for v in rg_numpy(np.asarray(rgb, np.float64))],
                        "ok": bool(ok),
                        **({} if status is None else {"status": status}),
                        **({} if error is None else {"angular": float(error)}),
                    }
                )
        return rows


def run_images(
    paths: Iterable[str | os.PathLike],
    models: Mapping[str, list[AbstractEstimator]],
    *,
    fold_of: np.ndarray | None = None,
    preprocessing: str | Preprocessing | None = None,
    dark: float = DEFAULT_DARK,
    read_options: dict | None = None,
    masks: Sequence[str | os.PathLike | None] | None = None,
    progress: bool = False,
    truth: np.ndarray | None = None,
    keep_going: bool = False,
) -> ImageResults:
    """Read each image once and run every method on it, each on its own kind of input
    (:func:`ccjax.runs.images.run_models` over the files).

    Arguments:
        paths: image files.
        models: ``{label: [model]}``, or one model per fold (``[model_fold0, model_fold1, ...]``).
        fold_of: ``(N,)`` fold of each image (selects its model); ``None``: fold 0.
        preprocessing: a preprocessing name for every method; None: each method's default.
        dark: the dark rule of the surface-list preprocessing (:func:`ccjax.preprocessing.usable_pixels`).
        read_options: keyword arguments of :func:`ccjax.io.read_image`.
        masks: optional mask file per image (``None`` entries: no mask; :func:`ccjax.io.read_mask`).
        progress: show a progress bar on stderr.
        truth: optional ``(N, 3)`` ground truth, stored in the result (rows of the images used).
        keep_going: record an image that cannot be read or prepared in ``failures`` (with the
            reason) and go on; otherwise the error is raised.

    Returns:
        :class:`ImageResults`.
    """
    paths = list(paths)
    if paths:
        source = image_folder(paths, masks=masks, read_options=read_options, keep_going=keep_going)
    else:
        source = ImageFolder([], read_options=dict(read_options or {}))
    run = run_models(
        source,
        models,
        fold_of=fold_of,
        preprocessing=preprocessing,
        dark=dark,
        progress=progress,
        keep_going=keep_going,
    )
    return ImageResults.from_run(run, truth)


def fold_worlds(
    world: World, truth: np.ndarray, folds: int, fold_of: np.ndarray | None = None
) -> tuple[np.ndarray, list[World]]:
    """Worlds for K-fold cross-validation of trained methods on an image set.

    Image ``i`` is in fold ``fold_of[i]`` (default ``i mod K``). The world of fold ``k`` keeps
    everything but its training illuminants, which become the lights of the *other* folds' ground
    truths: each ground-truth RGB is matched to the world illuminant (training or test set) of
    nearest (r,g) chromaticity, so the methods that learn from the expected lights (AVE-ILLUM, the
    illumination constraint of ECRULE, Colour by Correlation, the nets) learn those of the data set
    without seeing the held-out fold.

    Arguments:
        world: the world whose illuminants are matched.
        truth: ``(N, 3)`` ground-truth camera RGB, any scale.
        folds: ``K``, from 2 to ``N``.
        fold_of: ``(N,)`` the fold of each image, integers in ``[0, K)`` with every fold used (such
            as a data set's published split); ``None``: image ``i`` in fold ``i mod K``.

    Returns:
        ``(fold of each image (N,), [world_0, ..., world_{K-1}])``.
    """
    from ccjax._colour import rg_numpy

    truth = np.asarray(truth, np.float64)
    if not isinstance(folds, int) or not 2 <= folds <= len(truth):
        raise ValueError(f"folds: expected an integer in [2, {len(truth)}] (number of images), got {folds!r}")
    pool = np.concatenate([np.asarray(world.train_illuminants), np.asarray(world.test_illuminants)])
    pool_rg = rg_numpy(pool @ np.asarray(world.camera.sensors, np.float64))
    nearest = np.argmin(((rg_numpy(np.asarray(truth, np.float64))[:, None, :] - pool_rg[None]) ** 2).sum(-1), axis=1)
    if fold_of is None:
        fold_of = np.arange(len(truth)) % folds
    else:
        fold_of = np.asarray(fold_of)
        if fold_of.shape != (len(truth),) or not np.issubdtype(fold_of.dtype, np.integer):
            raise ValueError(f"fold_of: expected {len(truth)} integer folds (one per image), got {fold_of.shape}")
        if set(fold_of.tolist()) != set(range(folds)):
            raise ValueError(f"fold_of: expected every fold 0..{folds - 1} used, got {sorted(set(fold_of.tolist()))}")
    worlds = []
    for fold in range(folds):
        chosen = np.unique(nearest[fold_of != fold])
        spectra = jnp.asarray(pool[chosen], world.train_illuminants.dtype)
        worlds.append(eqx.tree_at(lambda w: w.train_illuminants, world, spectra))
    return fold_of, worlds
