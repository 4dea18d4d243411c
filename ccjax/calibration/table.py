"""Table 3.1 and the held-out check (Barnard 1999 §3.6).

:func:`calibration_table` fits the seven methods of Table 3.1 (the first two fit F and the sensors
jointly; the other five use the data linearised by the first fit's F) plus three rows that show
what F is worth (offset only, camera black subtracted, F ignored). With a synthetic data set it also
scores every fit against the truth: curve error (RMS over wavelengths, % of peak) and chromaticity
error of the predictions against the noise-free linear responses.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np

from ccjax._colour import rg_numpy
from ccjax.calibration._plan import DEFAULT_SMOOTHNESS
from ccjax.calibration._synthetic import SyntheticCalibration
from ccjax.calibration.errors import curve_error, fit_errors, support_of
from ccjax.calibration.fitting import SensorFit, fit_sensors, pseudo_inverse

JOINT = "New fitting method with linearity fitting"
JOINT_RANGE = "New method with linearity fitting and range"
PSEUDO_INVERSE = "Pseudo inverse method on linearized data"
PSEUDO_INVERSE_POSITIVE = "Pseudo inverse method positivity constraints"
NO_POSITIVITY = "New method on linearized data without positivity"
LINEARISED = "New method on linearized data"
LINEARISED_RANGE = "New method on linearized data with range"
OFFSET = "New method with offset fitting (eq. 3.15)"
BLACK_SUBTRACTED = "New method, camera black subtracted (F = x - b)"
IGNORE_F = "New method ignoring F (raw values as linear)"

THESIS_ROWS = (JOINT, JOINT_RANGE, PSEUDO_INVERSE, PSEUDO_INVERSE_POSITIVE, NO_POSITIVITY, LINEARISED, LINEARISED_RANGE)
EXTRA_ROWS = (OFFSET, BLACK_SUBTRACTED, IGNORE_F)

THESIS_TABLE_3_1 = {
    # RMS relative error (%), RMS absolute error (0-255), RMS error in r, in g; 612 measurements
    JOINT: (1.02, 1.09, 0.0020, 0.0017),
    JOINT_RANGE: (1.24, 1.11, 0.0029, 0.0023),
    PSEUDO_INVERSE: (0.93, 0.98, 0.0071, 0.0014),
    PSEUDO_INVERSE_POSITIVE: (1.21, 1.02, 0.0023, 0.0015),
    NO_POSITIVITY: (1.28, 1.05, 0.0025, 0.0018),
    LINEARISED: (1.39, 1.03, 0.0024, 0.0018),
    LINEARISED_RANGE: (1.55, 1.13, 0.0027, 0.0023),
}


@dataclass
class Row:
    """One fitted method: its fit, in-sample errors and (synthetic data) errors against the truth."""

    label: str
    fit: SensorFit
    errors: dict[str, float]
    curve_error: np.ndarray | None = None  # (3,) fraction of peak
    rg_error_vs_truth: float | None = None

    def truth_scores(self) -> tuple[np.ndarray, float]:
        """``(curve_error (3,), rg_error_vs_truth)``: only rows of a synthetic data set have them."""
        if self.curve_error is None or self.rg_error_vs_truth is None:
            raise ValueError(f"{self.label}: not scored against a truth (the data set is not synthetic)")
        return self.curve_error, self.rg_error_vs_truth


@dataclass
class CalibrationTable:
    """Table 3.1 for one data set."""

    rows: list[Row]
    n_measurements: int
    smoothness: float
    support: np.ndarray
    noise_level: float | None = None
    notes: list[str] = field(default_factory=list)

    def row(self, label: str) -> Row:
        return next(r for r in self.rows if r.label == label)

    def text(self) -> str:
        truth = self.rows[0].curve_error is not None
        head = f"{'Fitting method':<50}{'rel. err %':>11}{'abs. err':>10}{'r err':>9}{'g err':>9}"
        if truth:
            head += f"{'curve err % of peak (R G B)':>30}{'rg err vs truth':>17}"
        lines = [f"Table 3.1 ({self.n_measurements} measurements, smoothness {self.smoothness:g})", head]
        for r in self.rows:
            e = r.errors
            line = f"{r.label:<50}{100 * e['rms_relative']:11.2f}{e['rms_absolute']:10.2f}"
            line += f"{e['rms_r']:9.4f}{e['rms_g']:9.4f}"
            if truth:
                curve, rg_error = r.truth_scores()
                c = 100 * curve
                line += f"{c[0]:12.1f}{c[1]:9.1f}{c[2]:9.1f}{rg_error:17.4f}"
            lines.append(line)
        lines.append("thesis (Sony DXC-930, 612 real measurements):")
        for label, (rel, ab, er, eg) in THESIS_TABLE_3_1.items():
            lines.append(f"  {label:<48}{rel:11.2f}{ab:10.2f}{er:9.4f}{eg:9.4f}")
        lines.extend(self.notes)
        return "\n".join(lines)

    def rms_relative(self) -> dict[str, float]:
        """Method label -> RMS relative error as a fraction (the ``--json`` output)."""
        return {r.label: r.errors["rms_relative"] for r in self.rows}

    def to_json(self) -> str:
        return json.dumps(self.rms_relative(), indent=2)


def _rg_error(predicted: np.ndarray, truth: np.ndarray) -> float:
    """RMS over measurements of the (r,g) distance between predicted and true linear responses."""
    # float64 throughout: the fits' predictions may be float32.
    d = rg_numpy(np.asarray(predicted, np.float64)) - rg_numpy(np.asarray(truth, np.float64))
    return float(np.sqrt(np.mean(np.sum(d**2, axis=-1))))


def calibration_table(
    spectra: np.ndarray,
    raw: np.ndarray,
    *,
    black: float = 0.0,
    exp_rate=None,
    smoothness: float = DEFAULT_SMOOTHNESS,
    truth: SyntheticCalibration | None = None,
    truth_rows: np.ndarray | None = None,
) -> CalibrationTable:
    """Fit every method of Table 3.1 (and the F-ablation rows) to one data set.

    Arguments:
        spectra, raw: ``(M, 101)`` and ``(M, 3)`` usable measurements (raw pixel values).
        black: camera black b (eq. 3.14), pixel units.
        exp_rate: C, or ``None`` to search it.
        smoothness: lambda of every smoothed fit.
        truth, truth_rows: a synthetic data set and the indices of its rows that ``spectra`` holds,
            to score fits against the true curves and noise-free responses.

    Returns:
        A :class:`CalibrationTable`.
    """
    raw = np.asarray(raw, dtype=np.float64)
    spectra = np.asarray(spectra, dtype=np.float64)
    rows: list[tuple[str, SensorFit]] = []
    joint = fit_sensors(
        spectra, raw, smoothness=smoothness, linearisation="exp", black=black, exp_rate=exp_rate, name=JOINT
    )
    support = support_of(np.asarray(joint.sensors))
    rates = joint.fitted_linearisation().exp_rate
    rows.append((JOINT, joint))
    rows.append(
        (
            JOINT_RANGE,
            fit_sensors(
                spectra,
                raw,
                smoothness=smoothness,
                linearisation="exp",
                black=black,
                exp_rate=rates,
                support=support,
                name=JOINT_RANGE,
            ),
        )
    )
    linear = np.asarray(joint.linear, dtype=np.float64)
    positive_rows = np.all(linear > 0, axis=1)
    # Relative fits need positive responses; masked rows keep a placeholder value.
    linear_positive = np.where(positive_rows[:, None], linear, 1.0)
    rows.append((PSEUDO_INVERSE, pseudo_inverse(spectra, linear, name=PSEUDO_INVERSE)))
    rows.append((PSEUDO_INVERSE_POSITIVE, pseudo_inverse(spectra, linear, positive=True, name=PSEUDO_INVERSE_POSITIVE)))
    rows.append(
        (
            NO_POSITIVITY,
            fit_sensors(
                spectra, linear_positive, smoothness=smoothness, positive=False, mask=positive_rows, name=NO_POSITIVITY
            ),
        )
    )
    rows.append(
        (LINEARISED, fit_sensors(spectra, linear_positive, smoothness=smoothness, mask=positive_rows, name=LINEARISED))
    )
    rows.append(
        (
            LINEARISED_RANGE,
            fit_sensors(
                spectra,
                linear_positive,
                smoothness=smoothness,
                support=support,
                mask=positive_rows,
                name=LINEARISED_RANGE,
            ),
        )
    )
    rows.append(
        (OFFSET, fit_sensors(spectra, raw, smoothness=smoothness, linearisation="offset", black=black, name=OFFSET))
    )
    subtracted = raw - black
    above = np.all(subtracted > 0, axis=1)
    rows.append(
        (
            BLACK_SUBTRACTED,
            fit_sensors(
                spectra,
                np.where(above[:, None], subtracted, 1.0),
                smoothness=smoothness,
                mask=above,
                name=BLACK_SUBTRACTED,
            ),
        )
    )
    rows.append(
        (
            IGNORE_F,
            fit_sensors(
                spectra, np.where(raw > 0, raw, 1.0), smoothness=smoothness, mask=np.all(raw > 0, axis=1), name=IGNORE_F
            ),
        )
    )
    out = []
    for label, fit in rows:
        row = Row(label=label, fit=fit, errors=fit.errors.as_dict())
        if truth is not None:
            index = np.arange(len(spectra)) if truth_rows is None else np.asarray(truth_rows)
            row.curve_error = curve_error(np.asarray(fit.sensors), truth.sensors)
            row.rg_error_vs_truth = _rg_error(np.asarray(fit.predicted, dtype=np.float64), truth.linear[index])
        out.append(row)
    first = joint.fitted_linearisation()
    notes = [
        f"linearisation fitted by the first row: a0 = {np.round(first.a0, 3).tolist()}, "
        f"a1 = {np.round(first.a1, 3).tolist()}, C = {np.round(rates, 4).tolist()}, b = {black:g}",
        f"range constraint (main peaks of the first row, nm): {support.tolist()}",
    ]
    if truth is not None:
        t = truth.linearisation
        notes.insert(
            1, f"true linearisation: a0 = {t.a0[0]:g}, a1 = {t.a1[0]:g}, C = {t.exp_rate[0]:g}, b = {t.black[0]:g}"
        )
        notes.append(f"noise level (RMS relative noise of the usable measurements): {100 * truth.noise_level:.2f} %")
    return CalibrationTable(
        rows=out,
        n_measurements=len(spectra),
        smoothness=smoothness,
        support=support,
        noise_level=None if truth is None else truth.noise_level,
        notes=notes,
    )


@dataclass
class HeldOut:
    """Fit on one half, RMS relative error on the other (responses linearised by the train fit's F)."""

    train_rows: np.ndarray
    test_rows: np.ndarray
    errors: dict[str, float]  # label -> held-out RMS relative error (fraction)

    def text(self) -> str:
        lines = [
            f"held-out check: fit on {len(self.train_rows)} measurements, "
            f"RMS relative error on the other {len(self.test_rows)}"
        ]
        lines += [f"  {label:<50}{100 * e:9.2f} %" for label, e in self.errors.items()]
        return "\n".join(lines)


def held_out(
    spectra, raw, *, black: float = 0.0, exp_rate=None, smoothness: float = DEFAULT_SMOOTHNESS, seed: int = 0
) -> HeldOut:
    """The proposed joint fit against the pseudo-inverse baselines on a random half held out.

    The halves are row masks over the full arrays, so the fits reuse the programs compiled for
    the full data set.
    """
    spectra = np.asarray(spectra, dtype=np.float64)
    raw = np.asarray(raw, dtype=np.float64)
    order = np.random.default_rng(seed).permutation(len(spectra))
    train = np.zeros(len(spectra), bool)
    train[order[: len(order) // 2]] = True
    test = ~train
    joint = fit_sensors(
        spectra, raw, smoothness=smoothness, linearisation="exp", black=black, exp_rate=exp_rate, mask=train
    )
    linear = np.asarray(joint.linear, dtype=np.float64)  # every row through the train fit's F
    positive = np.all(linear > 0, axis=1)
    fits = {
        JOINT: joint,
        LINEARISED: fit_sensors(
            spectra, np.where(positive[:, None], linear, 1.0), smoothness=smoothness, mask=train & positive
        ),
        PSEUDO_INVERSE: pseudo_inverse(spectra, linear, mask=train),
        PSEUDO_INVERSE_POSITIVE: pseudo_inverse(spectra, linear, positive=True, mask=train),
    }
    errors = {label: float(fit_errors(fit.predicted, linear, test).rms_relative) for label, fit in fits.items()}
    return HeldOut(train_rows=np.flatnonzero(train), test_rows=np.flatnonzero(test), errors=errors)
