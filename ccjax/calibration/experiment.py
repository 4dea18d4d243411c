"""The chapter-3 experiments (Barnard 1999 §3.5-3.6) end to end: the synthetic experiment with a
known camera behind ``ccjax calibrate --synthetic``.

Table 3.1 and the held-out check live in :mod:`~ccjax.calibration.table`, the robustness experiment
in :mod:`~ccjax.calibration.robustness`, the plots in :mod:`~ccjax.calibration.plots`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ccjax.calibration._batch import CrossValidation
from ccjax.calibration._plan import DEFAULT_SMOOTHNESS
from ccjax.calibration._synthetic import LightChoice, SyntheticCalibration
from ccjax.calibration.table import (
    BLACK_SUBTRACTED,
    IGNORE_F,
    JOINT,
    PSEUDO_INVERSE,
    PSEUDO_INVERSE_POSITIVE,
    CalibrationTable,
    HeldOut,
    calibration_table,
    held_out,
)


@dataclass
class SyntheticReport:
    """Table 3.1, the held-out check, the noise-model fit and the acceptance numbers for one
    synthetic experiment with a known camera."""

    data: SyntheticCalibration
    table: CalibrationTable
    held_out: HeldOut
    noise_fit: tuple[np.ndarray, np.ndarray]  # fitted (gain, floor) per channel, unit scale
    cross_validation: CrossValidation | None = None

    def checks(self) -> dict[str, float]:
        """The numbers the thesis' claims are checked with (fractions unless stated)."""
        joint = self.table.row(JOINT)
        pi = self.table.row(PSEUDO_INVERSE)
        pip = self.table.row(PSEUDO_INVERSE_POSITIVE)
        ignore = self.table.row(IGNORE_F)
        black = self.table.row(BLACK_SUBTRACTED)
        lin = joint.fit.fitted_linearisation()
        t = self.data.linearisation
        return {
            "curve_error_max": float(joint.truth_scores()[0].max()),
            "curve_error_pseudo_inverse_min": float(pi.truth_scores()[0].min()),
            "curve_error_pseudo_inverse_positive_min": float(pip.truth_scores()[0].min()),
            "rms_relative_error": joint.errors["rms_relative"],
            "noise_level": self.data.noise_level,
            "error_over_noise": joint.errors["rms_relative"] / self.data.noise_level,
            "held_out_proposed": self.held_out.errors[JOINT],
            "held_out_pseudo_inverse": self.held_out.errors[PSEUDO_INVERSE],
            "held_out_pseudo_inverse_positive": self.held_out.errors[PSEUDO_INVERSE_POSITIVE],
            "rg_vs_truth_joint": joint.truth_scores()[1],
            "rg_vs_truth_ignoring_F": ignore.truth_scores()[1],
            "rg_vs_truth_black_subtracted": black.truth_scores()[1],
            "a0_relative_error_max": float(np.max(np.abs(np.asarray(lin.a0) / np.asarray(t.a0) - 1))),
            "a1_relative_error_max": float(np.max(np.abs(np.asarray(lin.a1) / np.asarray(t.a1) - 1))),
        }

    def text(self) -> str:
        c = self.checks()
        curve = 100 * self.table.row(JOINT).truth_scores()[0]
        gain, floor = self.noise_fit
        data = self.data
        lines = [
            f"synthetic calibration: camera {data.camera}; 24 ColorChecker patches x {len(data.lights)} lights "
            f"({data.light_source}); {data.n_usable} of {len(data.usable)} usable after clipping",
            f"  lights: {', '.join(data.lights)}",
            *([f"  note: {data.light_note}"] if data.light_note else []),
            self.table.text(),
            "",
            self.held_out.text(),
            "",
            "checks against the truth:",
            f"  proposed fit, curve error (RMS over wavelengths, % of peak): "
            f"R {curve[0]:.2f}  G {curve[1]:.2f}  B {curve[2]:.2f}   "
            f"(pseudo-inverse >= {100 * c['curve_error_pseudo_inverse_min']:.1f}, "
            f"with positivity >= {100 * c['curve_error_pseudo_inverse_positive_min']:.1f})",
            f"  proposed fit, RMS relative response error {100 * c['rms_relative_error']:.3f} % = "
            f"{c['error_over_noise']:.2f} x the noise level {100 * c['noise_level']:.3f} %",
            f"  held-out half: proposed {100 * c['held_out_proposed']:.3f} %, "
            f"pseudo-inverse {100 * c['held_out_pseudo_inverse']:.3f} %, "
            f"pseudo-inverse with positivity {100 * c['held_out_pseudo_inverse_positive']:.3f} %",
            f"  (r,g) error of predictions vs the noise-free linear responses: "
            f"joint F fit {c['rg_vs_truth_joint']:.4f}, F ignored {c['rg_vs_truth_ignoring_F']:.4f}, "
            f"camera black subtracted {c['rg_vs_truth_black_subtracted']:.4f}",
            f"  linearisation recovered: a0 within {100 * c['a0_relative_error_max']:.2f} %, "
            f"a1 within {100 * c['a1_relative_error_max']:.2f} %",
            f"  noise model from 100 repeats of 24 windows x 8 levels: "
            f"gain {[f'{v:.3e}' for v in gain]} (true {data.noise_gain:.3e}), "
            f"floor {[f'{v:.3e}' for v in floor]} (true {data.noise_floor:.3e})",
        ]
        if self.cross_validation is not None:
            lines += ["", self.cross_validation.table()]
        return "\n".join(lines)


def noise_experiment(gain: float, floor: float, *, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The thesis' noise measurement (Fig. 3.1) for a known model: 100 repeats of 24 windows at 8
    intensity levels per channel (unit scale), fitted with :func:`fit_noise_model`."""
    from ccjax.calibration._noise import fit_noise_model, synthetic_repeats

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
    lights: LightChoice = "auto",
) -> SyntheticReport:
    """The thesis' calibration experiment with a known camera (Barnard 1999 §3.5–3.6), end to end.

    Arguments:
        camera: the true camera (a name, a :class:`~ccjax.camera.Camera` or a ``(101, 3)`` array).
        seed: seed of the data set, the held-out split and the noise experiment.
        smoothness: lambda of every fit (default :data:`DEFAULT_SMOOTHNESS`); ignored with ``cv``.
        cv: choose lambda by five-fold cross-validation.
        exp_rate: C of the linearisation per channel, or ``None`` to search it.
        data_dir: external data directory (SFU lights, Sony curves).
        lights: the light set, see :func:`~ccjax.calibration._synthetic.calibration_lights`.

    Returns:
        A :class:`SyntheticReport`; its :meth:`~SyntheticReport.text` names the camera and the
        lights used, and says why when the SFU lights were not available.
    """
    from ccjax.calibration._batch import fit_sensors_cv
    from ccjax.calibration._synthetic import synthetic_calibration

    data = synthetic_calibration(camera, seed=seed, data_dir=data_dir, lights=lights)
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
        exp_rate=table.row(JOINT).fit.fitted_linearisation().exp_rate,
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
