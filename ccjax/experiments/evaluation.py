"""Evaluating estimators on a folder of images with ground truth (Barnard 1999 §4.6, ch. 5).

:func:`run_images` reads each image once and runs every method on it (the preprocessing is shared
between the surface-list methods); :func:`fold_worlds` builds the worlds of a K-fold
cross-validation whose trained methods learn the lights of the other folds' ground truth.
:func:`cached_world` gives the worlds the command line uses, stored on disk as arrays (no pickle);
fitted models come from :func:`ccjax.estimators.registry.fit_cached` (once per process; the
expensive fits keep their own arrays on disk).
"""

from __future__ import annotations

import hashlib
import os
import sys
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ccjax._cache import cached_arrays, content_key
from ccjax.camera import Camera
from ccjax.estimators.base import AbstractEstimator
from ccjax.io.reading import read_image
from ccjax.preprocessing import DEFAULT_DARK, DEFAULT_PREPROCESSING, Preprocessing, run_model, surfaces
from ccjax.world import World

_WORLD_ARRAYS = ("reflectances", "train_illuminants", "test_illuminants", "canonical")


def _source_fingerprint() -> str:
    """Hash of the package's source: a code change rebuilds every cached world."""
    digest = hashlib.sha256()
    for source in sorted(Path(__file__).parents[1].rglob("*.py")):
        digest.update(source.read_bytes())
    return digest.hexdigest()


def _world_arrays(world: World) -> dict[str, np.ndarray]:
    if world.camera.linearisation is not None:
        raise ValueError(f"world: {world.name!r} has a camera linearisation, which cannot be stored as arrays")
    arrays = {name: np.asarray(getattr(world, name)) for name in _WORLD_ARRAYS}
    return arrays | {
        "sensors": np.asarray(world.camera.sensors),
        "name": np.array(world.name),
        "camera_name": np.array(world.camera.name),
    }


def _world_from_arrays(arrays: Mapping[str, np.ndarray]) -> World:
    camera = Camera(sensors=jnp.asarray(arrays["sensors"]), name=str(arrays["camera_name"]))
    spectra = {name: jnp.asarray(arrays[name]) for name in _WORLD_ARRAYS}
    return World(**spectra, camera=camera, name=str(arrays["name"]))


def cached_world(
    kind: str = "default", camera: str | None = None, *, seed: int = 0, data_dir: str | os.PathLike | None = None
) -> World:
    """``World.default(camera)`` or ``World.barnard1999()``, built once and then read from disk.

    Arguments:
        kind: ``"default"`` (embedded data) or ``"barnard1999"`` (the thesis world, external data).
        camera: camera of the default world (default: the Canon EOS 5D Mark II).
        seed: seed of the illuminant mixtures.
        data_dir: where the external data lives (``barnard1999``).

    Returns:
        The world; its arrays are stored in the cache (``world/``) as ``.npz``.
    """
    if kind == "barnard1999":
        from ccjax.data import find_data_file

        source = find_data_file("sfu_barnard/sony_dxc930_380-780-4nm.csv", data_dir)
        parts, build = (kind, str(source), seed), lambda: World.barnard1999(data_dir, seed=seed)
    elif kind == "default":
        name = camera or "Canon EOS 5D Mark II"
        parts, build = (kind, name, seed), lambda: World.default(name, seed=seed)
    else:
        raise ValueError(f"world: expected 'default' or 'barnard1999', got {kind!r}")
    key = content_key("world", _source_fingerprint(), *parts)
    arrays = cached_arrays("world", key, lambda: _world_arrays(build()), {"world": list(parts)})
    return _world_from_arrays(arrays)


@dataclass
class ImageResults:
    """Estimates of several methods over a list of images.

    Attributes:
        paths: the image files, in order.
        estimates: ``{method: (N, 3)}`` illuminant RGB (unit scale of each image).
        ok: ``{method: (N,)}`` False where the method fell back or relaxed its constraints.
        truth: ``(N, 3)`` ground truth when known.
    """

    paths: list[str]
    estimates: dict[str, np.ndarray]
    ok: dict[str, np.ndarray]
    truth: np.ndarray | None = None

    def angular(self, method: str) -> np.ndarray:
        """``(N,)`` angular errors (degrees) of ``method`` against the ground truth."""
        from ccjax.metrics import angular_error

        return np.asarray(
            angular_error(jnp.asarray(self.estimates[method]), jnp.asarray(self.truth, jnp.float32)), np.float64
        )

    def summary(self, method: str) -> dict[str, float]:
        """Mean, median, trimean, best/worst 25 %, max of the angular error, and the not-ok share."""
        from ccjax.metrics import summarise

        errors = self.angular(method)
        row = {name: summarise(errors, name) for name in ("mean", "median", "trimean", "best25", "worst25", "max")}
        row["not_ok"] = float(1.0 - np.mean(self.ok[method]))
        return row

    def table(self) -> str:
        """Angular error (degrees) per method, one line each."""
        header = (
            f"{'method':<24}{'mean':>8}{'median':>8}{'trimean':>9}{'best25':>8}{'worst25':>9}{'max':>8}{'not ok':>9}"
        )
        lines = [f"angular error (degrees) over {len(self.paths)} images", header]
        for method in self.estimates:
            row = self.summary(method)
            lines.append(
                f"{method:<24}{row['mean']:8.3f}{row['median']:8.3f}{row['trimean']:9.3f}{row['best25']:8.3f}"
                f"{row['worst25']:9.3f}{row['max']:8.3f}{100 * row['not_ok']:8.1f}%"
            )
        return "\n".join(lines)

    def records(self) -> list[dict]:
        """One record per image and method (path, method, illuminant, rg, ok, angular error)."""
        from ccjax.spectra import chromaticity

        rows = []
        for method, estimates in self.estimates.items():
            errors = self.angular(method) if self.truth is not None else [None] * len(self.paths)
            for path, rgb, ok, error in zip(self.paths, estimates, self.ok[method], errors):
                rows.append(
                    {
                        "path": path,
                        "method": method,
                        "illuminant": [float(v) for v in rgb],
                        "rg": [float(v) for v in chromaticity(np.asarray(rgb, np.float64))],
                        "ok": bool(ok),
                        **({} if error is None else {"angular": float(error)}),
                    }
                )
        return rows


