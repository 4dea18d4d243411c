"""Camera calibration (Barnard 1999 chapter 3): sensor curves, linearisation and noise model.

* :func:`fit_sensors` — smooth, constrained, relative-error least squares (§3.4), optionally fitting
  the linearisation F jointly (eqs. 3.14–3.16); jaxopt solvers, vmapped over channels.
* :func:`fit_sensors_cv` — the smoothness chosen by cross-validation.
* :func:`pseudo_inverse` — the baselines of Table 3.1 (plain, and with positivity).
* :func:`fit_noise_model` — variance = a * mean + floor from repeated measurements (§3.4, Fig. 3.1).
* :func:`synthetic_calibration` — the thesis' experiment with a known camera (§3.5).
* :func:`read_calibration_csv` — calibration data from a file (``ccjax calibrate``).
* :func:`fit_sensors_batch` / :func:`fit_subsets` — many fits as one vmapped program.
* :mod:`ccjax.calibration.experiment` — Table 3.1, the held-out check, the robustness experiment
  (Fig. 3.6) and the plots behind ``ccjax calibrate``.
"""

from ccjax.calibration._batch import (
    BatchFit,
    CrossValidation,
    evaluate_batch,
    fit_sensors_batch,
    fit_sensors_cv,
    fit_subsets,
    random_subsets,
)
from ccjax.calibration._files import (
    CalibrationData,
    CalibrationFileError,
    read_calibration_csv,
    write_calibration_csv,
    write_sensors_csv,
)
from ccjax.calibration._kernel import second_difference
from ccjax.calibration._noise import NoiseModel, fit_noise_model, synthetic_repeats
from ccjax.calibration._plan import DEFAULT_SMOOTHNESS
from ccjax.calibration._synthetic import SyntheticCalibration, has_external_lights, synthetic_calibration
from ccjax.calibration.errors import FitErrors, curve_error, fit_errors, support_of
from ccjax.calibration.fitting import FitStatus, SensorFit, fit_sensors, pseudo_inverse
from ccjax.calibration.linearisation import Linearisation, apply_linearisation, invert_linearisation

__all__ = [
    "DEFAULT_SMOOTHNESS",
    "BatchFit",
    "CalibrationData",
    "CalibrationFileError",
    "CrossValidation",
    "FitErrors",
    "FitStatus",
    "Linearisation",
    "NoiseModel",
    "SensorFit",
    "SyntheticCalibration",
    "apply_linearisation",
    "curve_error",
    "evaluate_batch",
    "fit_errors",
    "fit_noise_model",
    "fit_sensors",
    "fit_sensors_batch",
    "fit_sensors_cv",
    "fit_subsets",
    "has_external_lights",
    "invert_linearisation",
    "pseudo_inverse",
    "random_subsets",
    "read_calibration_csv",
    "second_difference",
    "support_of",
    "synthetic_calibration",
    "synthetic_repeats",
    "write_calibration_csv",
    "write_sensors_csv",
]
