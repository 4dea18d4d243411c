"""Synthetic scene sources and their runs: keys + one scene-options value -> per-scene errors.

A :class:`SyntheticSource` is a sweep key, the surface counts, the scenes per count and one
:class:`~ccjax.scenes.SceneOptions`. The scenes of ``n`` surfaces are the stream
``sweep_keys(key, n, start, count)`` (:func:`ccjax.scenes.sweep_keys`), so sources that differ
only in their options see the same lights and surfaces, and a source's numbers depend neither on
its chunking nor on how the scene axis is sharded. :func:`run_synthetic` cuts every (source,
count) into chunks, pads counts that can share one compiled program (:func:`padded_sizes`, from
the models' :attr:`~ccjax.estimators.base.AbstractEstimator.padding` rules) and runs the engine
(:func:`ccjax.runs.engine.run_streams`), reading and writing each labelled cell in the disk cache
of sweeps when asked.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, Int

from ccjax import limits, scenes
from ccjax._cache import code_fingerprint, content_key
from ccjax._entries import Expect, read_arrays, write_arrays
from ccjax.estimators.base import AbstractEstimator, Padding, Status
from ccjax.estimators.inputs import require_kind
from ccjax.runs.engine import STATISTICS, Placement, Stream, applicable, chunking, run_streams
from ccjax.scenes import SceneOptions, Scenes, SceneTables, require_count
from ccjax.world import World

MAX_PADDING = 2
""":func:`padded_sizes` pads a surface count to at most this factor times itself where the
padded slots cost what real ones do."""

SHARED_SAMPLER_SLOTS = 64
"""Counts padded to at most this many slots are drawn by one sampler program as wide as the
largest of them (drawing a few dozen more surfaces costs far less than compiling a sampler), and
each stream's models read its own padded width of the batch."""


@dataclass(frozen=True, eq=False)
class SyntheticSource:
    """Synthetic scenes: per surface count, ``n_scenes`` scenes of the sweep key's stream, rendered
    with one set of scene options (Barnard 1999 §4.7).

    Attributes:
        key: the sweep key; the scenes of ``n`` surfaces are ``sweep_keys(key, n, 0, n_scenes)``.
        surfaces: surface counts (each at least 1; at most the world's reflectances at run time).
        n_scenes: scenes per count.
        options: the :class:`~ccjax.scenes.SceneOptions`.
        metals: ``(M, 101)`` spectra of the metallic highlights (default: the six metals'
            reflectances, :func:`ccjax.materials.scene_metal_spectra`).
        fluorescent_surfaces: the :class:`~ccjax.scenes.RadianceModel` of the fluorescent
            surfaces (default: their characterisation from the world's lights, as the thesis
            rendered its synthetic fluorescent scenes, §7.3:
            :func:`ccjax.estimators.gamut.characterised_fluorescents`).
    """

    key: jax.Array
    surfaces: tuple[int, ...]
    n_scenes: int
    options: SceneOptions = field(default_factory=SceneOptions)
    metals: Float[ArrayLike, "M 101"] | None = None
    fluorescent_surfaces: scenes.RadianceModel | None = None

    def __post_init__(self):
        counts = tuple(require_count(n, "n_surfaces", 1) for n in self.surfaces)
        if not counts:
            raise ValueError("n_surfaces: expected at least one surface count, got none")
        object.__setattr__(self, "surfaces", counts)
        object.__setattr__(self, "n_scenes", require_count(self.n_scenes, "n_scenes", 1, limits.SCENES))
        if not isinstance(self.options, SceneOptions):
            raise ValueError(f"options: expected a SceneOptions, got {type(self.options).__name__}")


@dataclass
class SyntheticRun:
    """What :func:`run_synthetic` computed.

    Attributes:
        errors: ``errors[source][n][position]`` -> statistic -> ``(n_scenes,)`` NumPy array (the
            applicable :func:`~ccjax.runs.engine.scene_errors` with ``ok`` and ``status``), per
            source index, surface count and model position.
        cells_from_cache: how many (source, count, model) cells were read from the disk cache.
    """

    errors: list[dict[int, list[dict[str, np.ndarray]]]]
    cells_from_cache: int = 0


