"""The image loop: a set of fitted models (optionally one per fold) run over an image source.

:func:`run_models` is the one loop where fitted models meet photographs (``ccjax estimate``,
``correct`` and ``evaluate`` and their Python calls go through it). Each image is read once and
each model gets its own input (:func:`ccjax.preprocessing.prepare`), prepared once per input rule
and shared between the models with that rule. Compilation is timed apart from estimation and
left out of the progress bar's rate. The results are plain arrays indexed by the items run, so
a caller can run a share of a source's items and gather the shares.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np

from ccjax.estimators.base import AbstractEstimator, Estimate
from ccjax.io.reading import LinearImage
from ccjax.preprocessing import DEFAULT_DARK, Preprocessing, input_shapes, run_model
from ccjax.runs import hosts
from ccjax.runs.pooled import ImageSource
from ccjax.runs.sources import check_preprocessing, input_rules


@dataclass
class ImageRun:
    """Estimates of several models over items of an image source.

    Attributes:
        paths: the file of each item run, in order (``N`` items).
        items: ``(N,)`` the items' indices in the source.
        done: ``(N,)`` True where the image was read, prepared and estimated.
        estimates: ``{label: (N, 3)}`` illuminant RGB (unit scale of each image; zeros where not done).
        ok: ``{label: (N,)}`` False where the model fell back or relaxed its constraints.
        status: ``{label: (N,)}`` :class:`ccjax.estimators.base.Status` codes (why not ok).
        failures: ``{path: failure record}`` of the items not done, in item order.
        seconds: ``{label: s}`` time spent estimating, compilation excluded.
        warmup: ``{label: s}`` compilation (the first call per input shape, timed apart).
        preprocessing: ``{label: name}`` the input each model got.
        preparation: ``{rule name: s}`` time spent preparing inputs (shared by the models that
            get the same input), and ``"read"``: decoding the files.
    """

    paths: list[str]
    items: np.ndarray
    done: np.ndarray
    estimates: dict[str, np.ndarray]
    ok: dict[str, np.ndarray]
    status: dict[str, np.ndarray]
    failures: dict[str, str] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)
    warmup: dict[str, float] = field(default_factory=dict)
    preprocessing: dict[str, str] = field(default_factory=dict)
    preparation: dict[str, float] = field(default_factory=dict)

    def records(self) -> list[dict]:
        """One record per estimated image and model, models first (path, method, illuminant with its
        largest channel 1 as in every output of ccjax, rg, ok, status).

        Returns:
            A list of dicts.
        """
        from ccjax._colour import rg_numpy, unit_light
        from ccjax.estimators.base import Status

        rows = []
        for label, estimates in self.estimates.items():
            for index in np.flatnonzero(self.done):
                rgb = estimates[index]
                rows.append(
                    {
                        "path": self.paths[index],
                        "method": label,
                        "illuminant": unit_light([float(v) for v in rgb]),
                        "rg": [float(v) for v in rg_numpy(np.asarray(rgb, np.float64))],
                        "ok": bool(self.ok[label][index]),
                        "status": Status(int(self.status[label][index])).name.lower(),
                    }
                )
        return rows


def _leave_out(bar, seconds: float) -> None:
    """Leave ``seconds`` (warm-up compilation) out of a tqdm bar's rate and ETA: the clock that
    the bar's rate is measured from moves forward by that much (what ``tqdm.unpause`` does)."""
    if not bar.disable:
        bar.start_t += seconds
        bar.last_print_t += seconds


def _count(bar, total: int) -> None:
    """Count one image as done, after its work (and its line, if any) is written: the bar shows
    the images done, and its last state, N of N, is drawn once, when it closes (drawn also here it
    showed twice)."""
    bar.n += 1
    if bar.n < total:
        bar.refresh()


