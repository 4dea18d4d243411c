"""Sweeps over synthetic scenes: chunked, optionally sharded, every method on the same scenes.

The protocol is the thesis' (Barnard 1999 §4.7): for each number of surfaces, ``n_scenes`` scenes
under test illuminants, every method run on the same scenes, errors aggregated per scene and then
summarised (RMS is the thesis' aggregate). Scenes come from per-scene keys, so a sweep's numbers do
not depend on its chunk size or on how the scene axis is sharded over devices.
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from tqdm.auto import tqdm

from ccjax import metrics
from ccjax._cache import code_fingerprint, content_key, read_arrays, write_arrays
from ccjax.estimators import base, registry
from ccjax.estimators.base import AbstractEstimator, AbstractImageEstimator, estimate_batch
from ccjax.estimators.gamut.constraints_3d import COUNTED_SLOTS
from ccjax.estimators.gamut.engine import GridOptions
from ccjax.estimators.gamut.model import GamutModel
from ccjax.experiments.reports import Column, Report
from ccjax.runs import store
from ccjax.scenes import Scenes, SceneTables, resolve_options, sample_batch, sample_batch_slots, scene_keys
from ccjax.world import World

STATISTICS = ("angular", "rg", "rgb", "brightness", "map_rg", "map_rgb")
"""Per-scene error measures (Barnard 1999 §4.2): angle (degrees), (r,g) distance, RGB distance,
signed R+G+B difference, scene mapping RMS (r,g) and RGB errors; RGB-valued ones on the unit scale."""

BRIGHTNESS_STATISTICS = ("rgb", "brightness", "map_rgb")
"""Statistics that apply only to methods estimating the light's brightness (3-D methods)."""

RGB_VALUED = ("rgb", "brightness", "map_rgb")
"""Statistics on the RGB scale (multiplied by the thesis' white = 255 when compared with it)."""

STATUS_SUMMARIES = ("relaxed", "fell_back")
"""Per-scene status shares of :meth:`SweepResult.status_fraction`: ``relaxed`` is
:attr:`Status.RELAXED <ccjax.estimators.base.Status>` (the method's answer broke a constraint and
the nearest admissible one is given, e.g. gamut mapping's relaxed constraints, thesis §4.3.2);
``fell_back`` is ``NO_DATA`` or ``EMPTY_SET`` (the model's fallback light is the answer)."""

MAX_PADDING = 2
""":func:`padded_sizes` pads a surface count to at most this factor times itself."""

# Scenes x surfaces per chunk: about 4M surfaces keeps a chunk's arrays near 100 MB.
_SURFACES_PER_CHUNK = 1 << 22


def scene_errors(model: AbstractEstimator, scenes, canonical_white) -> dict[str, jax.Array]:
    """Per-scene errors of one model on a scene batch (Barnard 1999 §4.2), plus ``ok``.

    Arguments:
        model: a surface estimator.
        scenes: a :class:`ccjax.scenes.Scenes` batch.
        canonical_white: the canonical light's camera RGB.

    Returns:
        :data:`STATISTICS` names -> ``(B,)`` errors, ``"ok"`` and ``"status"`` (the
        :class:`~ccjax.estimators.base.Status` codes).
    """
    estimate = estimate_batch(model, scenes.rgb, scenes.mask)
    e, truth = estimate.illuminant, scenes.illuminant
    map_rg, map_rgb = metrics.mapping_errors(e, scenes.rgb, scenes.mask, scenes.canonical_rgb, canonical_white)
    return {
        "angular": metrics.angular_error(e, truth),
        "rg": metrics.rg_error(e, truth),
        "rgb": metrics.rgb_error(e, truth),
        "brightness": metrics.brightness_error(e, truth),
        "map_rg": map_rg,
        "map_rgb": map_rgb,
        "ok": estimate.ok,
        "status": estimate.status,
    }


