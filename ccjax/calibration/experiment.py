"""The chapter-3 experiments: Table 3.1, held-out checks, the robustness experiment (Fig. 3.6), plots.

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

from ccjax.calibration.batch import evaluate_batch, fit_subsets, random_subsets
from ccjax.calibration.fitting import (
    DEFAULT_SMOOTHNESS,
    SensorFit,
    curve_error,
    fit_errors,
    fit_sensors,
    pseudo_inverse,
    support_of,
)
from ccjax.calibration.synthetic import SyntheticCalibration
from ccjax.spectra import WAVELENGTHS, chromaticity

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
            line = f"{r.label:<50}{100 * e['rms_relative']:11.2f}{e['rms_absolute']:10.2f}{e['rms_r']:9.4f}{e['rms_g']:9.4f}"
            if truth:
                c = 100 * r.curve_error
                line += f"{c[0]:12.1f}{c[1]:9.1f}{c[2]:9.1f}{r.rg_error_vs_truth:17.4f}"
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
    d = chromaticity(predicted) - chromaticity(truth)
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
    rates = joint.linearisation.exp_rate
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
    notes = [
        f"linearisation fitted by the first row: a0 = {np.round(joint.linearisation.a0, 3).tolist()}, "
        f"a1 = {np.round(joint.linearisation.a1, 3).tolist()}, C = {np.round(rates, 4).tolist()}, b = {black:g}",
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
            f"held-out check: fit on {len(self.train_rows)} measurements, RMS relative error on the other {len(self.test_rows)}"
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


ROBUSTNESS_SIZES = (400, 200, 100, 50, 25, 15)


@dataclass
class Robustness:
    """Fig. 3.6: mean RMS relative error on all measurements of fits to random subsets."""

    sizes: tuple[int, ...]
    n_subsets: int
    errors: dict[str, np.ndarray]  # label -> (len(sizes), n_subsets) RMS relative error
    converged: dict[str, float]  # label -> fraction of fits whose solver converged

    def mean(self) -> dict[str, np.ndarray]:
        return {label: e.mean(axis=1) for label, e in self.errors.items()}

    def text(self) -> str:
        head = f"{'method (mean RMS relative error %, all measurements)':<52}" + "".join(f"{n:>9}" for n in self.sizes)
        lines = [f"robustness (Fig. 3.6): {self.n_subsets} random subsets per size", head]
        for label, m in self.mean().items():
            lines.append(f"{label:<52}" + "".join(f"{100 * v:9.2f}" for v in m))
        lines.append("degradation (error at the smallest size / error at the largest):")
        for label, m in self.mean().items():
            lines.append(
                f"  {label:<50}{m[-1] / m[0]:9.1f}x   (solver converged in {100 * self.converged[label]:.0f} % of fits)"
            )
        return "\n".join(lines)

    def to_json(self) -> str:
        return json.dumps(
            {
                "sizes": list(self.sizes),
                "n_subsets": self.n_subsets,
                "mean_rms_relative": {k: v.tolist() for k, v in self.mean().items()},
            },
            indent=2,
        )


def robustness(
    spectra,
    raw,
    *,
    black: float = 0.0,
    exp_rate=None,
    smoothness: float = DEFAULT_SMOOTHNESS,
    sizes=ROBUSTNESS_SIZES,
    n_subsets: int = 100,
    seed: int = 0,
    chunk_size: int = 20,
    progress=None,
) -> Robustness:
    """The robustness experiment of §3.6 (Fig. 3.6).

    Every method of Table 3.1 is fitted to ``n_subsets`` random subsets of each size and scored by
    its RMS relative error on all measurements; joint fits use their own F, the linearised-data fits
    the full-data joint fit's F (as in the thesis). The range constraint comes from the full-data fit
    (optimistic, as the thesis notes), and so does C.
    """
    spectra = np.asarray(spectra, dtype=np.float64)
    raw = np.asarray(raw, dtype=np.float64)
    full = fit_sensors(spectra, raw, smoothness=smoothness, linearisation="exp", black=black, exp_rate=exp_rate)
    rates = full.linearisation.exp_rate
    support = support_of(np.asarray(full.sensors))
    linear = np.asarray(full.linear, dtype=np.float64)
    usable = np.all(linear > 0, axis=1)
    methods = {
        PSEUDO_INVERSE: (linear, dict(smoothness=0.0, error="absolute", positive=False)),
        NO_POSITIVITY: (linear, dict(smoothness=smoothness, positive=False)),
        PSEUDO_INVERSE_POSITIVE: (linear, dict(smoothness=0.0, error="absolute", positive=True)),
        LINEARISED: (linear, dict(smoothness=smoothness)),
        LINEARISED_RANGE: (linear, dict(smoothness=smoothness, support=support)),
        JOINT: (raw, dict(smoothness=smoothness, linearisation="exp", black=black, exp_rate=rates)),
        JOINT_RANGE: (
            raw,
            dict(smoothness=smoothness, linearisation="exp", black=black, exp_rate=rates, support=support),
        ),
    }
    errors = {label: np.zeros((len(sizes), n_subsets)) for label in methods}
    converged = {label: 0.0 for label in methods}
    for i, size in enumerate(sizes):
        masks = random_subsets(len(spectra), size, n_subsets, seed=seed + i, within=usable)
        for label, (responses, options) in methods.items():
            fits = fit_subsets(spectra, responses, masks, chunk_size=chunk_size, **options)
            scored = evaluate_batch(fits, spectra, responses, usable, linearised="linearisation" in options)
            errors[label][i] = np.asarray(scored.rms_relative)
            converged[label] += float(np.mean(np.asarray(fits.converged))) / len(sizes)
            if progress is not None:
                progress(size, label)
    return Robustness(sizes=tuple(sizes), n_subsets=n_subsets, errors=errors, converged=converged)


# ---------------------------------------------------------------------------------------------
# plots


def plot_sensors(table: CalibrationTable, path: str, *, truth: np.ndarray | None = None, title: str = "") -> None:
    """Fitted curves (Figs. 3.3–3.5): the proposed joint fit, the pseudo-inverse and the
    pseudo-inverse with positivity, each against the truth when it is known."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = (JOINT, PSEUDO_INVERSE_POSITIVE, PSEUDO_INVERSE)
    fig, axes = plt.subplots(1, 3, figsize=(16, 4.6))
    colours = ("tab:red", "tab:green", "tab:blue")
    for ax, label in zip(axes, panels):
        sensors = np.asarray(table.row(label).fit.sensors, dtype=np.float64)
        for k, colour in enumerate(colours):
            ax.plot(WAVELENGTHS, sensors[:, k], color=colour, lw=1.4, label=f"fitted {'RGB'[k]}")
            if truth is not None:
                ax.plot(WAVELENGTHS, truth[:, k], color=colour, lw=1.0, ls="--", label=f"true {'RGB'[k]}")
        if truth is not None and label != JOINT:
            top = 1.3 * truth.max()
            low = min(-0.3 * truth.max(), sensors.min())
            ax.set_ylim(max(low, -3 * truth.max()), max(top, min(sensors.max(), 4 * truth.max())))
        ax.axhline(0, color="k", lw=0.5)
        ax.set_title(label, fontsize=10)
        ax.set_xlabel("wavelength (nm)")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8, ncol=2)
    fig.suptitle(title or "fitted sensor curves")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_robustness(result: Robustness, path: str, *, title: str = "") -> None:
    """Fig. 3.6: log of RMS relative error against log of the number of measurements fitted."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 5.5))
    for label, m in result.mean().items():
        style = dict(lw=2.5, color="k" if label == JOINT else "0.35") if label in (JOINT, JOINT_RANGE) else dict(lw=1.3)
        ax.plot(result.sizes, 100 * m, marker="o", label=label, **style)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xticks(result.sizes, [str(n) for n in result.sizes])
    ax.minorticks_off()
    ax.set_xlabel("measurements fitted (log)")
    ax.set_ylabel("RMS relative error on all measurements, % (log)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    ax.set_title(title or f"robustness: {result.n_subsets} random subsets per size")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ---------------------------------------------------------------------------------------------
# the synthetic experiment end to end (``ccjax calibrate --synthetic``)


@dataclass
class SyntheticReport:
    """Table 3.1, the held-out check, the noise-model fit and the acceptance numbers for one
    synthetic experiment with a known camera."""

    data: SyntheticCalibration
    table: CalibrationTable
    held_out: HeldOut
    noise_fit: tuple[np.ndarray, np.ndarray]  # fitted (gain, floor) per channel, unit scale
    cross_validation: object | None = None

    def checks(self) -> dict[str, float]:
        """The numbers the thesis' claims are checked with (fractions unless stated)."""
        joint = self.table.row(JOINT)
        pi = self.table.row(PSEUDO_INVERSE)
        pip = self.table.row(PSEUDO_INVERSE_POSITIVE)
        ignore = self.table.row(IGNORE_F)
        black = self.table.row(BLACK_SUBTRACTED)
        lin = joint.fit.linearisation
        t = self.data.linearisation
        return {
            "curve_error_max": float(joint.curve_error.max()),
            "curve_error_pseudo_inverse_min": float(pi.curve_error.min()),
            "curve_error_pseudo_inverse_positive_min": float(pip.curve_error.min()),
            "rms_relative_error": joint.errors["rms_relative"],
            "noise_level": self.data.noise_level,
            "error_over_noise": joint.errors["rms_relative"] / self.data.noise_level,
            "held_out_proposed": self.held_out.errors[JOINT],
            "held_out_pseudo_inverse": self.held_out.errors[PSEUDO_INVERSE],
            "held_out_pseudo_inverse_positive": self.held_out.errors[PSEUDO_INVERSE_POSITIVE],
            "rg_vs_truth_joint": joint.rg_error_vs_truth,
            "rg_vs_truth_ignoring_F": ignore.rg_error_vs_truth,
            "rg_vs_truth_black_subtracted": black.rg_error_vs_truth,
            "a0_relative_error_max": float(np.max(np.abs(np.asarray(lin.a0) / np.asarray(t.a0) - 1))),
            "a1_relative_error_max": float(np.max(np.abs(np.asarray(lin.a1) / np.asarray(t.a1) - 1))),
        }

    def text(self) -> str:
        c = self.checks()
        joint = self.table.row(JOINT)
        gain, floor = self.noise_fit
        lines = [
            f"synthetic calibration: camera {self.data.camera}; 24 ColorChecker patches x {len(self.data.lights)} lights "
            f"({self.data.light_source}); {self.data.n_usable} of {len(self.data.usable)} usable after clipping",
            self.table.text(),
            "",
            self.held_out.text(),
            "",
            "checks against the truth:",
            f"  proposed fit, curve error (RMS over wavelengths, % of peak): R {100 * joint.curve_error[0]:.2f}  "
            f"G {100 * joint.curve_error[1]:.2f}  B {100 * joint.curve_error[2]:.2f}   (pseudo-inverse >= "
            f"{100 * c['curve_error_pseudo_inverse_min']:.1f}, with positivity >= {100 * c['curve_error_pseudo_inverse_positive_min']:.1f})",
            f"  proposed fit, RMS relative response error {100 * c['rms_relative_error']:.3f} % = {c['error_over_noise']:.2f} x the noise level "
            f"{100 * c['noise_level']:.3f} %",
            f"  held-out half: proposed {100 * c['held_out_proposed']:.3f} %, pseudo-inverse {100 * c['held_out_pseudo_inverse']:.3f} %, "
            f"pseudo-inverse with positivity {100 * c['held_out_pseudo_inverse_positive']:.3f} %",
            f"  (r,g) error of predictions vs the noise-free linear responses: joint F fit {c['rg_vs_truth_joint']:.4f}, "
            f"F ignored {c['rg_vs_truth_ignoring_F']:.4f}, camera black subtracted {c['rg_vs_truth_black_subtracted']:.4f}",
            f"  linearisation recovered: a0 within {100 * c['a0_relative_error_max']:.2f} %, a1 within {100 * c['a1_relative_error_max']:.2f} %",
            f"  noise model from 100 repeats of 24 windows x 8 levels: gain {[f'{v:.3e}' for v in gain]} (true {self.data.noise_gain:.3e}), "
            f"floor {[f'{v:.3e}' for v in floor]} (true {self.data.noise_floor:.3e})",
        ]
        if self.cross_validation is not None:
            lines += ["", self.cross_validation.table()]
        return "\n".join(lines)


