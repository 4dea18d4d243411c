"""The result of a sweep: per-scene errors per method and surface count, their summaries and
sampling errors, and their reports (Barnard 1999 §4.2, §4.7)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ccjax import metrics
from ccjax.estimators import base
from ccjax.experiments.reports import Column, Report
from ccjax.runs.engine import STATISTICS

STATUS_SUMMARIES = ("relaxed", "fell_back")
"""Per-scene status shares of :meth:`SweepResult.status_fraction`: ``relaxed`` is
:attr:`Status.RELAXED <ccjax.estimators.base.Status>` (the method's answer broke a constraint and
the nearest admissible one is given, e.g. gamut mapping's relaxed constraints, thesis §4.3.2);
``fell_back`` is ``NO_DATA`` or ``EMPTY_SET`` (the model's fallback light is the answer)."""


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


@dataclass
class SweepResult:
    """Per-scene errors of a sweep and their summaries.

    Attributes:
        methods: labels in order.
        surfaces: numbers of surfaces in order.
        n_scenes: scenes per number of surfaces.
        errors: ``errors[method][surfaces][statistic] -> (n_scenes,)`` NumPy arrays (unit scale),
            with ``"ok"`` booleans; statistics that do not apply to a method are absent.
        fits_from_cache, fits_fitted: how many labels were read from the disk cache of fits
            (:func:`ccjax.runs.store.fit_with_source`) and how many were fitted (methods given as
            models count in neither).
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