def sampling_error(errors, summary: str = "rms") -> float:
    """Standard error over scenes of a summary of per-scene errors.

    The scenes of a sweep are independent draws, so a summary (RMS, mean) computed from them has a
    sampling error that shrinks as ``1/sqrt(n)``. For the mean it is ``s / sqrt(n)`` (``s`` the
    sample standard deviation); for the RMS ``R = sqrt(M)``, ``M = mean(e^2)``, it is the delta
    method's ``SE(M) / (2 R)`` with ``SE(M) = sd(e^2) / sqrt(n)``: first order in ``1/sqrt(n)``,
    deterministic (no resampling), and exact enough at the thesis' 1000 scenes per cell.

    Arguments:
        errors: 1-D per-scene errors (finite, at least two).
        summary: ``"rms"`` or ``"mean"``.

    Returns:
        The standard error, in the units of ``errors`` (0 when every error is 0).
    """
    errors = np.asarray(errors, dtype=np.float64).ravel()
    if errors.size < 2:
        raise ValueError(f"errors: expected at least 2 per-scene errors, got {errors.size}")
    if not np.all(np.isfinite(errors)):
        raise ValueError("errors: contains NaN or infinite values")
    n = errors.size
    if summary == "mean":
        return float(np.std(errors, ddof=1) / np.sqrt(n))
    if summary == "rms":
        squares = errors**2
        rms = float(np.sqrt(np.mean(squares)))
        if rms == 0.0:
            return 0.0
        return float(np.std(squares, ddof=1) / np.sqrt(n) / (2.0 * rms))
    raise ValueError(f"summary: the sampling error is defined for 'rms' and 'mean', got {summary!r}")


@eqx.filter_jit
def _padded_sample(keys, tables, n_surfaces, size, specular, noise, clip) -> Scenes:
    """Scenes of ``n_surfaces`` surfaces (static), padded with masked-out surfaces to ``size``
    (one program per count; the sweep's sampler when counts cannot share one)."""
    scenes = sample_batch(keys, tables, n_surfaces, specular, noise, clip)
    pad = size - n_surfaces
    return Scenes(
        rgb=jnp.pad(scenes.rgb, ((0, 0), (0, pad), (0, 0))),
        mask=jnp.pad(scenes.mask, ((0, 0), (0, pad))),
        illuminant=scenes.illuminant,
        canonical_rgb=jnp.pad(scenes.canonical_rgb, ((0, 0), (0, pad), (0, 0))),
    )


@eqx.filter_jit
def _errors(models, scenes, canonical_white):
    return [scene_errors(model, scenes, canonical_white) for model in models]


def _instances(tree, kind: type, found: list) -> list:
    """Every instance of ``kind`` held by a model (static fields included), depth first."""
    if isinstance(tree, kind):
        found.append(tree)
    elif isinstance(tree, eqx.Module):
        for item in dataclasses.fields(tree):
            _instances(getattr(tree, item.name, None), kind, found)
    elif isinstance(tree, (list, tuple)):
        for item in tree:
            _instances(item, kind, found)
    return found


