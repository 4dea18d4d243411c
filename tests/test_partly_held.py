"""Cases a reliability probe found partly held, each checked against an independent source: a cache
folder that is a file (one warning per process, results computed), empty programs in JAX's
compilation cache (removed at start-up), grey edge at ``p = 1000`` and on images scaled far from 1
(a float64 NumPy oracle), model files with a fallback light that is not a light (refused at load),
and the rg error of lights at any scale (the closed form in float64)."""

from __future__ import annotations

import math
import os
import subprocess
import sys
import textwrap
import warnings

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import ndimage

from ccjax import _cache, _entries
from ccjax.estimators.spatial import edge_norms, fit_grey_edge
from ccjax.metrics import rg_error
from ccjax.runs import store

# ---------------------------------------------------------------------------------------------
# a cache folder that is a file


def _compute_counter():
    calls = []

    def compute():
        calls.append(1)
        return {"a": np.arange(3.0)}

    return calls, compute


@pytest.mark.parametrize("blocked", ["cache", "kind"])
def test_a_cache_folder_that_is_a_file_warns_once_and_computes(tmp_path, monkeypatch, blocked):
    cache = tmp_path / "cache"
    if blocked == "cache":
        cache.write_text("not a folder")
        blocker = cache
    else:
        cache.mkdir()
        blocker = cache / "things"
        blocker.write_text("not a folder")
    monkeypatch.setenv("CCJAX_CACHE", str(cache))
    calls, compute = _compute_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(2):  # a second pass over the same entries: still no second warning
            for key in ("k1", "k2", "k3"):
                arrays = _entries.cached_arrays("things", key, compute, {"a": _entries.Expect((3,))}, {})
                np.testing.assert_array_equal(arrays["a"], [0.0, 1.0, 2.0])
    assert len(calls) == 6  # run uncached: every request computed
    assert [w.category for w in caught] == [_entries.CacheFolderUnusable]
    message = str(caught[0].message)
    assert str(blocker) in message and "not cached" in message
    assert blocker.read_text() == "not a folder"  # the user's file is left alone


def test_fits_and_worlds_under_a_file_warn_once(tmp_path, monkeypatch, small_test_world):
    blocker = tmp_path / "cache-file"
    blocker.write_text("x")
    monkeypatch.setenv("CCJAX_CACHE", str(blocker))
    store.clear_memory()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for label in ("GW", "MAX-RGB"):
            store.fit(label, small_test_world)
    store.clear_memory()
    assert [w.category for w in caught] == [_entries.CacheFolderUnusable]
    assert str(blocker) in str(caught[0].message)


# ---------------------------------------------------------------------------------------------
# empty programs in JAX's compilation cache


def test_empty_compiled_programs_are_removed_and_nothing_else(tmp_path):
    folder = tmp_path / "xla"
    folder.mkdir()
    files = {
        "jit_f-0a1b-cache": b"",  # what a full disk leaves
        "jit_g-2c3d-cache": b"\x28\xb5\x2f\xfd compiled",
        "jit_f-0a1b-atime": b"\0" * 8,
        ".lockfile": b"",  # JAX's lock: empty by design
        "notes-cache.txt": b"",
    }
    for name, blob in files.items():
        (folder / name).write_bytes(blob)
    (folder / "sub-cache").mkdir()  # a folder is never removed
    removed = _cache.remove_empty_programs(folder)
    assert [path.name for path in removed] == ["jit_f-0a1b-cache"]
    assert sorted(os.listdir(folder)) == sorted(set(files) - {"jit_f-0a1b-cache"} | {"sub-cache"})
    assert _cache.remove_empty_programs(tmp_path / "missing") == []


_RUN = textwrap.dedent(
    """
    import warnings
    warnings.simplefilter("always")
    import jax, jax.numpy as jnp
    from ccjax import _cache
    _cache.enable_compilation_cache()
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0)
    print(float(jax.jit(lambda x: jnp.sin(x) * 3.0 + 1.0)(jnp.float32(0.5))))
    """
)