def noise_experiment(gain: float, floor: float, *, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The thesis' noise measurement (Fig. 3.1) for a known model: 100 repeats of 24 windows at 8
    intensity levels per channel (unit scale), fitted with :func:`fit_noise_model`."""
    from ccjax.calibration.noise import fit_noise_model, synthetic_repeats

    levels = np.repeat(np.geomspace(0.01, 0.9, 8), 24)
    samples = np.stack([synthetic_repeats(levels, gain=gain, floor=floor, seed=seed + k) for k in range(3)], axis=-1)
    model = fit_noise_model(samples)
    return np.asarray(model.gain, dtype=np.float64), np.asarray(model.floor, dtype=np.float64)


def synthetic_experiment(
    camera="Sony DXC-930",
    *,
    seed: int = 0,
    smoothness: float | None = None,
    cv: bool = False,
    exp_rate=None,
    data_dir=None,
) -> SyntheticReport:
    """The thesis' calibration experiment with a known camera (§3.5–3.6), end to end."""
    from ccjax.calibration.batch import fit_sensors_cv
    from ccjax.calibration.synthetic import synthetic_calibration

    data = synthetic_calibration(camera, seed=seed, data_dir=data_dir)
    black = data.linearisation.black[0]
    spectra, raw = data.usable_data()
    cross_validation = None
    if cv:
        _, cross_validation = fit_sensors_cv(
            spectra, raw, linearisation="exp", black=black, exp_rate=data.linearisation.exp_rate[0], seed=seed
        )
        smoothness = cross_validation.best
    smoothness = DEFAULT_SMOOTHNESS if smoothness is None else smoothness
    table = calibration_table(
        spectra,
        raw,
        black=black,
        exp_rate=exp_rate,
        smoothness=smoothness,
        truth=data,
        truth_rows=np.flatnonzero(data.usable),
    )
    check = held_out(
        spectra,
        raw,
        black=black,
        exp_rate=table.row(JOINT).fit.linearisation.exp_rate,
        smoothness=smoothness,
        seed=seed,
    )
    return SyntheticReport(
        data=data,
        table=table,
        held_out=check,
        noise_fit=noise_experiment(data.noise_gain, data.noise_floor, seed=seed),
        cross_validation=cross_validation,
    )