def padded_sizes(surfaces: Sequence[int], models: Sequence[AbstractEstimator]) -> dict[int, int]:
    """The scene size each surface count is padded to, so that several counts share one compiled
    program (compilation is most of a cold sweep's time) and every estimate stays what it is
    unpadded, up to rounding: a program of another shape can round in the last bit, which MV's
    pattern search can follow to a slightly different point (measured, ND-ECRULE-MV on 1,000
    scenes of 4 surfaces padded to 32: 19 % of scenes differ, by at most 4e-5 in (r,g) error).

    Padding adds masked-out surfaces, which no estimator uses; what could change is a Python
    branch on the scene's size. The gamut engine has such branches (at its observation budgets,
    :class:`~ccjax.estimators.gamut.engine.GridOptions`: ``fine_observations``,
    ``locate_observations``, ``large_scene``, ``exact_scene``), so counts are grouped between
    consecutive budgets and padded within a group only: a padded scene takes every branch its
    unpadded self takes. Below the smallest budget the 3-D engine reads only a scene's usable
    observations (:func:`~ccjax.estimators.gamut.constraints_3d.evaluate`, in scenes of at least
    ``COUNTED_SLOTS`` slots), so padding costs it almost nothing and that group is padded to its
    largest count when that count reaches ``COUNTED_SLOTS``; other groups, and every group
    when a sweep holds a grid model that reads every slot (CIP), are split into buckets spanning
    at most :data:`MAX_PADDING`, each padded to its largest count. Counts above every budget are
    not padded (the kernel's cost grows with the size). Without such models nothing is padded.

    Arguments:
        surfaces: the sweep's surface counts.
        models: its fitted models.

    Returns:
        ``count -> padded size`` (``>= count``).
    """
    grids = [options for model in models for options in _instances(model, GridOptions, [])]
    engines = [engine for model in models for engine in _instances(model, GamutModel, [])]
    limits = sorted(
        {
            limit
            for options in grids
            for limit in (
                options.fine_observations,
                options.locate_observations,
                options.large_scene,
                options.exact_scene,
            )
            if limit > 0
        }
    )
    if not limits:
        return {n: n for n in surfaces}
    # Every grid belongs to a 3-D engine (one GridOptions each): the smallest group pads freely.
    counted = len(engines) == len(grids)
    groups: dict[int, list[int]] = {}
    for n in sorted(set(surfaces)):
        above = [limit for limit in limits if limit >= n]
        groups.setdefault(above[0] if above else -n, []).append(n)
    sizes = {}
    for limit, group in groups.items():
        if counted and limit == limits[0] and group[-1] >= COUNTED_SLOTS:
            sizes.update({n: group[-1] for n in group})
            continue
        # A padded scene costs what its padded size costs where every slot is read (the
        # reduction of large scenes, CIP), so a bucket spans at most a factor MAX_PADDING.
        bucket: list[int] = []
        for n in group + [0]:
            if bucket and (n == 0 or n > MAX_PADDING * bucket[0]):
                sizes.update({m: bucket[-1] for m in bucket})
                bucket = []
            bucket.append(n)
    return sizes