def test_a_later_run_after_a_full_disk_reads_no_empty_program(tmp_path):
    environment = {**os.environ, "CCJAX_CACHE": str(tmp_path), "JAX_PLATFORMS": "cpu"}
    environment.pop("JAX_COMPILATION_CACHE_DIR", None)

    def run() -> str:
        done = subprocess.run(
            [sys.executable, "-c", _RUN], env=environment, capture_output=True, text=True, timeout=120
        )
        assert done.returncode == 0, done.stderr
        assert math.isclose(float(done.stdout), math.sin(0.5) * 3 + 1, rel_tol=1e-6)
        return done.stderr

    run()
    programs = sorted((tmp_path / "xla").glob("*-cache"))
    assert programs
    for path in programs:  # a full disk: each entry created, none of its bytes written
        path.write_bytes(b"")
    later = run()
    assert "persistent compilation cache" not in later, later
    assert all(path.stat().st_size > 0 for path in (tmp_path / "xla").glob("*-cache"))


# ---------------------------------------------------------------------------------------------
# grey edge at p = 1000 and on images scaled far from 1


def _edges64(image: np.ndarray, order: int, sigma: float) -> np.ndarray:
    """``(N, 3)`` float64 edge magnitudes of every position (module docstring of spatial.py),
    from SciPy's Gaussian derivatives, with a hypot so that no square overflows."""
    planes = []
    for c in range(3):
        f = image[..., c].astype(np.float64)

        def d(oy, ox, f=f):
            # A per-axis order (SciPy accepts a sequence; its stubs say int).
            return ndimage.gaussian_filter(f, sigma, order=[oy, ox], mode="nearest")  # pyright: ignore[reportArgumentType]

        if order == 1:
            planes.append(np.hypot(d(0, 1), d(1, 0)))
        else:
            planes.append(np.hypot(np.hypot(d(0, 2), d(2, 0)), 2.0 * d(1, 1)))
    return np.stack(planes, -1).reshape(-1, 3)


def _minkowski64(values: np.ndarray, p: float) -> np.ndarray:
    """Per channel ``(mean of values^p)^(1/p)``, taken as ``max * (mean of (values/max)^p)^(1/p)``."""
    top = values.max(axis=0)
    return top * np.mean((values / top) ** p, axis=0) ** (1.0 / p)


@pytest.fixture(scope="module")
def textured_image() -> np.ndarray:
    rng = np.random.default_rng(7)
    return rng.uniform(0.05, 0.9, (24, 32, 3)).astype(np.float32) * np.array([1.0, 0.8, 0.6], np.float32)


@pytest.mark.parametrize("order", [1, 2])
def test_grey_edge_at_p_1000_is_the_float64_mean_near_the_edge_max_rgb(small_test_world, textured_image, order):
    mask = np.ones(textured_image.shape[:2], bool)
    model = fit_grey_edge(small_test_world, order=order, p=1000.0, sigma=1.0)
    result = model(jnp.asarray(textured_image), jnp.asarray(mask))
    edges = _edges64(textured_image, order, 1.0)
    want = _minkowski64(edges, 1000.0)
    assert bool(result.ok)
    np.testing.assert_allclose(np.asarray(result.illuminant), want, rtol=2e-3)
    # (mean x^p)^(1/p) lies in [N^(-1/p), 1] times the max: within 1% of the edges' max-RGB here.
    np.testing.assert_allclose(want, edges.max(axis=0), rtol=len(edges) ** (1 / 1000) - 1)


def test_grey_edge_at_p_1000_in_row_tiles_is_the_float64_mean(textured_image):
    # Tiles' sums are combined at the largest tile's scale, each raised to p = 1000.
    mask = np.ones(textured_image.shape[:2], bool)
    tiled, _, _ = edge_norms(jnp.asarray(textured_image), jnp.asarray(mask), 1, 1.0, 1000.0, rows=5)
    np.testing.assert_allclose(np.asarray(tiled), _minkowski64(_edges64(textured_image, 1, 1.0), 1000.0), rtol=2e-3)


