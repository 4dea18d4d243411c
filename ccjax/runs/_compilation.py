"""How many programs a run compiled and how long that took, from JAX's monitoring events.

Every program JAX runs is traced to a jaxpr, lowered to a module and compiled by XLA or loaded from
the persistent compilation cache (``ccjax._cache.enable_compilation_cache``); JAX reports each of
those steps as a duration event (``/jax/core/compile/...``) and each cache hit as an event.
:class:`CompileLog` listens to them while it is open, so a command can print the number of
programs it compiled and the seconds that went into compiling, apart from running.
"""

from __future__ import annotations

import dataclasses
import threading
import time

import jax

__all__ = ["BACKEND_COMPILE", "CACHE_HIT", "COMPILE_STEPS", "CompileLog"]

BACKEND_COMPILE = "/jax/core/compile/backend_compile_duration"
"""One program compiled by XLA or loaded from the persistent cache (its duration)."""

COMPILE_STEPS = (
    "/jax/core/compile/jaxpr_trace_duration",
    "/jax/core/compile/jaxpr_to_mlir_module_duration",
    BACKEND_COMPILE,
)
"""The steps from a Python function to a loaded executable."""

CACHE_HIT = "/jax/compilation_cache/cache_hits"
"""A program read from the persistent compilation cache instead of compiled."""


@dataclasses.dataclass
class CompileLog:
    """Programs and compile time while open (``with CompileLog() as log: ...``).

    Attributes:
        programs: executables built (compiled by XLA or loaded from the persistent cache).
        cache_hits: of those, the ones loaded from the persistent cache.
        spans: ``(start, end)`` ``time.perf_counter`` seconds of every compile step.
    """

    programs: int = 0
    cache_hits: int = 0
    spans: list[tuple[float, float]] = dataclasses.field(default_factory=list)
    _lock: threading.Lock = dataclasses.field(default_factory=threading.Lock, repr=False)

    @property
    def compiled(self) -> int:
        """Programs XLA compiled (not read from the persistent cache)."""
        return self.programs - self.cache_hits

    def seconds(self, since: float = float("-inf")) -> float:
        """Time spent compiling: the union of the steps' spans (a jit traced inside another one's
        trace, and programs compiled by several threads at once, count once).

        Arguments:
            since: a ``time.perf_counter()`` reading; only the time after it counts.

        Returns:
            Wall-clock seconds after ``since`` during which some program was being traced, lowered
            or compiled.
        """
        with self._lock:
            spans = sorted((max(start, since), end) for start, end in self.spans if end > since)
        total, reach = 0.0, float("-inf")
        for start, end in spans:
            if end > reach:
                total += end - max(start, reach)
                reach = end
        return total

    def _duration(self, event: str, duration_secs: float, **kwargs: str | int) -> None:
        if event in COMPILE_STEPS:
            end = time.perf_counter()  # the event is recorded as its step ends
            with self._lock:
                self.spans.append((end - duration_secs, end))
                self.programs += event == BACKEND_COMPILE

    def _event(self, event: str, **kwargs: str | int) -> None:
        if event == CACHE_HIT:
            with self._lock:
                self.cache_hits += 1

    def __enter__(self) -> CompileLog:
        jax.monitoring.register_event_duration_secs_listener(self._duration)
        jax.monitoring.register_event_listener(self._event)
        return self

    def __exit__(self, *_) -> None:
        jax.monitoring.unregister_event_duration_listener(self._duration)
        jax.monitoring.unregister_event_listener(self._event)
