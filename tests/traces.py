"""Counting a jitted function's traces from JAX's log (``Finished tracing NAME for jit``, logged
at DEBUG unless ``jax_log_compiles``): for library functions a test cannot put a counter into."""

from __future__ import annotations

import logging

LOGGER = "jax._src.dispatch"


def count_traces(caplog, name: str) -> int:
    """Traces of the jitted function ``name`` in ``caplog``'s records (call
    ``caplog.set_level(logging.DEBUG, logger=LOGGER)`` first)."""
    return sum(record.getMessage().startswith(f"Finished tracing {name} for jit") for record in caplog.records)


def record_traces(caplog) -> None:
    """Make ``caplog`` record JAX's trace log."""
    caplog.set_level(logging.DEBUG, logger=LOGGER)