@dataclass
class SweepResult:
    """Per-scene errors of a sweep and their summaries.

    Attributes:
        methods: labels in order.
        surfaces: numbers of surfaces in order.
        n_scenes: scenes per number of surfaces.
        errors: ``errors[method][surfaces][statistic] -> (n_scenes,)`` NumPy arrays (unit scale),
            with ``"ok"`` booleans; statistics that do not apply to a method are absent.
        fits_from_cache, fits_fitted: how many labels were read from the cache of fits
            (:mod:`ccjax.runs.store`) and how many were fitted (methods given as models count in neither).
        cells_from_cache: how many (method, surface count) cells of per-scene errors were read
            from the disk cache of sweeps (``sweep(..., cache=True)``) instead of computed.
    """

    methods: list[str]
    surfaces: list[int]
    n_scenes: int
    errors: dict = field(default_factory=dict)
    fits_from_cache: int = 0
    fits_fitted: int = 0
    cells_from_cache: int = 0

    def value(self, method: str, surfaces: int, statistic: str, summary: str = "rms") -> float:
        """A summary of one method's per-scene errors at one surface count.

        Arguments:
            method: a label of :attr:`methods`.
            surfaces: a number of :attr:`surfaces`.
            statistic: one of :data:`STATISTICS`.
            summary: see :func:`ccjax.metrics.summarise` (``"rms"`` is the thesis' aggregate).

        Returns:
            The summary, on the unit scale.
        """
        return metrics.summarise(self.errors[method][surfaces][statistic], summary)

    def standard_error(self, method: str, surfaces: int, statistic: str, summary: str = "rms") -> float:
        """The sampling error of :meth:`value` over scenes (see :func:`sampling_error`).

        Arguments:
            method: a label of :attr:`methods`.
            surfaces: a number of :attr:`surfaces`.
            statistic: one of :data:`STATISTICS`.
            summary: ``"rms"`` or ``"mean"``.

        Returns:
            The standard error, on the unit scale.
        """
        return sampling_error(self.errors[method][surfaces][statistic], summary)

    def ok_fraction(self, method: str, surfaces: int) -> float:
        """The share of scenes with ``ok`` (``Status.ESTIMATED``).

        Arguments:
            method: a label of :attr:`methods`.
            surfaces: a number of :attr:`surfaces`.

        Returns:
            A fraction in [0, 1].
        """
        return float(np.mean(self.errors[method][surfaces]["ok"]))

    def status_fraction(self, method: str, surfaces: int, status: str) -> float:
        """The share of scenes whose estimate was relaxed or fell back (see :data:`STATUS_SUMMARIES`).

        Arguments:
            method: a label of :attr:`methods`.
            surfaces: a number of :attr:`surfaces`.
            status: ``"relaxed"`` or ``"fell_back"``.

        Returns:
            A fraction in [0, 1].
        """
        codes = np.asarray(self.errors[method][surfaces]["status"])
        if status == "relaxed":
            return float(np.mean(codes == base.Status.RELAXED))
        if status == "fell_back":
            return float(np.mean((codes == base.Status.NO_DATA) | (codes == base.Status.EMPTY_SET)))
        raise ValueError(f"status: expected one of {STATUS_SUMMARIES}, got {status!r}")

    def rows(self, summaries: Sequence[str] = ("rms",)) -> list[dict]:
        """The tidy table: one row per method, surfaces, statistic and summary.

        Arguments:
            summaries: the summaries of each statistic (see :func:`ccjax.metrics.summarise`).

        Returns:
            Dicts with ``method``, ``surfaces``, ``statistic``, ``summary``, ``value``,
            ``ok_fraction``, ``relaxed_fraction``, ``fell_back_fraction`` and ``n_scenes``.
        """
        out = []
        for method in self.methods:
            for n in self.surfaces:
                per_scene = self.errors[method][n]
                for statistic in STATISTICS:
                    if statistic not in per_scene:
                        continue
                    for summary in summaries:
                        out.append(
                            {
                                "method": method,
                                "surfaces": n,
                                "statistic": statistic,
                                "summary": summary,
                                "value": metrics.summarise(per_scene[statistic], summary),
                                "ok_fraction": self.ok_fraction(method, n),
                                "relaxed_fraction": self.status_fraction(method, n, "relaxed"),
                                "fell_back_fraction": self.status_fraction(method, n, "fell_back"),
                                "n_scenes": self.n_scenes,
                            }
                        )
        return out

    def report(self, summaries: Sequence[str] = ("rms",)) -> Report:
        """The tidy rows as a :class:`Report` (text, CSV, JSON).

        Arguments:
            summaries: the summaries of each statistic (see :func:`ccjax.metrics.summarise`).

        Returns:
            A :class:`Report` of :meth:`rows`.
        """
        columns = [
            Column("method"),
            Column("surfaces", align=">", gap=2),
            Column("statistic", gap=2),
            Column("summary", gap=2),
            Column("value", spec=".6g", align=">", gap=2),
            Column("ok_fraction", "ok", spec=".1%", align=">", gap=2),
            Column("relaxed_fraction", "relaxed", spec=".1%", align=">", gap=2),
            Column("fell_back_fraction", "fell back", spec=".1%", align=">", gap=2),
        ]
        return Report(self.rows(summaries), columns, metadata={"n_scenes": self.n_scenes})

    def to_csv(self, summaries: Sequence[str] = ("rms",)) -> str:
        """:meth:`report` as CSV.

        Arguments:
            summaries: the summaries of each statistic (see :func:`ccjax.metrics.summarise`).

        Returns:
            The CSV text.
        """
        return self.report(summaries).to_csv()

    def to_json(self, summaries: Sequence[str] = ("rms",)) -> str:
        """:meth:`report` as JSON.

        Arguments:
            summaries: the summaries of each statistic (see :func:`ccjax.metrics.summarise`).

        Returns:
            The JSON text.
        """
        return self.report(summaries).to_json()

    def status_table(self) -> str:
        """A text table of estimate statuses: methods down, and per surface count the percentage
        of scenes relaxed and fallen back (:data:`STATUS_SUMMARIES`).

        Returns:
            The table, one line per method after two heading lines.
        """
        width = max(len("relaxed / fell back"), *(len(m) for m in self.methods)) + 2
        head = "relaxed / fell back".ljust(width) + "".join(f"{n:>16d}" for n in self.surfaces)
        lines = [head, "-" * len(head)]
        for method in self.methods:
            shares = [
                (self.status_fraction(method, n, "relaxed"), self.status_fraction(method, n, "fell_back"))
                for n in self.surfaces
            ]
            cells = [f"{relaxed:.1%} / {fell_back:.1%}" for relaxed, fell_back in shares]
            lines.append(method.ljust(width) + "".join(f"{c:>16}" for c in cells))
        return "\n".join(lines)

    def table(self, statistic: str = "rg", summary: str = "rms") -> str:
        """A text table: methods down, surfaces across, with the ok-fraction of the last column.

        Arguments:
            statistic: one of :data:`STATISTICS`.
            summary: see :func:`ccjax.metrics.summarise`.

        Returns:
            The table (``*`` where the statistic does not apply to a method).
        """
        width = max(len(m) for m in self.methods) + 2
        head = f"{statistic} ({summary})".ljust(width) + "".join(f"{n:>10d}" for n in self.surfaces) + "      ok"
        lines = [head, "-" * len(head)]
        for method in self.methods:
            cells = []
            for n in self.surfaces:
                per_scene = self.errors[method][n]
                cells.append(
                    f"{metrics.summarise(per_scene[statistic], summary):10.4f}"
                    if statistic in per_scene
                    else f"{'*':>10}"
                )
            ok = self.ok_fraction(method, self.surfaces[-1])
            lines.append(method.ljust(width) + "".join(cells) + f"  {ok:6.1%}")
        return "\n".join(lines)


