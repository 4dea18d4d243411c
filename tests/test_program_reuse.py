"""Programs are keyed by what they compute (``ccjax.runs.engine``): sweeps of different method
lists in one process compile each model's estimate program once per batch shape, whatever the
other methods beside it, and nothing at all for a list of models already seen."""

from __future__ import annotations

import jax

from ccjax import experiments
from ccjax.runs import CompileLog, store

SWEEPS = (
    ("GW", "DB-GW", "RETINEX"),
    ("GW", "RETINEX", "shades-of-grey-p6"),
    ("GW", "C-by-C-MMSE"),
    ("DB-GW", "GW"),
)
"""Four method lists sharing models in other company and order (cheap models: no size branch)."""

SURFACES = (4, 8)
"""Two counts drawn by one sampler 8 slots wide (the 4-surface stream reads 4 of them): two batch
shapes, so a model's programs are two."""


def test_four_sweeps_compile_no_program_twice(default_world):
    for label in {label for methods in SWEEPS for label in methods}:
        store.fit(label, default_world)  # fits are not the subject: done before the compile log
    key = jax.random.key(54)
    seen: set[str] = set()
    for index, methods in enumerate(SWEEPS):
        new = [label for label in methods if label not in seen]
        with CompileLog() as log:
            result = experiments.sweep(default_world, list(methods), SURFACES, 56, key, progress=False)
        assert set(result.errors) == set(methods)
        if index:
            # One estimate program per new model and batch shape; the sampler and the statistics
            # were compiled by the first sweep, the other models' programs by the sweeps before.
            assert log.programs <= len(SURFACES) * len(new), (methods, new, log.programs)
        seen.update(methods)
    # The same lists again: nothing left to compile.
    with CompileLog() as log:
        for methods in SWEEPS:
            experiments.sweep(default_world, list(methods), SURFACES, 56, key, progress=False)
    assert log.programs == 0


def test_the_process_keeps_a_bounded_number_of_programs(default_world, monkeypatch):
    # Kept to two programs (a model's estimate program and the shared statistics program): a
    # second model's program pushes the least recently used one out instead of growing the table.
    from ccjax.runs import engine

    monkeypatch.setattr(engine, "PROGRAMS_KEPT", 2)
    key = jax.random.key(55)
    for label in ("GW", "RETINEX", "DB-GW"):
        store.fit(label, default_world)
        experiments.sweep(default_world, [label], (4,), 56, key, progress=False)
        assert engine.held_programs() <= 2, label
    with CompileLog() as log:  # the last model and the statistics: still held, nothing to build
        experiments.sweep(default_world, ["DB-GW"], (4,), 56, key, progress=False)
    assert log.programs == 0
