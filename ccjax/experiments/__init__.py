"""Sweeps over synthetic scenes: chunked, optionally sharded, with tidy tables and plots.

The protocol is the thesis' (Barnard 1999 §4.7): for each number of surfaces, ``n_scenes`` scenes
under test illuminants, every method run on the same scenes, errors aggregated per scene and then
summarised (RMS is the thesis' aggregate). Scenes come from per-scene keys, so a sweep's numbers do
not depend on its chunk size or on how the scene axis is sharded over devices.
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import equinox as eqx
import jax
import numpy as np
from tqdm.auto import tqdm

from ccjax import metrics
from ccjax.estimators import registry
from ccjax.estimators.base import Estimator, estimate_batch
from ccjax.scenes import SceneTables, resolve_options, sample_batch, scene_keys
from ccjax.world import World

STATISTICS = ("angular", "rg", "rgb", "brightness", "map_rg", "map_rgb")
"""Per-scene error measures (thesis §4.2): angle (degrees), (r,g) distance, RGB distance, signed
R+G+B difference, scene mapping RMS (r,g) and RGB errors; RGB-valued ones on the unit scale."""

BRIGHTNESS_STATISTICS = ("rgb", "brightness", "map_rgb")
RGB_VALUED = ("rgb", "brightness", "map_rgb")

# Scenes x surfaces per chunk: about 4M surfaces keeps a chunk's arrays near 100 MB.
_SURFACES_PER_CHUNK = 1 << 22


def scene_errors(model: Estimator, scenes, canonical_white) -> dict[str, jax.Array]:
    """Per-scene errors of one model on a scene batch, plus ``ok``."""
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
    }


@eqx.filter_jit
def _chunk(models, tables, keys, n_surfaces, specular, noise, clip):
    scenes = sample_batch(keys, tables, n_surfaces, specular, noise, clip)
    return [scene_errors(model, scenes, tables.canonical_white) for model in models]


@dataclass
class SweepResult:
    """Per-scene errors of a sweep and their summaries.

    Attributes:
        methods: labels in order.
        surfaces: numbers of surfaces in order.
        n_scenes: scenes per number of surfaces.
        errors: ``errors[method][surfaces][statistic] -> (n_scenes,)`` NumPy arrays (unit scale),
            with ``"ok"`` booleans; statistics that do not apply to a method are absent.
    """

    methods: list[str]
    surfaces: list[int]
    n_scenes: int
    errors: dict = field(default_factory=dict)

    def value(self, method: str, surfaces: int, statistic: str, summary: str = "rms") -> float:
        return metrics.summarise(self.errors[method][surfaces][statistic], summary)

    def ok_fraction(self, method: str, surfaces: int) -> float:
        return float(np.mean(self.errors[method][surfaces]["ok"]))

    def rows(self, summaries: Sequence[str] = ("rms",)) -> list[dict]:
        """The tidy table: one row per method, surfaces, statistic and summary."""
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
                                "n_scenes": self.n_scenes,
                            }
                        )
        return out

    def to_csv(self, summaries: Sequence[str] = ("rms",)) -> str:
        rows = self.rows(summaries)
        buffer = io.StringIO()
        writer = csv.DictWriter(buffer, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
        return buffer.getvalue()

    def to_json(self, summaries: Sequence[str] = ("rms",)) -> str:
        return json.dumps({"n_scenes": self.n_scenes, "rows": self.rows(summaries)}, indent=1)

    def table(self, statistic: str = "rg", summary: str = "rms") -> str:
        """A text table: methods down, surfaces across, with the ok-fraction of the last column."""
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


def _resolve_methods(world: World, methods) -> list[tuple[str, Estimator]]:
    resolved = []
    for method in methods:
        if isinstance(method, str):
            resolved.append((method, registry.fit(method, world)))
        elif isinstance(method, tuple) and len(method) == 2 and isinstance(method[1], Estimator):
            resolved.append(method)
        elif isinstance(method, Estimator):
            resolved.append((type(method).__name__, method))
        else:
            raise ValueError(f"methods: expected labels, Estimators or (label, Estimator) pairs, got {method!r}")
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
) -> SweepResult:
    """Run every method on the same synthetic scenes for each number of surfaces.

    Arguments:
        world: the world.
        methods: labels (``"GW"``), fitted estimators, or ``(label, estimator)`` pairs.
        n_surfaces: numbers of surfaces per scene.
        n_scenes: scenes per number of surfaces (1000 in the thesis).
        key: PRNG key (default ``jax.random.key(0)``).
        specular, noise, clip: scene options, as in :func:`ccjax.scenes.sample`.
        chunk_size: scenes per compiled chunk (default: about 4M surfaces per chunk), which bounds
            memory whatever ``n_scenes`` is.
        mesh: optional ``jax.sharding.Mesh`` with one axis; the scene axis of every chunk is sharded
            over it (multi-device or multi-host).
        progress: show a progress bar.

    Returns:
        A :class:`SweepResult`.
    """
    if not isinstance(n_scenes, int) or n_scenes < 1:
        raise ValueError(f"n_scenes: expected a positive integer, got {n_scenes!r}")
    n_reflectances = int(world.reflectances.shape[0])
    surfaces = [int(n) for n in n_surfaces]
    if not surfaces or any(not 1 <= n <= n_reflectances for n in surfaces):
        raise ValueError(f"n_surfaces: expected integers in [1, {n_reflectances}], got {list(n_surfaces)}")
    specular, noise = resolve_options(specular, noise, clip)
    resolved = _resolve_methods(world, methods)
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

    result = SweepResult(methods=labels, surfaces=surfaces, n_scenes=n_scenes)
    plan = []
    for n in surfaces:
        size = chunk_size or max(64, min(16384, _SURFACES_PER_CHUNK // n))
        size = min(size, n_scenes)
        size = int(math.ceil(size / n_devices) * n_devices)
        plan.append((n, size, int(math.ceil(n_scenes / size))))
    bar = tqdm(
        total=sum(chunks for _, _, chunks in plan), desc="sweep", unit="chunk", disable=not progress, leave=False
    )
    for n, size, chunks in plan:
        stream = jax.random.fold_in(key, n)
        collected: list[list[dict]] = []
        for index in range(chunks):
            # Every chunk has the same shape (the last is padded with later scenes of the stream
            # and trimmed), so each (surfaces, chunk size) compiles once.
            keys = scene_keys(stream, index * size, size)
            if sharding is not None:
                keys = jax.device_put(keys, sharding)
            out = _chunk(models, tables, keys, n, specular, noise, clip)
            collected.append(jax.device_get(out))
            bar.update()
        for position, (label, model) in enumerate(resolved):
            merged = {
                name: np.concatenate([chunk[position][name] for chunk in collected])[:n_scenes]
                for name in (*STATISTICS, "ok")
                if model.estimates_brightness or name not in BRIGHTNESS_STATISTICS
            }
            result.errors.setdefault(label, {})[n] = merged
    bar.close()
    return result


def plot(result: SweepResult, path, statistics: Sequence[str] = ("rg", "angular"), summary: str = "rms", title=None):
    """Error versus number of surfaces (log2 x axis, as the thesis' figures), one panel per statistic."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = {
        "angular": "angular error (degrees)",
        "rg": "(r,g) error",
        "rgb": "RGB error",
        "brightness": "R+G+B error",
        "map_rg": "mapping (r,g) error",
        "map_rgb": "mapping RGB error",
    }
    fig, axes = plt.subplots(1, len(statistics), figsize=(5.5 * len(statistics), 4.2), squeeze=False)
    for ax, statistic in zip(axes[0], statistics):
        for method in result.methods:
            points = [
                (n, result.value(method, n, statistic, summary))
                for n in result.surfaces
                if statistic in result.errors[method][n]
            ]
            if points:
                xs, ys = zip(*points)
                ax.plot(np.log2(xs), ys, marker="o", label=method)
        ax.set_xticks(np.log2(result.surfaces))
        ax.set_xticklabels([str(n) for n in result.surfaces])
        ax.set_xlabel("number of surfaces (log2 scale)")
        ax.set_ylabel(f"{summary.upper()} {labels.get(statistic, statistic)}")
        ax.grid(alpha=0.3)
    handles, names = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, names, fontsize=8, loc="center left", bbox_to_anchor=(1.0, 0.5))
    fig.suptitle(title or f"{result.n_scenes} scenes per point")
    fig.tight_layout()
    fig.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(fig)


