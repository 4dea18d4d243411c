"""The thesis tables' protocols behind ``ccjax reproduce``, and the comparison with the thesis.

Each table of Barnard 1999 that ccjax reproduces is a list of :class:`Condition` sweeps (scene
options and the per-scene statistic behind each column); :func:`reproduce` runs them on the thesis
world and sets our value beside the transcribed one (:mod:`ccjax.thesis`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import jax
import numpy as np

from ccjax.experiments.reports import Column, Report
from ccjax.experiments.sweeps import RGB_VALUED, STATISTICS, is_registered, sweep
from ccjax.world import World


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


BASIC_COLUMNS = {name: name for name in STATISTICS}
"""The columns of Tables 4.2 and 4.3: every statistic under its own name."""

PROTOCOLS: dict[str, list[Condition]] = {
    # Table 4.2: 8 matte surfaces (§4.7).
    "4.2": [Condition(8, BASIC_COLUMNS)],
    # Table 4.3: 8 surfaces, 25 % specular + U(0, 2) x white.
    "4.3": [Condition(8, BASIC_COLUMNS, specular=True)],
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
the RMS, :func:`ccjax.experiments.sweeps.sampling_error`), in the units of ``ours``."""


@dataclass
class Reproduction:
    """Our value, the thesis' value and their relative difference per (method, column)."""

    table: str
    rows: list[dict]

    def report(self) -> Report:
        """The rows as a :class:`Report`: the cells, then the ±10/15/20 % bands and the orderings."""
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
        title = [f"Table {self.table}: ours vs thesis (RGB-valued errors in thesis units, white = 255)"]
        return Report(self.rows, REPRODUCTION_COLUMNS, metadata={"table": self.table}, title=title, footer=footer)

    def to_json(self) -> str:
        return self.report().to_json()

    def to_csv(self) -> str:
        return self.report().to_csv()

    def text(self) -> str:
        return self.report().text()

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
        table: a table id with a protocol in :data:`PROTOCOLS` (``"4.2"``, ``"4.3"``, ``"4.4"``, ...).
        world: normally :meth:`World.barnard1999`.
        methods: labels (default: every method of the table that ccjax registers).
        n_scenes: scenes per condition (1000 in the thesis).
        key: PRNG key (default ``jax.random.key(0)``).
        progress: show a progress bar.

    Returns:
        A :class:`Reproduction`; ``relative_difference = ours / thesis - 1``; ``sampling_error`` is
        the standard error of ``ours`` over the scenes (delta method for the RMS, see
        :func:`ccjax.experiments.sweeps.sampling_error`), in the units of ``ours``.
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
    return Reproduction(table=table, rows=rows)
