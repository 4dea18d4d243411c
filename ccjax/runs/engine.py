"""The engine: fitted models run on streams of equal-shaped chunks of items, per-item errors out.

A run is a list of :class:`Stream` s, each a number of items cut into chunks of one shape (so a
program compiles once per shape, and memory stays bounded whatever the number of items). Every
chunk is placed on the devices by a :class:`Placement` (one device, or the item axis sharded over
a ``jax.sharding.Mesh``), every model's estimate program (:func:`estimate_scenes`) and the
shared statistics program (:func:`scene_statistics`) run on it (together they give
:func:`scene_errors`), and the per-item errors and statuses come back to the host, trimmed to the
stream's items and to the statistics that apply to the model (:func:`applicable`). Programs are
keyed by what they compute and kept for the process, and are traced and compiled on two worker
threads ahead of the chunks that need them (:func:`run_streams`).
"""

from __future__ import annotations

import collections
import concurrent.futures
import math
import threading
from collections.abc import Callable, Hashable, Sequence
from dataclasses import dataclass

import equinox as eqx
import jax
import numpy as np
from jaxtyping import Array, Bool, Float
from tqdm.auto import tqdm

from ccjax import backends, metrics
from ccjax.estimators.base import AbstractEstimator, estimate_batch
from ccjax.runs import hosts
from ccjax.scenes import Scenes

STATISTICS = ("angular", "rg", "rgb", "brightness", "map_rg", "map_rgb")
"""Per-scene error measures (Barnard 1999 §4.2): angle (degrees), (r,g) distance, RGB distance,
signed R+G+B difference, scene mapping RMS (r,g) and RGB errors; RGB-valued ones on the unit scale."""

RGB_VALUED = ("rgb", "brightness", "map_rgb")
"""Statistics on the RGB scale: they apply only to methods estimating the light's brightness (3-D
methods), and are multiplied by the thesis' white = 255 when compared with its tables."""


def scene_errors(model: AbstractEstimator, scenes: Scenes, canonical_white: Float[Array, " 3"]) -> dict[str, jax.Array]:
    """Per-scene errors of one model on a scene batch (Barnard 1999 §4.2), plus ``ok`` and ``status``.

    Arguments:
        model: a surface estimator.
        scenes: a :class:`ccjax.scenes.Scenes` batch.
        canonical_white: the canonical light's camera RGB.

    Returns:
        :data:`STATISTICS` names -> ``(B,)`` errors, ``"ok"`` and ``"status"`` (the
        :class:`~ccjax.estimators.base.Status` codes).
    """
    estimate = estimate_batch(model, scenes.rgb, scenes.mask)
    return {**_statistics(estimate.illuminant, scenes, canonical_white), "ok": estimate.ok, "status": estimate.status}


def _statistics(e: Float[Array, "B 3"], scenes: Scenes, canonical_white: Float[Array, " 3"]) -> dict[str, jax.Array]:
    """The :data:`STATISTICS` of the estimates ``e`` of a batch's lights."""
    truth = scenes.illuminant
    map_rg, map_rgb = metrics.mapping_errors(e, scenes.rgb, scenes.mask, scenes.canonical_rgb, canonical_white)
    return {
        "angular": metrics.angular_error(e, truth),
        "rg": metrics.rg_error(e, truth),
        "rgb": metrics.rgb_error(e, truth),
        "brightness": metrics.brightness_error(e, truth),
        "map_rg": map_rg,
        "map_rgb": map_rgb,
    }


def _narrowed(scenes: Scenes, slots: int | None) -> Scenes:
    """``scenes`` with only their first ``slots`` surface slots (``None``: all of them)."""
    if slots is None:
        return scenes
    return Scenes(
        rgb=scenes.rgb[:, :slots],
        mask=scenes.mask[:, :slots],
        illuminant=scenes.illuminant,
        canonical_rgb=scenes.canonical_rgb[:, :slots],
    )