# ---------------------------------------------------------------------------------------------
# Reproduction of the thesis' tables


@dataclass(frozen=True)
class Condition:
    """One sweep of a table's protocol and which table columns it fills.

    Attributes:
        n_surfaces: surfaces per scene.
        columns: table column -> per-scene statistic (one of :data:`STATISTICS`).
        specular, noise, clip: scene options (clip on ccjax's unit scale).
    """

    n_surfaces: int
    columns: dict
    specular: object = None
    noise: object = None
    clip: float | None = None


_BASIC_COLUMNS = {name: name for name in STATISTICS}

PROTOCOLS: dict[str, list[Condition]] = {
    # Table 4.2: 8 matte surfaces (§4.7).
    "4.2": [Condition(8, _BASIC_COLUMNS)],
    # Table 4.3: 8 surfaces, 25 % specular + U(0, 2) x white.
    "4.3": [Condition(8, _BASIC_COLUMNS, specular=True)],
    # Table 4.4: specular scenes, surfaces with any channel above 400/300/250 (thesis units) discarded.
    "4.4": [
        Condition(8, {f"angular@{level}": "angular", f"rg@{level}": "rg"}, specular=True, clip=level / 255.0)
        for level in (400, 300, 250)
    ],
    # Table 6.1 (§6.3): matte scenes of 4, 8 and 16 surfaces, rg only.
    "6.1": [Condition(n, {f"rg@{n}": "rg"}) for n in (4, 8, 16)],
    # Table 10.1 (§10.3): 8 surfaces, matte and specular worlds (rg only; fluorescent column later).
    "10.1": [Condition(8, {"rg@matte": "rg"}), Condition(8, {"rg@specular": "rg"}, specular=True)],
    # Table 10.2 (§10.3): 8 matte surfaces.
    "10.2": [Condition(8, {"rg": "rg"})],
}


