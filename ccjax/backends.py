"""Shapes for the backend: how many scenes a vmapped block and a chunk of a run hold, chosen by
the backend and its device memory (docs/gpu.md: a GPU wants batches of tens of thousands of scenes,
a CPU cache-sized blocks; the same code and the same numbers on both).

* :func:`block_scenes`: scenes per vmapped block of
  :func:`~ccjax.estimators.base.estimate_batch` for the estimators that block their batches
  (the gamut engine's hook); on CPU 128, cache-sized; on an accelerator as many as a share of
  its memory holds, at most :data:`ACCELERATOR_BLOCK`.
* :func:`chunk_slots`, :func:`chunk_items`: the surface slots and the most scenes of one chunk of
  a run (:func:`ccjax.runs.engine.chunking`, used by sweeps and the evaluations); on CPU about
  100 MB of arrays, on an accelerator an eighth of its memory.

Measured on an NVIDIA H200 (``../shared/gpu/README.md``): blocks of 128 scenes left the GPU idle
between tiny launches (CRULE-AVE 43,519 scenes/s at 8 surfaces); blocks of 2,048 and 16,384 gave
375,060 and 413,873.
"""

from __future__ import annotations

import jax

__all__ = [
    "ACCELERATOR_BLOCK",
    "ACCELERATOR_CHUNK_ITEMS",
    "CPU_BLOCK",
    "CPU_CHUNK_ITEMS",
    "CPU_CHUNK_SLOTS",
    "block_scenes",
    "chunk_items",
    "chunk_slots",
    "device_memory",
]

CPU_BLOCK = 128
"""Scenes per block on CPU: measured against 16, 32 and 64 (interleaved runs, median of 9) with
the certified fine stage, 1.1-1.25x faster at 8 and 64 surfaces and equal at 1,024 (the per-block
loops' fixed cost is shared by more scenes); larger blocks stream every stage through memory."""

ACCELERATOR_BLOCK = 16384
"""The most scenes per block on an accelerator (the largest block measured on the H200)."""

BLOCK_BYTES_PER_SCENE = 1 << 20
"""Working memory per scene of a gamut block, a bound: the fine grid's 2,025 directions against
the scene's observations reduced to a fixed budget (at most 48), in float32, with the stages'
temporaries; a block on an accelerator takes at most a quarter of its memory at this rate."""

CPU_CHUNK_SLOTS = 1 << 22
"""Surface slots (scenes x padded size) of one chunk of a run on CPU: its arrays near 100 MB."""

CPU_CHUNK_ITEMS = 16384
"""The most scenes per chunk on CPU."""

ACCELERATOR_CHUNK_ITEMS = 1 << 20
"""The most scenes per chunk on an accelerator."""

CHUNK_BYTES_PER_SLOT = 24
"""Bytes per surface slot of a chunk's arrays (RGB in float32, mask, and the per-scene results)."""


def device_memory(backend: str | None = None) -> int | None:
    """Bytes of memory of the first device of ``backend`` (default: JAX's default backend), or
    ``None`` on CPU or where the runtime does not say.

    Arguments:
        backend: ``"cpu"``, ``"gpu"``, ``"tpu"`` or ``None``.

    Returns:
        The device's memory limit in bytes, or ``None``.
    """
    backend = backend or jax.default_backend()
    if backend == "cpu":
        return None
    stats = jax.devices(backend)[0].memory_stats() or {}
    limit = stats.get("bytes_limit")
    return int(limit) if limit else None


def block_scenes(backend: str) -> int:
    """Scenes per vmapped block on ``backend``.

    Arguments:
        backend: ``"cpu"``, ``"gpu"`` or ``"tpu"``.

    Returns:
        :data:`CPU_BLOCK` on CPU; elsewhere as many scenes as a quarter of the device's memory
        holds at :data:`BLOCK_BYTES_PER_SCENE`, between :data:`CPU_BLOCK` and
        :data:`ACCELERATOR_BLOCK` (the largest when the memory is not known).
    """
    if backend == "cpu":
        return CPU_BLOCK
    memory = device_memory(backend)
    if memory is None:
        return ACCELERATOR_BLOCK
    fits = memory // 4 // BLOCK_BYTES_PER_SCENE
    return int(min(ACCELERATOR_BLOCK, max(CPU_BLOCK, fits)))


def chunk_slots(backend: str | None = None) -> int:
    """Surface slots of one chunk of a run on ``backend`` (default: JAX's default backend).

    Arguments:
        backend: ``"cpu"``, ``"gpu"``, ``"tpu"`` or ``None``.

    Returns:
        :data:`CPU_CHUNK_SLOTS` on CPU (and where the memory is not known); on an accelerator an
        eighth of its memory at :data:`CHUNK_BYTES_PER_SLOT`, at least the CPU's.
    """
    memory = device_memory(backend)
    if memory is None:
        return CPU_CHUNK_SLOTS
    return max(CPU_CHUNK_SLOTS, memory // 8 // CHUNK_BYTES_PER_SLOT)


def chunk_items(backend: str | None = None) -> int:
    """The most scenes of one chunk of a run on ``backend`` (default: JAX's default backend).

    Arguments:
        backend: ``"cpu"``, ``"gpu"``, ``"tpu"`` or ``None``.

    Returns:
        :data:`CPU_CHUNK_ITEMS` on CPU, :data:`ACCELERATOR_CHUNK_ITEMS` elsewhere.
    """
    return CPU_CHUNK_ITEMS if (backend or jax.default_backend()) == "cpu" else ACCELERATOR_CHUNK_ITEMS