def estimate_scenes(
    model: AbstractEstimator,
    rgb: Float[Array, "B P 3"],
    mask: Bool[Array, "B P"],
    slots: int | None = None,
    sharding: jax.sharding.Sharding | None = None,
) -> tuple[jax.Array, jax.Array, jax.Array]:
    """One model's estimates of a batch's lights: the engine's estimate program, one per model
    and batch shape whatever other models a run holds.

    Arguments:
        model: a surface estimator.
        rgb: ``(B, P, 3)`` surface RGBs.
        mask: ``(B, P)``, True where a surface is valid.
        slots: the model reads the first ``slots`` surface slots (static; ``None``: all of them),
            so batches drawn wider than a stream's padded size serve it.
        sharding: where the results live (static; ``None``: where XLA puts them), so that the
            statistics program compiled for that placement takes them as they are.

    Returns:
        ``(illuminant (B, 3) in the dtype of rgb, ok (B,), status (B,))``.
    """
    if slots is not None:
        rgb, mask = rgb[:, :slots], mask[:, :slots]
    estimate = estimate_batch(model, rgb, mask)
    out = (estimate.illuminant.astype(rgb.dtype), estimate.ok, estimate.status)
    if sharding is not None:
        out = jax.lax.with_sharding_constraint(out, sharding)
    return out


def scene_statistics(
    illuminant: Float[Array, "B 3"], scenes: Scenes, canonical_white: Float[Array, " 3"], slots: int | None = None
) -> dict[str, jax.Array]:
    """The :data:`STATISTICS` of estimates of a batch's lights: the engine's statistics program,
    one per batch shape shared by every model.

    Arguments:
        illuminant: ``(B, 3)`` estimates (:func:`estimate_scenes`).
        scenes: the :class:`ccjax.scenes.Scenes` batch they estimate.
        canonical_white: the canonical light's camera RGB.
        slots: the mapping errors read the first ``slots`` surface slots (static; ``None``: all).

    Returns:
        :data:`STATISTICS` names -> ``(B,)`` errors, as :func:`scene_errors` gives them.
    """
    return _statistics(illuminant, _narrowed(scenes, slots), canonical_white)


def applicable(model: AbstractEstimator, errors: dict) -> dict:
    """``errors`` without the statistics that do not apply to ``model``: the RGB-valued ones
    (:data:`RGB_VALUED`) unless it estimates the light's brightness.

    Arguments:
        model: the estimator the errors are of.
        errors: statistic name -> values (as :func:`scene_errors` returns them).

    Returns:
        A new dict, in the order of ``errors``.
    """
    return {name: value for name, value in errors.items() if model.estimates_brightness or name not in RGB_VALUED}


_estimate_program = eqx.filter_jit(estimate_scenes)
_statistics_program = eqx.filter_jit(scene_statistics)


class Placement:
    """Where the item axis of a chunk lives: the default device, or sharded over the one axis of a
    ``jax.sharding.Mesh`` (several devices; under ``jax.distributed`` several processes).

    The engine puts every chunk's inputs through :meth:`place` and brings every result back
    through :meth:`fetch`, the two points where items cross between host and devices (where a
    run over several processes exchanges its shares).

    Arguments:
        mesh: optional ``jax.sharding.Mesh`` with one axis (a ValueError otherwise).

    Attributes:
        sharding: the ``NamedSharding`` of the item axis, or ``None`` on one device.
        n_devices: devices the item axis is split over (chunks are a multiple of it).
    """

    def __init__(self, mesh: jax.sharding.Mesh | None = None):
        self.mesh = mesh
        self.sharding = None
        self.n_devices = 1
        self.spans_processes = False
        if mesh is not None:
            if len(mesh.axis_names) != 1:
                raise ValueError(f"mesh: expected one axis, got {mesh.axis_names}")
            self.sharding = hosts.item_sharding(mesh)
            self.n_devices = int(mesh.devices.size)
            self.spans_processes = len({device.process_index for device in mesh.devices.flat}) > 1

    def place(self, items):
        """``items`` (leading axis: the items) on the devices.

        Arguments:
            items: an array or PyTree of arrays.

        Returns:
            The same, sharded along the item axis when there is a mesh.
        """
        if self.mesh is None:
            return items
        if self.spans_processes:
            # Every process derives the whole chunk (keys are cheap) and contributes its own block
            # of rows: the chunk is a multiple of the device count, so the blocks are equal.
            count = jax.tree.leaves(items)[0].shape[0]
            share = hosts.process_share(count)
            items = jax.tree.map(lambda leaf: leaf[share], items)
        return hosts.shard_items(items, self.mesh)

    def fetch(self, tree):
        """A PyTree of device arrays as NumPy arrays on the host.

        Arguments:
            tree: results of a chunk.

        Returns:
            The same tree of NumPy arrays.
        """
        return jax.device_get(tree) if self.mesh is None else hosts.global_value(tree)


