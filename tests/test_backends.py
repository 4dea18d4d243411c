"""Shapes per backend (ccjax.backends) and the compile log of ``ccjax compare``
(ccjax.runs.CompileLog)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import pytest

from ccjax import backends
from ccjax.runs import CompileLog, engine

GIB = 1 << 30


def test_cpu_shapes_are_the_cache_sized_ones():
    assert backends.block_scenes("cpu") == 128
    assert backends.device_memory("cpu") is None
    assert backends.chunk_slots("cpu") == 1 << 22
    assert backends.chunk_items("cpu") == 16384
    # The engine's default chunks on this (CPU) machine: 4M slots, at most 16,384 scenes.
    assert engine.chunking(100_000, 8) == (16384, 7)
    assert engine.chunking(100_000, 1024) == (4096, 25)


@pytest.mark.parametrize(
    "memory,block",
    [
        (None, 16384),  # unknown memory: the largest block
        (140 * GIB, 16384),  # an H200: capped
        (16 * GIB, 4096),  # a quarter of 16 GiB at 1 MiB per scene
        (GIB // 4, 128),  # never below the CPU's block
    ],
)
def test_accelerator_blocks_follow_device_memory(monkeypatch, memory, block):
    monkeypatch.setattr(backends, "device_memory", lambda backend=None: memory)
    assert backends.block_scenes("gpu") == block


def test_accelerator_chunks_follow_device_memory(monkeypatch):
    monkeypatch.setattr(backends, "device_memory", lambda backend=None: 80 * GIB)
    assert backends.chunk_slots("gpu") == 80 * GIB // 8 // 24
    monkeypatch.setattr(backends, "device_memory", lambda backend=None: GIB // 4)
    assert backends.chunk_slots("gpu") == 1 << 22  # never below the CPU's
    assert backends.chunk_items("gpu") == 1 << 20


def test_compile_log_counts_programs_and_their_time():
    def fresh(x):  # a function never compiled before in this process
        return jnp.sin(x) * 3.25 + jnp.cos(x[::-1])

    x, y = jax.block_until_ready((jnp.arange(17.0), jnp.arange(18.0)))
    with CompileLog() as log:
        jax.block_until_ready(jax.jit(fresh)(x))
        jax.block_until_ready(jax.jit(fresh)(x))  # the same program: no new one
    assert log.programs == 1
    assert 0 <= log.cache_hits <= 1
    assert 0 < log.seconds() < 60
    before = log.programs
    jax.block_until_ready(jax.jit(fresh)(y))  # closed: not counted
    assert log.programs == before


def test_compile_log_time_is_the_union_of_spans():
    log = CompileLog(spans=[(0.0, 2.0), (1.0, 3.0), (5.0, 6.0), (5.5, 5.7)])
    assert log.seconds() == pytest.approx(4.0)  # [0, 3] and [5, 6]
    assert log.seconds(since=2.5) == pytest.approx(1.5)  # [2.5, 3] and [5, 6]
    assert CompileLog().seconds() == 0.0