def padded_sizes(surfaces: Sequence[int], models: Sequence[AbstractEstimator]) -> dict[int, int]:
    """The scene size each surface count is padded to, so that several counts share one compiled
    program (compilation is most of a cold sweep's time) and every estimate stays what it is
    unpadded, up to rounding: a program of another shape can round in the last bit, which MV's
    pattern search can follow to a slightly different point (measured, ND-ECRULE-MV on 1,000
    scenes of 4 surfaces padded to 32: 19 % of scenes differ, by at most 4e-5 in (r,g) error).

    Padding adds masked-out surfaces, which no estimator uses; what could change is a Python
    branch on the scene's size. The models state theirs (:class:`~ccjax.estimators.base.Padding`,
    combined over the models with :meth:`Padding.combine`): counts are grouped between
    consecutive budgets and padded within a group only, so a padded scene takes every branch its
    unpadded self takes. Where every model with budgets reads only a scene's usable observations
    below its smallest budget (``counted_slots``), padding costs almost nothing there and that
    group is padded to its largest count when that count reaches ``counted_slots``; other groups
    are split into buckets spanning at most :data:`MAX_PADDING`, each padded to its largest count.
    Counts above every budget are not padded (the kernel's cost grows with the size). Without a
    model that branches on the size nothing is padded.

    Arguments:
        surfaces: the surface counts.
        models: the fitted models run on them.

    Returns:
        ``count -> padded size`` (``>= count``).
    """
    rule = Padding.combine(model.padding for model in models)
    limits = list(rule.budgets)
    if not limits:
        return {n: n for n in surfaces}
    groups: dict[int, list[int]] = {}
    for n in sorted(set(surfaces)):
        above = [limit for limit in limits if limit >= n]
        groups.setdefault(above[0] if above else -n, []).append(n)
    sizes = {}
    for limit, group in groups.items():
        if rule.counted_slots is not None and limit == limits[0] and group[-1] >= rule.counted_slots:
            sizes.update({n: group[-1] for n in group})
            continue
        bucket: list[int] = []
        for n in group + [0]:
            if bucket and (n == 0 or n > MAX_PADDING * bucket[0]):
                sizes.update({m: bucket[-1] for m in bucket})
                bucket = []
            bucket.append(n)
    return sizes


def scene_tables(
    world: World,
    options: SceneOptions,
    metals: Float[ArrayLike, "M 101"] | None = None,
    fluorescent_surfaces: scenes.RadianceModel | None = None,
) -> SceneTables:
    """The world's scene tables with the material colours ``options`` need.

    Arguments:
        world: the world.
        options: the scene options (metals are built only for metallic highlights, fluorescent
            surfaces only for fluorescent ones).
        metals: as :attr:`SyntheticSource.metals`.
        fluorescent_surfaces: as :attr:`SyntheticSource.fluorescent_surfaces`.

    Returns:
        :class:`~ccjax.scenes.SceneTables`.
    """
    fluorescent = None
    if options.fluorescent is not None:
        if fluorescent_surfaces is None:
            from ccjax.estimators.gamut import characterised_fluorescents

            fluorescent_surfaces = characterised_fluorescents(world)
        fluorescent = fluorescent_surfaces
    return SceneTables.from_world(
        world,
        metals=(True if metals is None else metals) if options.metallic is not None else None,
        fluorescent=fluorescent,
    )


@eqx.filter_jit
def _sample_padded(keys, tables, n_surfaces, slots, options) -> Scenes:
    """Scenes of ``n_surfaces`` surfaces (static) padded with masked-out zeros to ``slots`` (one
    program per count: the sampler of counts padded alike where JAX's threefry is not
    partitionable, so :func:`~ccjax.scenes.sample_batch_slots` cannot share one)."""
    batch = _sample(keys, tables, n_surfaces, options)
    pad = slots - n_surfaces
    return Scenes(
        rgb=jnp.pad(batch.rgb, ((0, 0), (0, pad), (0, 0))),
        mask=jnp.pad(batch.mask, ((0, 0), (0, pad))),
        illuminant=batch.illuminant,
        canonical_rgb=jnp.pad(batch.canonical_rgb, ((0, 0), (0, pad), (0, 0))),
        light=batch.light,
    )


def _sample(keys, tables: SceneTables, n_surfaces: int, options: SceneOptions) -> Scenes:
    return scenes.sample_batch(
        keys, tables, n_surfaces, options.specular, options.noise, options.clip, options.metallic, options.fluorescent
    )


def _sample_slots(
    keys, tables: SceneTables, n_surfaces: int | Int[Array, ""], slots: int, options: SceneOptions
) -> Scenes:
    count = jnp.asarray(n_surfaces, jnp.int32)
    return scenes.sample_batch_slots(
        keys, tables, count, slots, options.specular, options.noise, options.clip, options.metallic, options.fluorescent
    )