@dataclass
class Reproduction:
    """Our value, the thesis' value and their relative difference per (method, column)."""

    table: str
    rows: list[dict]

    def to_json(self) -> str:
        return json.dumps({"table": self.table, "rows": self.rows}, indent=1)

    def text(self) -> str:
        lines = [f"Table {self.table}: ours vs thesis (RGB-valued errors in thesis units, white = 255)"]
        lines.append(f"{'method':<22}{'column':<14}{'ours':>10}{'thesis':>10}{'diff':>9}  ok")
        for row in self.rows:
            lines.append(
                f"{row['method']:<22}{row['column']:<14}{row['ours']:>10.4g}{row['thesis']:>10.4g}"
                f"{row['relative_difference']:>+9.1%}  {row['ok_fraction']:.0%}"
            )
        if self.rows:
            differences = np.abs([row["relative_difference"] for row in self.rows])
            within = ", ".join(
                f"{np.sum(differences <= band)}/{len(differences)} within ±{band:.0%}" for band in (0.10, 0.15, 0.20)
            )
            lines.append(f"cells: {within}; largest |diff| {np.max(differences):.1%}")
        lines.extend(f"ordering: {line}" for line in self.orderings())
        return "\n".join(lines)

    def orderings(self) -> list[str]:
        """The thesis' orderings for this table (``thesis.ORDERINGS``), checked on our values."""
        from ccjax import thesis

        ours = {(row["method"], row["column"]): row["ours"] for row in self.rows}
        lines = []
        for better, worse, column in thesis.ORDERINGS.get(self.table, []):
            if (better, column) in ours and (worse, column) in ours:
                a, b = ours[(better, column)], ours[(worse, column)]
                lines.append(f"{better} {a:.4g} < {worse} {b:.4g} at {column}: {'holds' if a < b else 'FAILS'}")
        return lines


def reproduce(
    table: str,
    world: World,
    methods: Sequence[str] | None = None,
    n_scenes: int = 1000,
    key: jax.Array | None = None,
    progress: bool = True,
) -> Reproduction:
    """Run a thesis table's protocol on ``world`` and compare with the thesis' numbers.

    Arguments:
        table: a table id with a protocol in :data:`PROTOCOLS` (``"4.2"``, ``"4.3"``, ``"4.4"``).
        world: normally :meth:`World.barnard1999`.
        methods: labels (default: every method of the table that ccjax registers).
        n_scenes: scenes per condition (1000 in the thesis).
        key: PRNG key (default ``jax.random.key(0)``).

    Returns:
        A :class:`Reproduction`; ``relative_difference = ours / thesis - 1``.
    """
    from ccjax import thesis

    if table not in PROTOCOLS or table not in thesis.TABLES:
        raise ValueError(f"table: no protocol for {table!r}; available: {sorted(PROTOCOLS)}")
    targets = thesis.TABLES[table]
    if methods is None:
        methods = [m for m in targets if _is_registered(m)]
    unknown = [m for m in methods if m not in targets]
    if unknown:
        raise ValueError(f"methods: {unknown} are not rows of Table {table}")
    rows = []
    for condition in PROTOCOLS[table]:
        result = sweep(
            world,
            list(methods),
            [condition.n_surfaces],
            n_scenes,
            key,
            specular=condition.specular,
            noise=condition.noise,
            clip=condition.clip,
            progress=progress,
        )
        for method in methods:
            for column, statistic in condition.columns.items():
                if column not in targets[method] or statistic not in result.errors[method][condition.n_surfaces]:
                    continue
                ours = result.value(method, condition.n_surfaces, statistic)
                if statistic in RGB_VALUED:
                    ours *= thesis.THESIS_RGB_SCALE
                reference = targets[method][column]
                rows.append(
                    {
                        "method": method,
                        "column": column,
                        "ours": ours,
                        "thesis": reference,
                        "relative_difference": ours / reference - 1.0,
                        "ok_fraction": result.ok_fraction(method, condition.n_surfaces),
                    }
                )
    order = {m: i for i, m in enumerate(methods)}
    rows.sort(key=lambda r: order[r["method"]])
    return Reproduction(table=table, rows=rows)


def _is_registered(label: str) -> bool:
    try:
        registry.lookup(label)
        return True
    except ValueError:
        return False