def is_registered(label: str) -> bool:
    """Whether ``label`` names a registered estimator (see ``ccjax methods``).

    Arguments:
        label: an estimator label.

    Returns:
        True when a registry family's grammar accepts it.
    """
    try:
        registry.lookup(label)
        return True
    except ValueError:
        return False


def weights_ready(label: str, world: World) -> bool:
    """False for a learned method whose weights are not cached for ``world`` (never train silently).

    Default method sets (``ccjax compare``, ``ccjax reproduce``) include the neural net (Barnard
    1999 §4.5.5) only once ``ccjax train-net`` has cached its weights.

    Arguments:
        label: an estimator label.
        world: the world the weights must have been trained for.

    Returns:
        True for every label but a net's without cached weights.
    """
    from ccjax.estimators import neural

    return not neural.is_net_label(label) or neural.has_weights(world, label)


def runnable_methods(labels: Sequence[str], world: World) -> list[str]:
    """The labels of ``labels`` that are registered and, if learned, have cached weights.

    Arguments:
        labels: candidate labels, in order.
        world: the world of the weights.

    Returns:
        The runnable labels, in the given order.
    """
    return [label for label in labels if is_registered(label) and weights_ready(label, world)]


def require_surface_estimator(label: str, model: AbstractEstimator) -> None:
    """Refuse an image estimator where synthetic surface lists are the input.

    Sweeps sample scenes as lists of surface RGBs (Barnard 1999 §4.7); an image estimator (grey
    edge) needs ``(H, W, 3)`` images with neighbouring pixels, so it is run through the image
    experiments instead.

    Arguments:
        label: the model's label (named in the error).
        model: a fitted estimator.

    Raises:
        ValueError: naming ``label`` when ``model`` is an image estimator.
    """
    check = getattr(base, "require_kind", None)  # the estimator contract's own check, where it exists
    if check is not None:
        check(model, "surfaces", f"methods: {label!r}")
    image = isinstance(model, AbstractImageEstimator) or getattr(type(model), "input_kind", "surfaces") == "image"
    if image:
        raise ValueError(
            f"methods: {label!r} is an image estimator (it needs (H, W, 3) images, not the surface lists "
            "a sweep samples); run it on images with `ccjax evaluate` / ccjax.experiments.evaluation.run_images or on "
            "synthetic images with `ccjax indexing` / ccjax.experiments.indexing.run_indexing"
        )