def sampler_widths(source: SyntheticSource, sizes: dict[int, int], chunk_sizes: dict[int, int]) -> dict[int, int]:
    """The width each count's batches are drawn at: its padded size, or, for the counts that can
    share one sampler program, the widest of their padded sizes.

    Counts share when their draws are bitwise those of their own width: JAX's threefry is
    partitionable (a wider draw's random bits extend a narrower one's) and the scenes have at most
    one rendering option (:func:`~ccjax.scenes.sample_batch_slots`: with several, another width
    may round their sums otherwise); and when their chunks are equal and their padded sizes at
    most :data:`SHARED_SAMPLER_SLOTS` (so memory and the sampler's work stay those of a small
    scene).

    Arguments:
        source: the source.
        sizes: count -> padded size (:func:`padded_sizes`).
        chunk_sizes: count -> scenes per chunk.

    Returns:
        count -> sampler width (``>= sizes[count]``).
    """
    options = source.options
    n_options = sum(
        value is not None
        for value in (options.specular, options.noise, options.clip, options.metallic, options.fluorescent)
    )
    partitionable = bool(jax.config.jax_threefry_partitionable)  # pyright: ignore[reportAttributeAccessIssue]
    widths = dict(sizes)
    if partitionable and n_options <= 1:
        for chunk in set(chunk_sizes.values()):
            small = [n for n in source.surfaces if chunk_sizes[n] == chunk and sizes[n] <= SHARED_SAMPLER_SLOTS]
            if len(small) > 1:
                widths.update({n: max(sizes[m] for m in small) for n in small})
    return widths


@eqx.filter_jit
def _draw(key, count, start, size: int, tables: SceneTables, slots: int | None, options: SceneOptions) -> Scenes:
    """A chunk's scenes from the sweep key, keys derived in the same program: ``size`` scenes from
    position ``start`` (traced) of the stream of ``count``-surface scenes, drawn as themselves
    (``slots`` None, ``count`` static) or in ``slots`` slots (``count`` traced: one program for
    every count and chunk)."""
    keys = scenes.sweep_keys(key, count, start, size)
    if slots is None:
        return _sample(keys, tables, count, options)
    return _sample_slots(keys, tables, count, slots, options)


def _maker(source: SyntheticSource, tables: SceneTables, n: int, slots: int, shared: bool, size: int, placement):
    """The chunk maker of count ``n`` and the key of its program. A count alone in its sampler
    width is sampled as itself (:func:`~ccjax.scenes.sample_batch`); counts drawn at one width
    share one program of ``slots`` slots (the scenes of :func:`~ccjax.scenes.sample_batch_slots`
    extend a shorter draw's random bits, which needs partitionable threefry; else one program
    each). On one device the keys are derived in the sampler's program; over a mesh they are
    derived first and sharded, and the sampler runs on the shards."""
    options = source.options
    materials = (options.metallic is not None, options.fluorescent is not None)
    partitionable = bool(jax.config.jax_threefry_partitionable)  # pyright: ignore[reportAttributeAccessIssue]
    if shared and not partitionable:
        program = ("padded", n, slots)

        def make(index: int) -> Scenes:
            keys = placement.place(scenes.sweep_keys(source.key, n, index * size, size))
            return _sample_padded(keys, tables, n, slots, options)

    elif placement.mesh is not None:
        program = ("slots", slots) if shared else ("count", n)

        def make(index: int) -> Scenes:
            keys = placement.place(scenes.sweep_keys(source.key, n, index * size, size))
            return _sample_slots(keys, tables, n, slots, options) if shared else _sample(keys, tables, n, options)

    else:
        program = ("drawn", slots) if shared else ("drawn", "count", n)
        # A shared program takes the count as an array (traced); a count of its own is static.
        count = np.int32(n) if shared else n

        def make(index: int) -> Scenes:
            return _draw(source.key, count, np.uint32(index * size), size, tables, slots if shared else None, options)

    return make, (*program, size, options, materials)


_RANGES = {"angular": (0.0, 180.0), "brightness": (-np.inf, np.inf)}
"""Value ranges of the statistics (others are distances, >= 0)."""


def cell_layout(model: AbstractEstimator, n_scenes: int) -> dict[str, Expect]:
    """What a cached cell of ``model``'s per-scene errors must hold (:func:`ccjax._entries.read_arrays`):
    the statistics that apply to it, ``ok`` and ``status``, one value per scene, finite and in range.

    Arguments:
        model: the estimator the errors are of.
        n_scenes: the source's scene count.

    Returns:
        Array name -> :class:`ccjax._entries.Expect`.
    """
    floats = {name: Expect((n_scenes,), "f", *_RANGES.get(name, (0.0, np.inf))) for name in STATISTICS}
    return {
        **applicable(model, floats),
        "ok": Expect((n_scenes,), "b"),
        "status": Expect((n_scenes,), "iu", 0.0, float(max(Status))),
    }


