"""The thesis tables' protocols behind ``ccjax reproduce``, and the comparison with the thesis.

Each table of Barnard 1999 that ccjax reproduces is a list of :class:`Condition` sweeps (scene
options and the per-scene statistic behind each column); :func:`reproduce` runs them on the thesis
world and sets our value beside the transcribed one (:mod:`ccjax.thesis`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import jax
import numpy as np

from ccjax.experiments.reports import Column, Report
from ccjax.experiments.sweep_results import SweepResult
from ccjax.experiments.sweeps import is_registered, resolve_methods
from ccjax.runs.engine import RGB_VALUED, STATISTICS
from ccjax.runs.synthetic import SyntheticSource, run_synthetic
from ccjax.scenes import Fluorescent, Metallic, SceneOptions, Specular
from ccjax.world import World


@dataclass(frozen=True)
class Condition:
    """One sweep of a table's protocol and which table columns it fills.

    Attributes:
        n_surfaces: surfaces per scene.
        columns: table column -> per-scene statistic (one of :data:`STATISTICS`).
        options: the :class:`~ccjax.scenes.SceneOptions` (specularities, noise, clip on ccjax's
            unit scale, metallic highlights, fluorescent surfaces).
    """

    n_surfaces: int
    columns: dict
    options: SceneOptions = field(default_factory=SceneOptions)


BASIC_COLUMNS = {name: name for name in STATISTICS}
"""The columns of Tables 4.2 and 4.3: every statistic under its own name."""

CLIP_300 = 300 / 255.0
"""Chapter 8's clip level (300 in thesis units; Table 8.2 column 3 equals Table 4.4's 300 column)."""


def _chapter8_conditions(statistic: str, name: str) -> list[Condition]:
    """Tables 8.2 / 8.3's five conditions (§8.3), one statistic each (columns ``name@...``):
    matte; dielectric specularities ("spec"); the same clipped at 300; metallic specularities
    ("metal": 25 %, ``U(0, 4)`` x a metal spectrum drawn from every metal, A11); the same clipped."""
    return [
        Condition(8, {f"{name}@matte": statistic}),
        Condition(8, {f"{name}@spec": statistic}, SceneOptions(specular=Specular())),
        Condition(8, {f"{name}@spec+clip": statistic}, SceneOptions(specular=Specular(), clip=CLIP_300)),
        Condition(8, {f"{name}@metal": statistic}, SceneOptions(metallic=Metallic())),
        Condition(8, {f"{name}@metal+clip": statistic}, SceneOptions(clip=CLIP_300, metallic=Metallic())),
    ]


PROTOCOLS: dict[str, list[Condition]] = {
    # Table 4.2: 8 matte surfaces (§4.7).
    "4.2": [Condition(8, BASIC_COLUMNS)],
    # Table 4.3: 8 surfaces, 25 % specular + U(0, 2) x white.
    "4.3": [Condition(8, BASIC_COLUMNS, SceneOptions(specular=Specular()))],
    # Table 4.4: specular scenes, surfaces with any channel above 400/300/250 (thesis units) discarded.
    "4.4": [
        Condition(
            8,
            {f"angular@{level}": "angular", f"rg@{level}": "rg"},
            SceneOptions(specular=Specular(), clip=level / 255.0),
        )
        for level in (400, 300, 250)
    ],
    # Table 6.1 (§6.3): matte scenes of 4, 8 and 16 surfaces, rg only.
    "6.1": [Condition(n, {f"rg@{n}": "rg"}) for n in (4, 8, 16)],
    # Table 7.2 (§7.3): 4 and 8 surfaces, matte, then each surface fluorescent with p = 0.3 (A21).
    "7.2": [
        condition
        for n in (4, 8)
        for condition in (
            Condition(n, {f"rg@{n}": "rg"}),
            Condition(n, {f"rg@{n}+FL": "rg"}, SceneOptions(fluorescent=Fluorescent())),
        )
    ],
    # Tables 8.2 and 8.3 (§8.3): 8 surfaces under five conditions; the first three are exactly
    # Table 4.2's, 4.3's and 4.4's (clip 300) sweeps, so the same key gives the same scenes.
    "8.2": _chapter8_conditions("rg", "rg"),
    "8.3": _chapter8_conditions("brightness", "sum"),
    # Table 10.1 (§10.3): 8 surfaces, matte, fluorescent (p = 0.15 per surface, A17) and specular worlds (rg only).
    "10.1": [
        Condition(8, {"rg@matte": "rg"}),
        Condition(8, {"rg@fluorescent": "rg"}, SceneOptions(fluorescent=Fluorescent(probability=0.15))),
        Condition(8, {"rg@specular": "rg"}, SceneOptions(specular=Specular())),
    ],
    # Table 10.2 (§10.3): 8 matte surfaces.
    "10.2": [Condition(8, {"rg": "rg"})],
}
"""Table id -> the sweeps of its protocol (Barnard 1999 §4.7, §6.3, §10.3)."""

REPRODUCTION_COLUMNS = (
    Column("method", width=22),
    Column("column", width=14),
    Column("ours", spec=".4g", width=10, align=">"),
    Column("thesis", spec=".4g", width=10, align=">"),
    Column("relative_difference", "diff", spec="+.1%", width=9, align=">"),
    Column("sampling_error", "s.e.", spec=".2g", width=9, align=">"),
    Column("ok_fraction", "ok", spec=".0%", gap=2),
)
"""The text view of a reproduction; ``s.e.`` is ours' standard error over scenes (delta method for
the RMS, :func:`ccjax.experiments.sweep_results.sampling_error`), in the units of ``ours``."""


@dataclass
class Reproduction:
    """Our value, the thesis' value and their relative difference per (method, column).

    Attributes:
        table: the thesis table id (``"4.2"``, ``"8.3"``, ...), a key of :data:`PROTOCOLS`.
        rows: one dict per (method, column) cell, in the order of the methods, with keys
            ``method``, ``column``, ``ours``, ``thesis``, ``relative_difference`` (``ours / thesis -
            1``), ``sampling_error`` (standard error of ``ours`` over the scenes) and
            ``ok_fraction`` (share of scenes the method answered with ``ok``); RGB-valued errors
            are in thesis units (white = 255), the columns of :data:`REPRODUCTION_COLUMNS`.
        notes: extra footer lines of the report (Table 7.2: the fluorescent characterisation's
            prediction error per surface, §7.1).
    """

    table: str
    rows: list[dict]
    notes: list[str] = field(default_factory=list)

    def report(self) -> Report:
        """The rows as a report.

        Returns:
            The :class:`Report`: the cells, then the ±10/15/20 % bands and the orderings.
        """
        footer = []
        if self.rows:
            differences = np.abs([row["relative_difference"] for row in self.rows])
            within = ", ".join(
                f"{np.sum(differences <= band)}/{len(differences)} within ±{band:.0%}" for band in (0.10, 0.15, 0.20)
            )
            footer.append(f"cells: {within}; largest |diff| {np.max(differences):.1%}")
            if any(row.get("sampling_error") is not None for row in self.rows):
                footer.append("s.e.: standard error of ours over the scenes (delta method for the RMS)")
        footer.extend(f"ordering: {line}" for line in self.orderings())
        footer.extend(f"check: {line}" for line in self.checks())
        footer.extend(self.notes)
        title = [f"Table {self.table}: ours vs thesis (RGB-valued errors in thesis units, white = 255)"]
        return Report(self.rows, REPRODUCTION_COLUMNS, metadata={"table": self.table}, title=title, footer=footer)

    def checks(self) -> list[str]:
        """The thesis' claims on this table (``thesis.CHECKS``: pairs, ratios, best rows, spreads),
        checked on our values.

        Returns:
            One line per claim, marked ``ok`` or ``MISS``; claims whose cells were not run are left
            out.
        """
        from ccjax import thesis

        ours = {(row["method"], row["column"]): row["ours"] for row in self.rows}
        lines = []
        for claim in thesis.CHECKS.get(self.table, []):
            line = check_claim(claim, ours)
            if line is not None:
                lines.append(line)
        return lines

    def to_json(self) -> str:
        return self.report().to_json()

    def to_csv(self) -> str:
        return self.report().to_csv()

    def text(self) -> str:
        return self.report().text()

    def orderings(self) -> list[str]:
        """The thesis' orderings for this table (``thesis.ORDERINGS``), checked on our values.

        Returns:
            One line per ordering.
        """
        from ccjax import thesis

        ours = {(row["method"], row["column"]): row["ours"] for row in self.rows}
        lines = []
        for better, worse, column in thesis.ORDERINGS.get(self.table, []):
            if (better, column) in ours and (worse, column) in ours:
                a, b = ours[(better, column)], ours[(worse, column)]
                lines.append(f"{better} {a:.4g} < {worse} {b:.4g} at {column}: {'holds' if a < b else 'FAILS'}")
        return lines


CHUNK = 1000
"""Scenes per chunk of a table's conditions (every chunk has the same shape, so each model
compiles once per number of surfaces for all the conditions of a table)."""


def run_conditions(
    world: World,
    fitted: list,
    conditions: Sequence[Condition],
    n_scenes: int,
    key: jax.Array,
    progress: bool = True,
    metals: np.ndarray | None = None,
) -> list[SweepResult]:
    """Every model on every condition's scenes, the scene draws shared across conditions.

    A condition's scenes come from the sweep's keys (:func:`ccjax.scenes.sweep_keys`: the stream of
    its number of surfaces), so conditions differing only in specularities, metals, fluorescent
    surfaces or clipping see the same lights and surfaces, as the thesis' chapter-8 runs did
    (Table 8.2's columns 1-3 are Tables 4.2-4.4's scenes), and equal ``ccjax compare``'s
    scenes for the same key. Each condition is one synthetic source of the engine
    (:func:`ccjax.runs.synthetic.run_synthetic`), unpadded (one count each), in chunks of
    :data:`CHUNK` scenes; fluorescent surfaces are rendered through their characterisation, as
    the thesis rendered its synthetic fluorescent scenes (§7.3; its error against the physical
    model is printed with Table 7.2).

    Arguments:
        world: the world.
        fitted: ``(label, surface estimator)`` pairs.
        conditions: the table's :class:`Condition` list.
        n_scenes: scenes per condition.
        key: the sweep key.
        progress: show a progress bar.
        metals: ``(M, 101)`` spectra of the metallic highlights (default: the six metals'
            reflectances, :func:`ccjax.materials.scene_metal_spectra`).

    Returns:
        One :class:`~ccjax.experiments.sweep_results.SweepResult` per condition (one surface count each).
    """
    sources = [
        SyntheticSource(key, (condition.n_surfaces,), n_scenes, condition.options, metals=metals)
        for condition in conditions
    ]
    run = run_synthetic(
        world, [model for _, model in fitted], sources, chunk_size=CHUNK, progress=progress, desc="reproduce"
    )
    results = []
    for condition, errors in zip(conditions, run.errors, strict=True):
        n = condition.n_surfaces
        result = SweepResult(methods=[label for label, _ in fitted], surfaces=[n], n_scenes=n_scenes)
        for position, (label, _) in enumerate(fitted):
            result.errors.setdefault(label, {})[n] = errors[n][position]
        results.append(result)
    return results


def check_claim(claim: tuple, ours: dict) -> str | None:
    """One claim of ``thesis.CHECKS`` on ``ours`` (``(method, column) -> value``): a line ending
    in ``ok`` or ``MISS``, or ``None`` when a cell it needs is missing.

    Kinds: ``("less", a, b, column)``; ``("ratio", a, b, column, f)`` (``a <= f b``); ``("best",
    rows, "gamut", column)`` (every row of ``rows`` beats every other gamut-mapping row run);
    ``("spread", a, columns, low, high)`` (``low <= max / min <= high`` over the columns).

    Arguments:
        claim: one entry of ``thesis.CHECKS``.
        ours: our values, ``(method, column) -> value``.

    Returns:
        A line ending in ``ok`` or ``MISS``, or ``None`` when a cell it needs is missing.
    """
    kind = claim[0]
    mark = lambda holds: "ok" if holds else "MISS"
    if kind in ("less", "ratio"):
        a, b, column = claim[1:4]
        if (a, column) not in ours or (b, column) not in ours:
            return None
        x, y = ours[(a, column)], ours[(b, column)]
        if kind == "less":
            return f"{a} {x:.4g} < {b} {y:.4g} at {column}: {mark(x < y)}"
        factor = claim[4]
        return f"{a} {x:.4g} <= {factor:g} x {b} {y:.4g} (ratio {x / y:.3f}) at {column}: {mark(x <= factor * y)}"
    if kind == "best":
        rows, _, column = claim[1:4]
        if any((r, column) not in ours for r in rows):
            return None
        others = {m: v for (m, c), v in ours.items() if c == column and "CRULE" in m and m not in rows}
        if not others:
            return None
        rival = min(others, key=others.__getitem__)
        worst = max(rows, key=lambda r: ours[(r, column)])
        holds = ours[(worst, column)] < others[rival]
        named = " and ".join(f"{r} {ours[(r, column)]:.4g}" for r in rows)
        return f"{named} best gamut row(s) at {column} (next {rival} {others[rival]:.4g}): {mark(holds)}"
    if kind == "spread":
        a, columns, low, high = claim[1:5]
        if any((a, c) not in ours for c in columns):
            return None
        values = [ours[(a, c)] for c in columns]
        ratio = max(values) / min(values)
        bound = f"in [{low:g}, {high:g}]" if np.isfinite(high) else f">= {low:g}"
        return f"{a} max/min over the {len(columns)} columns {ratio:.2f} {bound}: {mark(low <= ratio <= high)}"
    raise ValueError(f"claim: unknown kind {kind!r}")


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
        table: a table id with a protocol in :data:`PROTOCOLS` (``"4.2"``, ``"4.3"``, ``"4.4"``, ...).
        world: normally :meth:`World.barnard1999`.
        methods: labels (default: every method of the table that ccjax registers).
        n_scenes: scenes per condition (1000 in the thesis).
        key: PRNG key (default ``jax.random.key(0)``).
        progress: show a progress bar.

    Returns:
        A :class:`Reproduction`; ``relative_difference = ours / thesis - 1``; ``sampling_error`` is
        the standard error of ``ours`` over the scenes (delta method for the RMS, see
        :func:`ccjax.experiments.sweep_results.sampling_error`), in the units of ``ours``.
    """
    from ccjax import thesis

    if table not in PROTOCOLS or table not in thesis.TABLES:
        raise ValueError(f"table: no protocol for {table!r}; available: {sorted(PROTOCOLS)}")
    targets = thesis.TABLES[table]
    if methods is None:
        methods = [m for m in targets if is_registered(m)]
    unknown = [m for m in methods if m not in targets]
    if unknown:
        raise ValueError(f"methods: {unknown} are not rows of Table {table}")
    fitted = resolve_methods(world, methods)  # through the store's cache of fits
    key = jax.random.key(0) if key is None else key
    rows = []
    for condition, result in zip(
        PROTOCOLS[table], run_conditions(world, fitted, PROTOCOLS[table], n_scenes, key, progress)
    ):
        for method in methods:
            for column, statistic in condition.columns.items():
                if column not in targets[method] or statistic not in result.errors[method][condition.n_surfaces]:
                    continue
                ours = result.value(method, condition.n_surfaces, statistic)
                error = result.standard_error(method, condition.n_surfaces, statistic)
                if statistic in RGB_VALUED:
                    ours *= thesis.THESIS_RGB_SCALE
                    error *= thesis.THESIS_RGB_SCALE
                reference = targets[method][column]
                rows.append(
                    {
                        "method": method,
                        "column": column,
                        "ours": ours,
                        "thesis": reference,
                        "relative_difference": ours / reference - 1.0,
                        "sampling_error": error,
                        "ok_fraction": result.ok_fraction(method, condition.n_surfaces),
                    }
                )
    order = {m: i for i, m in enumerate(methods)}
    rows.sort(key=lambda r: order[r["method"]])
    return Reproduction(table=table, rows=rows, notes=characterisation_notes(world) if table == "7.2" else [])


def characterisation_notes(world: World) -> list[str]:
    """The fluorescent characterisation's prediction error per surface (§7.1, reported with
    Table 7.2): NNLS from the measurement lights, predicted under the world's test lights.

    Arguments:
        world: the world whose test lights the surfaces are predicted under.

    Returns:
        The report's lines.
    """
    from ccjax import materials
    from ccjax.estimators.gamut import MEASUREMENT_LIGHTS, characterised_fluorescents

    surfaces = materials.synthetic_fluorescent_surfaces()
    error = materials.prediction_error(
        surfaces, characterised_fluorescents(world), world.test_illuminants, world.camera.sensors
    )
    lines = [
        f"characterisation (§7.1): NNLS on the world's first {MEASUREMENT_LIGHTS} training lights, predicted under "
        f"{error.n_lights} test lights; RMS relative spectral / RGB error, RMS and worst (r,g) error per surface:"
    ]
    lines.extend(
        f"  {row['surface']:<18} {row['spectral']:7.2%} {row['rgb']:7.2%} {row['rg']:8.4f} {row['rg_max']:8.4f}"
        for row in error.rows()
    )
    return lines