@pytest.mark.parametrize("scale", [1e-30, 1e-20, 1e20, 1e25, 1e30])
@pytest.mark.parametrize("p", [6.0, 1000.0])
def test_grey_edge_direction_is_the_same_at_any_scale(small_test_world, textured_image, scale, p):
    mask = np.ones(textured_image.shape[:2], bool)
    model = fit_grey_edge(small_test_world, order=1, p=p, sigma=1.0)
    result = model(jnp.asarray(textured_image * np.float32(scale)), jnp.asarray(mask))
    want = _minkowski64(_edges64(textured_image, 1, 1.0), p)  # the unscaled image's answer
    light = np.asarray(result.illuminant, np.float64)
    assert bool(result.ok) and np.all(np.isfinite(light))
    np.testing.assert_allclose(light / light.sum(), want / want.sum(), rtol=2e-3)
    np.testing.assert_allclose(light / scale, want, rtol=2e-3)


# ---------------------------------------------------------------------------------------------
# model files whose fallback light is not a light


@pytest.mark.parametrize("light", [[-1.0, -1.0, -1.0], [0.0, 0.0, 0.0], [0.5, -0.25, 1.0]])
def test_a_model_file_with_a_bad_fallback_light_is_refused(tmp_path, monkeypatch, small_test_world, light):
    monkeypatch.setenv("CCJAX_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(store, "world", lambda *a, **k: small_test_world)
    model = store.fit("GW", small_test_world)
    bad = eqx.tree_at(lambda m: m.fallback, model, jnp.asarray(light, jnp.float32))
    path = store.save_trained(tmp_path / "gw.eqx", bad, label="GW", camera=None)
    with pytest.raises(ValueError) as caught:
        store.load_model(path)
    message = str(caught.value)
    assert str(path) in message and "\n" not in message
    assert "fallback light must be finite and non-negative with a positive channel" in message


def test_a_model_file_with_a_one_channel_fallback_loads(tmp_path, monkeypatch, small_test_world):
    monkeypatch.setenv("CCJAX_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(store, "world", lambda *a, **k: small_test_world)
    model = store.fit("GW", small_test_world)
    edited = eqx.tree_at(lambda m: m.fallback, model, jnp.asarray([0.0, 0.0, 2.0], jnp.float32))
    loaded = store.load_model(store.save_trained(tmp_path / "gw.eqx", edited, label="GW", camera=None))
    np.testing.assert_array_equal(np.asarray(loaded.fallback), [0.0, 0.0, 2.0])  # pyright: ignore[reportAttributeAccessIssue]


# ---------------------------------------------------------------------------------------------
# rg error at any scale


def _rg_error64(a: np.ndarray, b: np.ndarray) -> float:
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return float(np.hypot(*(a[:2] / a.sum() - b[:2] / b.sum())))


SCALES = [10.0**e for e in range(-30, 31, 5)] + [9e37, 3e38]


@pytest.mark.parametrize("scale", SCALES)
def test_rg_error_of_orthogonal_lights_is_the_same_at_any_scale(scale):
    red, green = np.array([scale, 0, 0], np.float32), np.array([0, scale, 0], np.float32)
    assert math.isclose(float(rg_error(red, green)), math.sqrt(2.0), rel_tol=1e-6)


def test_rg_error_matches_the_closed_form_at_mixed_scales():
    rng = np.random.default_rng(3)
    lights = rng.uniform(0.0, 1.0, (40, 2, 3))
    scales = 10.0 ** rng.uniform(-30, 30, (40, 2, 1))
    scaled = (lights * scales).astype(np.float32)
    got = np.asarray(rg_error(scaled[:, 0], scaled[:, 1]))
    want = [_rg_error64(a, b) for a, b in lights]
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)