def run_synthetic(
    world: World,
    models: Sequence[AbstractEstimator],
    sources: Sequence[SyntheticSource],
    *,
    labels: Sequence[str | None] | None = None,
    chunk_size: int | None = None,
    mesh: jax.sharding.Mesh | None = None,
    progress: bool = True,
    cache: bool = False,
    desc: str = "scenes",
) -> SyntheticRun:
    """Every model on every source's scenes (Barnard 1999 §4.7): per-scene errors and statuses.

    Arguments:
        world: the world the scenes are drawn from.
        models: fitted surface estimators (image estimators are refused with a ValueError).
        sources: the :class:`SyntheticSource` s.
        labels: per model, its registry label, or ``None``; only labelled models' cells are cached.
        chunk_size: scenes per chunk (default: :func:`~ccjax.runs.engine.chunking`'s), which
            bounds memory whatever the number of scenes.
        mesh: optional ``jax.sharding.Mesh`` with one axis; the scene axis of every chunk is
            sharded over it.
        progress: show a progress bar.
        cache: read and write each labelled (source, count, model) cell's per-scene errors in the
            disk cache of sweeps (``<cache>/sweeps``), keyed by everything they depend on (the
            label, the world, the scene options and their material colours, the key, the count,
            the padded and chunk sizes, ccjax's code, JAX's version and backend), so a repeated
            run computes only the cells it has not seen. Sharded runs are not cached.
        desc: the progress bar's label.

    Returns:
        A :class:`SyntheticRun`.
    """
    labels = list(labels) if labels is not None else [None] * len(models)
    if len(labels) != len(models):
        raise ValueError(f"labels: expected one per model ({len(models)}), got {len(labels)}")
    if not models:
        raise ValueError("models: empty")
    for position, (label, model) in enumerate(zip(labels, models, strict=True)):
        require_kind(model, "surfaces", f"methods: {label!r}" if label is not None else f"models[{position}]")
    n_reflectances = int(world.reflectances.shape[0])
    for source in sources:
        if any(n > n_reflectances for n in source.surfaces):
            raise ValueError(f"n_surfaces: expected integers in [1, {n_reflectances}], got {list(source.surfaces)}")
    placement = Placement(mesh)
    tables: dict[tuple, SceneTables] = {}
    streams: list[Stream] = []
    cells: dict[tuple[int, int, int], dict[str, np.ndarray]] = {}
    cell_keys: dict[tuple[int, int, int], str] = {}
    cell_facts: dict[tuple[int, int, int], dict] = {}
    for index, source in enumerate(sources):
        need = (source.options.metallic is not None, source.options.fluorescent is not None)
        tables_key = (need, id(source.metals), id(source.fluorescent_surfaces))
        if tables_key not in tables:
            tables[tables_key] = scene_tables(world, source.options, source.metals, source.fluorescent_surfaces)
        table = tables[tables_key]
        sizes = padded_sizes(source.surfaces, models)
        chunk_sizes = {n: chunking(source.n_scenes, sizes[n], chunk_size, placement.n_devices)[0] for n in sizes}
        widths = sampler_widths(source, sizes, chunk_sizes)
        for n in source.surfaces:
            size = chunk_sizes[n]
            if cache and mesh is None:
                common = (
                    world,
                    code_fingerprint(),
                    jax.__version__,
                    jax.default_backend(),
                    jax.random.key_data(source.key),
                    source.n_scenes,
                    source.options,
                    table if any(need) else None,
                )
                for position, label in enumerate(labels):
                    if label is not None:
                        cell_key = content_key("sweep", label, n, sizes[n], size, *common)
                        facts = {"label": label, "surfaces": n, "scenes": source.n_scenes, "world": world.name}
                        layout = cell_layout(models[position], source.n_scenes)
                        stored = read_arrays("sweeps", cell_key, layout, facts)
                        cell_facts[index, n, position] = facts
                        if stored is not None:
                            cells[index, n, position] = stored
                        cell_keys[index, n, position] = cell_key
            shared = sum(widths[m] == widths[n] for m in set(source.surfaces)) > 1
            make, maker = _maker(source, table, n, widths[n], shared, size, placement)
            todo = tuple(p for p in range(len(models)) if (index, n, p) not in cells)
            slots = sizes[n] if sizes[n] < widths[n] else None
            streams.append(
                Stream(source.n_scenes, size, make, maker, (widths[n], size), todo, table.canonical_white, slots)
            )
    from_cache = len(cells)
    plan = [(index, n) for index, source in enumerate(sources) for n in source.surfaces]
    computed_streams = run_streams(models, streams, placement, progress=progress, desc=desc)
    for (index, n), computed in zip(plan, computed_streams, strict=True):
        for position, errors in computed.items():
            cells[index, n, position] = errors
            if (index, n, position) in cell_keys:
                write_arrays("sweeps", cell_keys[index, n, position], errors, cell_facts[index, n, position])
    errors = [
        {n: [cells[index, n, p] for p in range(len(models))] for n in source.surfaces}
        for index, source in enumerate(sources)
    ]
    return SyntheticRun(errors=errors, cells_from_cache=from_cache)
