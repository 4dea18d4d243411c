"""Fit-time helpers of the Colour by Correlation family: the on-disk cache of slow fits (DESIGN.md
§2), option checks and defaults."""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ccjax.scenes import Specular
from ccjax.world import World

_CACHE_VERSION = 2  # bump when a cached computation changes
DEFAULT_SOFTNESS = 0.1
"""Soft binning scale in bins: weights move from one bin to the next over about +-0.3 bins."""
DEFAULT_TEMPERATURE = 0.05
"""Soft MAP: softmax of the log-posterior divided by this (-> MAP as it -> 0)."""


def _cache_dir() -> Path:
    root = os.environ.get("CCJAX_CACHE")
    if root:
        return Path(root)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "ccjax"


def _world_digest(world: World) -> str:
    digest = hashlib.sha256()
    for array in (
        world.reflectances,
        world.train_illuminants,
        world.test_illuminants,
        world.canonical,
        world.camera.sensors,
    ):
        values = np.ascontiguousarray(np.asarray(array, np.float32))
        digest.update(str(values.shape).encode())
        digest.update(values.tobytes())
    return digest.hexdigest()


def cached(kind: str, world: World, options: dict, compute) -> dict[str, np.ndarray]:
    """Load ``compute()``'s arrays for (``kind``, world, options) from the cache, else compute and
    store them (``$CCJAX_CACHE``, else ``$XDG_CACHE_HOME/ccjax`` or ``~/.cache/ccjax``)."""
    text = json.dumps({"kind": kind, "version": _CACHE_VERSION, "options": options}, sort_keys=True, default=str)
    key = hashlib.sha256((text + _world_digest(world)).encode()).hexdigest()[:20]
    path = _cache_dir() / f"correlation-{kind}-{key}.npz"
    if path.exists():
        try:
            with np.load(path) as stored:
                return {name: stored[name] for name in stored.files}
        except (OSError, ValueError):
            pass  # a damaged entry is recomputed and replaced
    arrays = compute()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path.parent, suffix=".npz", delete=False) as handle:
            np.savez(handle, **arrays)
        os.replace(handle.name, path)
    except OSError:
        pass  # an unwritable cache only costs time
    return arrays


def illuminant_rg_of(world: World) -> Float[Array, "I 2"]:
    whites = np.asarray(world.train_illuminants, np.float64) @ np.asarray(world.camera.sensors, np.float64)
    return jnp.asarray(whites[:, :2] / whites.sum(axis=1, keepdims=True), jnp.float32)


def resolve_specular(specular) -> Specular | None:
    if specular is True:
        return Specular()
    if specular in (None, False):
        return None
    if not isinstance(specular, Specular):
        raise ValueError(f"specular: expected True, False, None or a Specular, got {specular!r}")
    return specular


def check_positive(name: str, value, *, allow_zero: bool = False) -> float:
    if not isinstance(value, (int, float)) or not (value >= 0 if allow_zero else value > 0):
        raise ValueError(f"{name}: expected a {'non-negative' if allow_zero else 'positive'} number, got {value!r}")
    return float(value)