def resolve_methods(world: World, methods, counts: dict | None = None) -> list[tuple[str, AbstractEstimator]]:
    """``(label, surface estimator)`` pairs from labels, estimators or pairs (labels are fitted,
    through the store, :func:`ccjax.runs.store.fit_with_source`).

    Arguments:
        world: the world labels are fitted to.
        methods: labels, fitted surface estimators, or ``(label, estimator)`` pairs.
        counts: if given, ``"cached"`` and ``"fitted"`` are incremented per label.

    Returns:
        The pairs, in order.

    Raises:
        ValueError: an empty list, an unknown item or an image estimator.
    """
    resolved = []
    for method in methods:
        if isinstance(method, str):
            model, hit = store.fit_with_source(method, world)
            if counts is not None:
                name = "cached" if hit else "fitted"
                counts[name] = counts.get(name, 0) + 1
            resolved.append((method, model))
        elif isinstance(method, tuple) and len(method) == 2 and isinstance(method[1], AbstractEstimator):
            resolved.append(method)
        elif isinstance(method, AbstractEstimator):
            resolved.append((type(method).__name__, method))
        else:
            raise ValueError(f"methods: expected labels, Estimators or (label, Estimator) pairs, got {method!r}")
        require_surface_estimator(*resolved[-1])
    if not resolved:
        raise ValueError("methods: empty")
    return resolved


