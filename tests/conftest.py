"""Shared fixtures and the suite's strict settings.

The suite is stricter than the library: jaxtyping runtime checks with beartype on every ``ccjax``
module (``--jaxtyping-packages`` in pyproject's ``addopts``; pytest's jaxtyping plugin installs the
import hook before this file imports ccjax), strict dtype promotion (below) and warnings as errors
(pyproject's ``filterwarnings``, with the named exceptions). External-data tests skip when
../shared/data is missing, except under CI=true, where a missing data directory is a failure."""

from __future__ import annotations

import os

import jax
import pytest

# The suite checks numbers, not speed, and most of its time is XLA compiling programs that it runs
# once, on small batches: they are compiled with LLVM's cheapest optimisation level and without its
# expensive passes (the same XLA program, less machine-code optimisation; a result may differ from
# the default build's in its last float bits, inside every tolerance the tests allow for float32
# rounding). Measured on 2 cores, the gamut, engine and scene tests: 222 s at XLA's defaults, 135 s
# at level 0, 120 s with both. Set before the XLA backend starts (at its first use: importing JAX does
# not start it); a flag already in XLA_FLAGS is kept. The command tests' subprocesses inherit them.
for _flag, _value in (("xla_backend_optimization_level", "0"), ("xla_llvm_disable_expensive_passes", "true")):
    if _flag not in os.environ.get("XLA_FLAGS", ""):
        os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} --{_flag}={_value}".strip()

# An implicit promotion (int -> float, float32 -> float64) inside ccjax is a bug: it hides a dtype
# the code did not choose, and under x64 it silently changes precision. Set before ccjax is used.
jax.config.update("jax_numpy_dtype_promotion", "strict")

from ccjax import data  # noqa: E402  (after the promotion setting, which must precede any use)
from ccjax.world import World  # noqa: E402


def require_external_data() -> None:
    """Skip (or fail under CI=true) when the external data directory cannot be found."""
    try:
        data.find_data_file("sfu_barnard/sony_dxc930_380-780-4nm.csv")
    except data.DataNotFoundError as error:
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(f"external data missing under CI: {error}")
        pytest.skip(str(error))


@pytest.fixture(scope="session")
def barnard_world() -> World:
    """The thesis world (external data). Only tests marked ``external_data`` may use it: they
    compare with thesis numbers; oracle, property and gradient tests use ``default_world``."""
    require_external_data()
    return World.barnard1999()


@pytest.fixture(scope="session")
def default_world() -> World:
    return World.default()


@pytest.fixture(scope="session")
def small_test_world() -> World:
    """The small synthetic world of ``tests/small_world.py`` (fast fits), shared by the command tests."""
    from small_world import small_world

    return small_world()


@pytest.fixture
def small_world_commands(tmp_path, monkeypatch, small_test_world):
    """Every command on the small world, with a private cache in ``tmp_path`` (returned)."""
    from ccjax.runs import store

    monkeypatch.setenv("CCJAX_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(store, "world", lambda *a, **k: small_test_world)
    return tmp_path


def pytest_runtest_setup(item):
    # Tests marked external_data skip with the reason when the external data is absent (fail under
    # CI=true). A setup hook, not a fixture mark added at collection: pytest has resolved each
    # test's fixtures before ``pytest_collection_modifyitems`` runs, so such a mark is ignored.
    if item.get_closest_marker("external_data") is not None:
        require_external_data()


def pytest_configure(config):
    # A run started in the background of a non-interactive shell (`pytest &`, nohup) inherits
    # SIGINT ignored, and an ignored signal stays ignored across exec: the commands the Ctrl-C
    # tests start would never see the signal. Restore what a terminal user has (in the main
    # thread only: Python allows signal handlers nowhere else).
    import signal
    import threading

    if signal.getsignal(signal.SIGINT) == signal.SIG_IGN and threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.default_int_handler)

    # Share compiled XLA programs between the xdist workers and between tests of one run: most of
    # the suite's time is compilation, and many tests compile the same sweep shapes.
    import tempfile

    import jax

    cache = os.environ.get("CCJAX_TEST_JAX_CACHE") or os.path.join(tempfile.gettempdir(), "ccjax-test-jax-cache")
    jax.config.update("jax_compilation_cache_dir", cache)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)


@pytest.fixture
def plain_preview_commands(small_world_commands, monkeypatch):
    """:func:`small_world_commands` with the identity preview matrix (no colour-science fit)."""
    import numpy as np

    import ccjax.io

    monkeypatch.setattr(ccjax.io, "preview_matrix_cached", lambda w: np.eye(3, dtype=np.float32))
    return small_world_commands