def chunking(n_items: int, item_size: int, requested: int | None = None, n_devices: int = 1) -> tuple[int, int]:
    """Items per chunk and number of chunks for ``n_items`` items of ``item_size`` slots each.

    Arguments:
        n_items: items in the stream.
        item_size: slots per item (a scene's padded number of surfaces).
        requested: items per chunk (default: about :func:`ccjax.backends.chunk_slots` slots,
            between 64 and :func:`ccjax.backends.chunk_items` items: on CPU 4M slots, arrays
            near 100 MB, and at most 16,384 items; on an accelerator by its memory).
        n_devices: the chunk is rounded up to a multiple of it (an equal share per device).

    Returns:
        ``(size, n_chunks)``: every chunk has ``size`` items (the last one is filled with items
        beyond the stream's end and trimmed).
    """
    size = requested or max(64, min(backends.chunk_items(), backends.chunk_slots() // max(item_size, 1)))
    size = min(size, n_items)
    size = int(math.ceil(size / n_devices) * n_devices)
    return size, int(math.ceil(n_items / size))


@dataclass(frozen=True, eq=False)
class Stream:
    """Items of one kind cut into equal chunks, and the models to run on them.

    Attributes:
        n_items: items in the stream (results are trimmed to them).
        size: items per chunk.
        make: chunk index -> the chunk's batch (a :class:`~ccjax.scenes.Scenes` of ``size`` items),
            placed on the devices.
        maker: a key of the program ``make`` runs: streams with equal keys share it (it is
            compiled once, ahead, by making the first chunk of the first of them).
        shape: a key of the batch's shapes and dtypes within a run: streams with equal keys (and
            equal ``slots``) are compiled for once (the programs themselves are keyed by the
            batch's actual shapes and dtypes, across runs).
        positions: indices of the models to run.
        canonical_white: the canonical light's camera RGB (mapping errors).
        slots: the models read the first ``slots`` surface slots of each item (``None``: all), so
            one maker drawing wide batches serves streams padded to several sizes.
    """

    n_items: int
    size: int
    make: Callable[[int], Scenes]
    maker: Hashable
    shape: Hashable
    positions: tuple[int, ...]
    canonical_white: Float[Array, " 3"]
    slots: int | None = None

    @property
    def n_chunks(self) -> int:
        """Chunks in the stream."""
        return -(-self.n_items // self.size)


@dataclass(frozen=True)
class _Aval:
    """An array leaf of a program key: what a compiled program is specialised on."""

    shape: tuple[int, ...]
    dtype: str
    weak_type: bool


def _signature(tree) -> Hashable:
    """What ``eqx.filter_jit`` keys a program on: the PyTree structure (with the models' static
    fields), the non-array leaves, and the arrays' shapes and dtypes (where they are placed is
    the run's :class:`Placement`, part of the key beside this)."""
    leaves, treedef = jax.tree.flatten(tree)

    def leaf_key(leaf):
        if not eqx.is_array(leaf):
            return leaf
        return _Aval(tuple(leaf.shape), str(leaf.dtype), bool(getattr(leaf, "weak_type", False)))

    return treedef, tuple(leaf_key(leaf) for leaf in leaves)


PROGRAMS_KEPT = 128
"""How many compiled programs a process keeps: a long session (a notebook sweeping many shapes,
the test suite) would otherwise hold every executable it ever built; the least recently used
finished program goes first, and the persistent compilation cache still serves it again."""

_PROGRAMS: collections.OrderedDict[Hashable, concurrent.futures.Future] = collections.OrderedDict()
"""The compiled programs of this process (estimate and statistics), by :func:`_signature` of
their arguments, least recently used first: a run reuses what any earlier run in the process
compiled."""

_PROGRAMS_LOCK = threading.Lock()


def _compiled(key: Hashable, build: Callable[[], Callable]) -> Callable:
    """The program of ``key`` from the process's programs, else built (once: a second thread
    asking for it meanwhile waits for the first one's)."""
    with _PROGRAMS_LOCK:
        future = _PROGRAMS.get(key)
        owner = future is None
        if owner:
            future = _PROGRAMS[key] = concurrent.futures.Future()
            _forget_oldest()
        else:
            _PROGRAMS.move_to_end(key)
    assert future is not None
    if owner:
        try:
            future.set_result(build())
        except BaseException as error:
            with _PROGRAMS_LOCK:
                del _PROGRAMS[key]  # not kept: a later run tries again
            future.set_exception(error)
            raise
    return future.result()


def held_programs() -> int:
    """How many compiled programs this process holds (at most :data:`PROGRAMS_KEPT` finished ones,
    plus any being built).

    Returns:
        The number of entries in the process's program table.
    """
    with _PROGRAMS_LOCK:
        return len(_PROGRAMS)


def _forget_oldest() -> None:
    """Drops the least recently used finished programs beyond :data:`PROGRAMS_KEPT` (one still
    being built stays: a thread waits on it). Called with the lock held."""
    excess = len(_PROGRAMS) - PROGRAMS_KEPT
    if excess <= 0:
        return
    for key in [key for key, future in _PROGRAMS.items() if future.done()][:excess]:
        del _PROGRAMS[key]


def compile_order(models: Sequence[AbstractEstimator], positions: Sequence[int]) -> list[int | None]:
    """The order in which a stream's programs are compiled ahead: the estimate programs of the
    models with size branches first (the gamut family: the largest programs, so that one compile
    worker starts on them while the other compiles the rest), then the statistics program
    (``None``), then the other models' estimate programs.

    Arguments:
        models: the fitted models.
        positions: indices into ``models`` (the stream's).

    Returns:
        The positions, every one once, and ``None`` for the statistics program.
    """
    branched = [position for position in positions if models[position].padding.budgets]
    return [*branched, None, *(position for position in positions if not models[position].padding.budgets)]


def run_streams(
    models: Sequence[AbstractEstimator],
    streams: Sequence[Stream],
    placement: Placement,
    *,
    progress: bool = True,
    desc: str = "run",
) -> list[dict[int, dict[str, np.ndarray]]]:
    """Every stream's models on every chunk of the stream: per-item errors and statuses.

    Each model's estimates of a chunk come from its estimate program (:func:`estimate_scenes`,
    one per model and batch shape) and their errors from the statistics program
    (:func:`scene_statistics`, one per batch shape, shared by every model). Programs are keyed by
    what they compute (the model's structure and static fields, the batch's shapes, dtypes and
    placement, the slots read), never by the other models of the run, and kept for the process:
    a later run, whatever its list of models, compiles only the programs no run has compiled.

    Two worker threads trace and compile, in the order they are first needed (:func:`compile_order`)
    and each once, the streams' makers and the programs, while this thread runs those already
    compiled (XLA compiles and runs without holding the GIL), so compiling overlaps running. The
    workers see ``jax_enable_x64`` as the caller has it; other per-thread JAX settings (a
    ``jax.default_device`` context) are not passed on: set those globally. An error raised while
    compiling reaches the caller as itself.

    Arguments:
        models: fitted surface estimators.
        streams: the streams, run in order.
        placement: where the chunks live.
        progress: show a progress bar (one step per chunk).
        desc: the progress bar's label.

    Returns:
        Per stream: model position -> statistic -> ``(n_items,)`` NumPy array (the
        :func:`applicable` :func:`scene_errors`).
    """
    x64 = bool(jax.config.read("jax_enable_x64"))
    sharding = placement.sharding
    batches: dict[Hashable, Scenes] = {}

    def compile_maker(stream: Stream) -> None:
        with jax.enable_x64(x64):  # the caller's setting (a context is per thread)
            stream.make(0)

    def example(stream: Stream) -> Scenes:
        # On one device, host zeros of the batch's shapes (no program builds them), so that the
        # programs need not wait for the maker; sharded, the first chunk (whose layout the maker
        # decides). Once per maker: its streams' batches are alike.
        if stream.maker not in batches:
            if sharding is None:
                shapes = jax.eval_shape(lambda: stream.make(0))
                batches[stream.maker] = jax.tree.map(lambda leaf: np.zeros(leaf.shape, leaf.dtype), shapes)
            else:
                batches[stream.maker] = stream.make(0)
        return batches[stream.maker]

    def compile_program(position: int | None, stream: Stream):
        with jax.enable_x64(x64):
            batch = example(stream)
            if position is None:
                illuminant = np.zeros((batch.rgb.shape[0], 3), batch.rgb.dtype)
                if sharding is not None:
                    illuminant = placement.place(illuminant)
                args = (illuminant, batch, stream.canonical_white)
                key = ("statistics", _signature(args), stream.slots, sharding, x64)
                return _compiled(key, lambda: _statistics_program.lower(*args, stream.slots).compile())
            args = (models[position], batch.rgb, batch.mask)
            key = ("estimate", _signature(args), stream.slots, sharding, x64)
            return _compiled(key, lambda: _estimate_program.lower(*args, stream.slots, sharding).compile())

    results: list[dict[int, dict[str, np.ndarray]]] = []
    bar = tqdm(
        total=sum(s.n_chunks for s in streams if s.positions),
        desc=desc,
        unit="chunk",
        disable=not progress,
        leave=False,
    )
    compiler = concurrent.futures.ThreadPoolExecutor(max_workers=2, thread_name_prefix="ccjax-compile")
    try:
        makers: dict[Hashable, concurrent.futures.Future] = {}
        programs: dict[tuple, concurrent.futures.Future] = {}
        for stream in streams:
            if stream.positions and stream.maker not in makers:
                makers[stream.maker] = compiler.submit(compile_maker, stream)
        # In the order the streams need them (within a stream, the largest programs first).
        for stream in streams:
            for position in compile_order(models, stream.positions) if stream.positions else ():
                key = (position, stream.shape, stream.slots)
                if key not in programs:
                    programs[key] = compiler.submit(compile_program, position, stream)
        for stream in streams:
            collected: dict[int, list[dict]] = {position: [] for position in stream.positions}
            if stream.positions:
                # Until its programs are compiled a stream's first chunk waits: say so.
                bar.set_postfix_str("compiling")
                makers[stream.maker].result()
                statistics = programs[None, stream.shape, stream.slots]
                for index in range(stream.n_chunks):
                    batch = stream.make(index)
                    chunk = {}
                    for position in stream.positions:
                        estimate = programs[position, stream.shape, stream.slots].result()
                        model = models[position]
                        illuminant, ok, status = estimate(model, batch.rgb, batch.mask, stream.slots, sharding)
                        errors = statistics.result()(illuminant, batch, stream.canonical_white, stream.slots)
                        chunk[position] = {**errors, "ok": ok, "status": status}
                    for position, errors in placement.fetch(chunk).items():
                        collected[position].append(errors)
                    bar.set_postfix_str("", refresh=False)
                    bar.update()
            results.append(
                {
                    position: applicable(
                        models[position],
                        {name: np.concatenate([c[name] for c in chunks])[: stream.n_items] for name in chunks[0]},
                    )
                    for position, chunks in collected.items()
                }
            )
    finally:
        compiler.shutdown(wait=False, cancel_futures=True)
        bar.close()
    return results