def sweep(
    world: World,
    methods: Sequence,
    n_surfaces: Sequence[int] = (4, 8, 16, 32, 64),
    n_scenes: int = 1000,
    key: jax.Array | None = None,
    *,
    specular=None,
    noise=None,
    clip: float | None = None,
    chunk_size: int | None = None,
    mesh: jax.sharding.Mesh | None = None,
    progress: bool = True,
    cache: bool = False,
) -> SweepResult:
    """Run every method on the same synthetic scenes for each number of surfaces (Barnard 1999 §4.7).

    Arguments:
        world: the world.
        methods: labels (``"GW"``), fitted surface estimators, or ``(label, estimator)`` pairs.
            Image estimators (grey edge) are refused with a ValueError.
        n_surfaces: numbers of surfaces per scene.
        n_scenes: scenes per number of surfaces (1000 in the thesis).
        key: PRNG key (default ``jax.random.key(0)``).
        specular, noise, clip: scene options, as in :func:`ccjax.scenes.sample`.
        chunk_size: scenes per compiled chunk (default: about 4M surfaces per chunk), which bounds
            memory whatever ``n_scenes`` is.
        mesh: optional ``jax.sharding.Mesh`` with one axis; the scene axis of every chunk is sharded
            over it (multi-device or multi-host).
        progress: show a progress bar.
        cache: read and write each (label, surface count) cell's per-scene errors in the disk
            cache (``<cache>/sweeps``), keyed by everything they depend on (the label, the world,
            the scene options and key, the counts, padded and chunk sizes, ccjax's code, JAX's
            version and backend), so a repeated sweep computes only the cells it has not seen.
            Only labelled methods on one device are cached (models given as objects, and sharded
            sweeps, are always computed); the count of cells read is
            :attr:`SweepResult.cells_from_cache`.

    Returns:
        A :class:`SweepResult`.

    The surface counts' programs are traced and compiled on two worker threads ahead of the
    count that runs. They see ``jax_enable_x64`` as the caller has it; other per-thread JAX
    settings (a ``jax.default_device`` context) are not passed on: set those globally.
    """
    if not isinstance(n_scenes, int) or n_scenes < 1:
        raise ValueError(f"n_scenes: expected a positive integer, got {n_scenes!r}")
    n_reflectances = int(world.reflectances.shape[0])
    surfaces = [int(n) for n in n_surfaces]
    if not surfaces or any(not 1 <= n <= n_reflectances for n in surfaces):
        raise ValueError(f"n_surfaces: expected integers in [1, {n_reflectances}], got {list(n_surfaces)}")
    specular, noise = resolve_options(specular, noise, clip)
    counts: dict[str, int] = {}
    resolved = resolve_methods(world, methods, counts)
    labels = [label for label, _ in resolved]
    models = [model for _, model in resolved]
    key = jax.random.key(0) if key is None else key
    tables = SceneTables.from_world(world)
    sharding = None
    n_devices = 1
    if mesh is not None:
        if len(mesh.axis_names) != 1:
            raise ValueError(f"mesh: expected one axis, got {mesh.axis_names}")
        sharding = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec(mesh.axis_names[0]))
        n_devices = mesh.devices.size

    sizes = padded_sizes(surfaces, models)
    result = SweepResult(
        methods=labels,
        surfaces=surfaces,
        n_scenes=n_scenes,
        fits_from_cache=counts.get("cached", 0),
        fits_fitted=counts.get("fitted", 0),
    )
    plan = []
    for n in surfaces:
        # The chunk size follows the padded size, so counts padded alike share one program.
        size = chunk_size or max(64, min(16384, _SURFACES_PER_CHUNK // sizes[n]))
        size = min(size, n_scenes)
        size = int(math.ceil(size / n_devices) * n_devices)
        plan.append((n, size, int(math.ceil(n_scenes / size))))
    # Cells of the disk cache of sweeps: the key holds everything a cell's numbers depend on, so a
    # hit is what recomputing would give on this code, JAX and backend.
    cell_keys: dict[tuple[int, int], str] = {}
    if cache and mesh is None:
        common = (
            world,
            code_fingerprint(),
            jax.__version__,
            jax.default_backend(),
            jax.random.key_data(key),
            n_scenes,
            specular,
            noise,
            clip,
        )
        for n, size, _ in plan:
            for position, method in enumerate(methods):
                if isinstance(method, str):
                    cell_keys[n, position] = content_key("sweep", method, n, sizes[n], size, *common)
    cells: dict[tuple[int, int], dict[str, np.ndarray]] = {}
    for (n, position), cell_key in cell_keys.items():
        stored = read_arrays("sweeps", cell_key)
        if stored is not None:
            cells[n, position] = stored
    result.cells_from_cache = len(cells)
    todo = {n: [p for p in range(len(resolved)) if (n, p) not in cells] for n in surfaces}
    bar = tqdm(
        total=sum(chunks for n, _, chunks in plan if todo[n]),
        desc="sweep",
        unit="chunk",
        disable=not progress,
        leave=False,
    )

    # One sampler program per (padded size, chunk size) when counts can share it: the scenes of
    # `sample_batch_slots` extend a shorter draw's random bits, which needs partitionable threefry.
    shared_sampler = bool(jax.config.jax_threefry_partitionable)  # pyright: ignore[reportAttributeAccessIssue]

    def chunk_scenes(n: int, size: int, index: int) -> Scenes:
        # Every chunk has the same shape (the last is padded with later scenes of the stream and
        # trimmed), so the estimators compile once per (padded size, chunk size).
        keys = scene_keys(jax.random.fold_in(key, n), index * size, size)
        if sharding is not None:
            keys = jax.device_put(keys, sharding)
        count = jnp.asarray(n, jnp.int32) if shared_sampler else n
        sampler = sample_batch_slots if shared_sampler else _padded_sample
        return sampler(keys, tables, count, sizes[n], specular, noise, clip)

    def sampler_key(n: int, size: int) -> tuple:
        return (sizes[n], size) if shared_sampler else (n, size)

    x64 = bool(jax.config.read("jax_enable_x64"))

    def compile_sampler(n: int, size: int) -> None:
        """Compile count ``n``'s sampler (by sampling its first chunk once)."""
        with jax.enable_x64(x64):  # the caller's setting (a context is per thread)
            chunk_scenes(n, size, 0)

    def compile_errors(n: int, size: int, positions: list[int]):
        """Compile the errors program of count ``n``'s padded size: on one device from zeros of the
        scenes' shapes, so it does not wait for the sampler to compile; sharded, from the first
        chunk (whose layout the sampler decides)."""
        with jax.enable_x64(x64):
            if sharding is None:
                shapes = jax.eval_shape(lambda: chunk_scenes(n, size, 0))
                scenes = jax.tree.map(lambda leaf: jnp.zeros(leaf.shape, leaf.dtype), shapes)
            else:
                scenes = chunk_scenes(n, size, 0)
            return _errors.lower([models[p] for p in positions], scenes, tables.canonical_white).compile()

    # Compilation is most of a cold sweep: two worker threads trace and compile the programs in
    # the order they are first needed, each distinct one once (counts padded alike share their
    # errors program and their sampler), while this thread runs those already compiled (XLA
    # compiles and runs without holding the GIL), so compiling overlaps running, and two
    # programs compile at once.
    # (Measured on 2 cores, the default `ccjax compare` cold: 52 s compiling in sequence, 45 s with
    # one worker; two workers against one, interleaved on a slower phase of the same machine:
    # 78.9 and 68.4 s against 79.9 and 79.3 s.)
    compiler = concurrent.futures.ThreadPoolExecutor(max_workers=2, thread_name_prefix="ccjax-compile")
    try:
        programs: dict[tuple, concurrent.futures.Future] = {}
        samplers: dict[tuple, concurrent.futures.Future] = {}
        for n, size, _ in plan:
            if todo[n]:
                program_key = (sizes[n], size, tuple(todo[n]))
                if program_key not in programs:
                    programs[program_key] = compiler.submit(compile_errors, n, size, todo[n])
                if sampler_key(n, size) not in samplers:
                    samplers[sampler_key(n, size)] = compiler.submit(compile_sampler, n, size)
        for n, size, chunks in plan:
            positions = todo[n]
            if positions:
                samplers[sampler_key(n, size)].result()
                program = programs[sizes[n], size, tuple(positions)].result()
                chosen = [models[p] for p in positions]
                collected: list[list[dict]] = []
                for index in range(chunks):
                    out = program(chosen, chunk_scenes(n, size, index), tables.canonical_white)
                    collected.append(jax.device_get(out))
                    bar.update()
                for slot, position in enumerate(positions):
                    merged = {
                        name: np.concatenate([chunk[slot][name] for chunk in collected])[:n_scenes]
                        for name in (*STATISTICS, "ok", "status")
                        if models[position].estimates_brightness or name not in BRIGHTNESS_STATISTICS
                    }
                    cells[n, position] = merged
                    if (n, position) in cell_keys:
                        record = {"label": labels[position], "surfaces": n, "world": world.name}
                        write_arrays("sweeps", cell_keys[n, position], merged, record)
            for position, label in enumerate(labels):
                result.errors.setdefault(label, {})[n] = cells[n, position]
    finally:
        compiler.shutdown(wait=False, cancel_futures=True)
        bar.close()
    return result