def run_images(
    paths: Iterable[str | os.PathLike],
    models: Mapping[str, list[AbstractEstimator]],
    *,
    fold_of: np.ndarray | None = None,
    preprocessing: str | Preprocessing = DEFAULT_PREPROCESSING,
    dark: float = DEFAULT_DARK,
    read_options: dict | None = None,
    progress: bool = False,
    truth: np.ndarray | None = None,
) -> ImageResults:
    """Read each image once and run every method on it (preprocessing shared between methods).

    Arguments:
        paths: image files.
        models: ``{label: [model]}``, or one model per fold (``[model_fold0, model_fold1, ...]``).
        fold_of: ``(N,)`` fold of each image (selects its model); ``None``: fold 0.
        preprocessing, dark: see :func:`ccjax.preprocessing.surfaces`.
        read_options: keyword arguments of :func:`ccjax.io.read_image`.
        progress: show a progress bar on stderr.
        truth: optional ``(N, 3)`` ground truth, stored in the result.

    Returns:
        :class:`ImageResults`.
    """
    from tqdm.auto import tqdm

    paths = [Path(p) for p in paths]
    method = Preprocessing.parse(preprocessing) if isinstance(preprocessing, str) else preprocessing
    estimates = {label: np.zeros((len(paths), 3), np.float32) for label in models}
    ok = {label: np.zeros(len(paths), bool) for label in models}
    for index, path in enumerate(tqdm(paths, desc="images", unit="image", disable=not progress, file=sys.stderr)):
        image = read_image(path, **(read_options or {}))
        surface_input = None
        for label, fold_models in models.items():
            model = fold_models[0 if fold_of is None else int(fold_of[index])]
            if model.input_kind == "image":
                rgb, mask = image.rgb, ~image.clipped
            else:
                if surface_input is None:
                    surface_input = surfaces(image, method, dark=dark)
                rgb, mask = surface_input
            result = run_model(model, jnp.asarray(rgb), jnp.asarray(mask))
            estimates[label][index] = np.asarray(result.illuminant)
            ok[label][index] = bool(result.ok)
    return ImageResults(paths=[str(p) for p in paths], estimates=estimates, ok=ok, truth=truth)


def fold_worlds(world: World, truth: np.ndarray, folds: int) -> tuple[np.ndarray, list[World]]:
    """Worlds for K-fold cross-validation of trained methods on an image set.

    Image ``i`` is in fold ``i mod K``. The world of fold ``k`` keeps everything but its training
    illuminants, which become the lights of the *other* folds' ground truths: each ground-truth RGB
    is matched to the world illuminant (training or test set) of nearest (r,g) chromaticity, so the
    methods that learn from the expected lights (AVE-ILLUM, the illumination constraint of ECRULE,
    Colour by Correlation, the nets) learn those of the data set without seeing the held-out fold.

    Arguments:
        world: the world whose illuminants are matched.
        truth: ``(N, 3)`` ground-truth camera RGB, any scale.
        folds: ``K``, from 2 to ``N``.

    Returns:
        ``(fold of each image (N,), [world_0, ..., world_{K-1}])``.
    """
    from ccjax.spectra import chromaticity

    truth = np.asarray(truth, np.float64)
    if not isinstance(folds, int) or not 2 <= folds <= len(truth):
        raise ValueError(f"folds: expected an integer in [2, {len(truth)}] (number of images), got {folds!r}")
    pool = np.concatenate([np.asarray(world.train_illuminants), np.asarray(world.test_illuminants)])
    pool_rg = chromaticity(pool @ np.asarray(world.camera.sensors, np.float64))
    nearest = np.argmin(((chromaticity(truth)[:, None, :] - pool_rg[None]) ** 2).sum(-1), axis=1)
    fold_of = np.arange(len(truth)) % folds
    worlds = []
    for fold in range(folds):
        chosen = np.unique(nearest[fold_of != fold])
        spectra = jnp.asarray(pool[chosen], world.train_illuminants.dtype)
        worlds.append(eqx.tree_at(lambda w: w.train_illuminants, world, spectra))
    return fold_of, worlds