def _timed(model, rgb, mask) -> tuple[Estimate, float]:
    start = time.perf_counter()
    result = run_model(model, rgb, mask)
    jax.block_until_ready(result)
    return result, time.perf_counter() - start


def run_models(
    source: ImageSource,
    models: Mapping[str, Sequence[AbstractEstimator]],
    *,
    items: Sequence[int] | np.ndarray | None = None,
    fold_of: Sequence[int] | np.ndarray | None = None,
    preprocessing: str | Preprocessing | None = None,
    dark: float = DEFAULT_DARK,
    progress: bool = False,
    keep_going: bool = True,
    each: Callable[[int, LinearImage, dict[str, Estimate]], None] | None = None,
    share: bool = True,
) -> ImageRun:
    """Run every model on every item of ``source``, each on its own kind of input.

    Each model gets the input :func:`ccjax.preprocessing.prepare` gives it: its own default
    (``pixels`` for the statistics methods, ``ave5`` for the world-based ones) or ``preprocessing``
    for all; models that get the same input share it (prepared once per image).

    Compilation is kept out of the timings and of the progress bar's rate: before the bar starts,
    every model is compiled for every image size the headers announce (the models that get the
    image); surface lists, whose padded length depends on the content, are compiled when a size
    class first appears, and that call is timed as warm-up, apart from the run.

    Arguments:
        source: the images (:func:`ccjax.runs.sources.image_folder`).
        models: ``{label: [model]}``, or one model per fold (``[model_fold0, model_fold1, ...]``).
        items: the source's items to run, in order (default: every file).
        fold_of: the fold of each of the source's files (selects its model; indexed like
            ``source.paths``); None: fold 0.
        preprocessing: a preprocessing for every model; None: each model's default.
        dark: the dark rule of the surface-list preprocessing (:func:`ccjax.preprocessing.usable_pixels`).
        progress: show a progress bar on stderr.
        keep_going: record an item that cannot be read or prepared in ``failures`` and go on;
            otherwise its error is raised.
        each: called after each estimated item with ``(index in source, image, {label: Estimate})``
            (e.g. to write a corrected image before the next one is read).
        share: under ``jax.distributed`` (several processes), each process reads and estimates
            only its :func:`~ccjax.runs.hosts.process_share` of the items and the per-item results
            and failure records are pooled (:func:`~ccjax.runs.hosts.gather`), so every process
            returns the whole run; ``each`` is called for this process's items only. False: this
            process runs every item given.

    Returns:
        :class:`ImageRun`.
    """
    from tqdm.auto import tqdm

    check_preprocessing(preprocessing)
    chosen = np.arange(len(source)) if items is None else np.asarray(items, np.int64).reshape(-1)
    # Under jax.distributed each process reads only its share of the files; the per-item results
    # are pooled at the end, so every process returns the whole run.
    pooled = share and jax.process_count() > 1
    every = chosen
    if pooled:
        chosen = every[hosts.process_share(len(every))]
    first = {label: fold_models[0] for label, fold_models in models.items()}
    keys, rules = input_rules(first, preprocessing)

    # Warm-up for image inputs: their shapes are in the headers.
    warmup = dict.fromkeys(models, 0.0)
    compiled: set[tuple] = set()
    sizes = source.image_sizes(chosen.tolist())
    for label, fold_models in models.items():
        for fold, model in enumerate(fold_models):
            for size in sizes:
                for rgb_shape, mask_shape in input_shapes(model, size, preprocessing):
                    if len(rgb_shape) == 3:
                        # Sizes from headers that passed the pixel budget: the largest allocation
                        # here is the largest image the run processes, and it is freed at once.
                        zeros = jnp.zeros(rgb_shape, jnp.float32), jnp.zeros(mask_shape, bool)
                        warmup[label] += _timed(model, *zeros)[1]
                        del zeros
                        compiled.add((label, fold, rgb_shape))

    count = len(chosen)
    done = np.zeros(count, bool)
    estimates = {label: np.zeros((count, 3), np.float32) for label in models}
    ok = {label: np.zeros(count, bool) for label in models}
    status = {label: np.zeros(count, np.int32) for label in models}
    seconds = dict.fromkeys(models, 0.0)
    preparation = {"read": 0.0} | dict.fromkeys(rules, 0.0)
    failures: dict[str, str] = {}
    bar = tqdm(total=count, desc="images", unit="image", disable=not progress, file=sys.stderr)
    for position, item in enumerate(source.prepared(rules, chosen.tolist(), dark=dark)):
        if item.failure is not None:
            if not keep_going and item.error is not None:
                raise item.error
            failures[str(item.path)] = item.failure
            _count(bar, count)
            continue
        preparation["read"] += item.read_seconds
        for name, spent in item.prepare_seconds.items():
            preparation[name] += spent
        # device_put, not jnp.asarray: on the CPU backend an aliased NumPy image is copied again
        # (a second image-sized transient) when a compiled model first reads it.
        inputs = {name: jax.device_put((rgb, valid)) for name, (rgb, valid) in item.inputs.items()}
        # Only the inputs stay in memory while the models run (the image too for ``each``).
        image = item.image if each is not None else None
        item.image, item.inputs = None, {}
        fold = 0 if fold_of is None else int(fold_of[item.index])
        results = {}
        for label, fold_models in models.items():
            rgb, valid = inputs[keys[label]]
            if (label, fold, rgb.shape) not in compiled:
                # First call at this shape: compilation, timed apart and left out of the bar.
                compile_seconds = _timed(fold_models[fold], rgb, valid)[1]
                warmup[label] += compile_seconds
                _leave_out(bar, compile_seconds)
                compiled.add((label, fold, rgb.shape))
            result, spent = _timed(fold_models[fold], rgb, valid)
            seconds[label] += spent
            estimates[label][position] = np.asarray(result.illuminant)
            ok[label][position] = bool(result.ok)
            status[label][position] = int(result.status)
            results[label] = result
        # The models' inputs go before ``each`` runs: it may need the memory (a corrected copy).
        del inputs, rgb, valid
        done[position] = True
        if each is not None:
            assert image is not None
            each(item.index, image, results)
        _count(bar, count)
    bar.close()
    if pooled:
        done, estimates, ok, status, failures = _pool(source, every, done, estimates, ok, status, failures)
        chosen = every
    return ImageRun(
        paths=[str(source.paths[index]) for index in chosen],
        items=chosen,
        done=done,
        estimates=estimates,
        ok=ok,
        status=status,
        failures=failures,
        seconds=seconds,
        warmup=warmup,
        preprocessing={label: rules[key].name for label, key in keys.items()},
        preparation=preparation,
    )


FAILURE_BYTES = 1024
"""Longest failure record pooled between processes (longer ones are cut, with an ellipsis)."""


def _pool(source: ImageSource, every: np.ndarray, done, estimates, ok, status, failures):
    """Every process's per-item results and failure records, in item order (``hosts.gather``)."""
    local = every[hosts.process_share(len(every))]
    records = np.zeros((len(local), FAILURE_BYTES), np.uint8)
    for row, index in enumerate(local):
        text = failures.get(str(source.paths[index]))
        if text is not None:
            blob = text.encode()
            if len(blob) > FAILURE_BYTES:
                blob = blob[: FAILURE_BYTES - 3] + b"..."
            records[row, : len(blob)] = np.frombuffer(blob, np.uint8)
    pooled = hosts.gather({"done": done, "estimates": estimates, "ok": ok, "status": status, "records": records})
    texts = {}
    for index, record in zip(every, pooled["records"], strict=True):
        blob = bytes(record).rstrip(b"\0")
        if blob:
            texts[str(source.paths[index])] = blob.decode(errors="replace")
    return pooled["done"], pooled["estimates"], pooled["ok"], pooled["status"], texts
