"""Calibrate a camera from ColorChecker measurements (Barnard 1999 ch. 3) with the Python API.

Generates the thesis' experiment for a known camera, writes it as a calibration file, reads it
back, fits sensors and the linearisation F jointly, and compares with the truth and with the
pseudo-inverse. Run: python examples/calibrate_synthetic.py [CAMERA] [--quick]

The run is one calibration experiment (a few hundred measurements, one joint fit); ``--quick`` runs
it unchanged (it is already a smoke test's size) and exists so every example takes the flag.
"""

import argparse
import tempfile

import numpy as np

from ccjax import calibration as cal

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("camera", nargs="?", default="Canon EOS 5D Mark II")
parser.add_argument("--quick", action="store_true", help="the same run (already small)")
camera = parser.parse_args().camera
truth = cal.synthetic_calibration(camera, seed=0)
print(f"{camera}: {truth.n_usable} usable measurements ({truth.light_source}), noise {100 * truth.noise_level:.2f} %")
if truth.light_note:
    print(f"note: {truth.light_note}")

with tempfile.NamedTemporaryFile(suffix=".csv") as f:
    cal.write_calibration_csv(f.name, *truth.usable_data())
    data = cal.read_calibration_csv(f.name)

# The thesis' method: relative error, positivity, smoothness, F(x) = x - a0 - a1 exp(-C (x - b))
# fitted jointly (b = camera black given, C searched per channel).
fit = cal.fit_sensors(data.spectra, data.responses, linearisation="exp", black=10.0)
print(f"solver: {fit.status.solver}; converged {np.asarray(fit.status.converged).tolist()}")
F = fit.fitted_linearisation()
print(
    f"fitted F: a0 = {np.round(F.a0, 2).tolist()}, a1 = {np.round(F.a1, 2).tolist()}, "
    f"C = {np.round(F.exp_rate, 3).tolist()} (true 12, 4, 0.15)"
)
print(
    f"RMS relative error {100 * float(fit.errors.rms_relative):.2f} %, curve error vs truth "
    f"{np.round(100 * cal.curve_error(fit.sensors, truth.sensors), 2).tolist()} % of peak"
)

baseline = cal.pseudo_inverse(data.spectra, np.asarray(fit.linear))
print(
    f"pseudo-inverse: RMS relative error {100 * float(baseline.errors.rms_relative):.2f} %, curve error "
    f"{np.round(100 * cal.curve_error(baseline.sensors, truth.sensors), 1).tolist()} % of peak"
)

# The fitted camera plugs into the rest of ccjax (e.g. ccjax.World.default(camera=fit.camera)).
print(fit.camera.name, fit.camera.sensors.shape)
