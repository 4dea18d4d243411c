"""The robustness experiment of Barnard 1999 §3.6 (Fig. 3.6): fits to random subsets of the data."""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np

from ccjax.calibration._batch import evaluate_batch, fit_subsets, random_subsets
from ccjax.calibration._plan import DEFAULT_SMOOTHNESS
from ccjax.calibration.errors import support_of
from ccjax.calibration.fitting import fit_sensors
from ccjax.calibration.table import (
    JOINT,
    JOINT_RANGE,
    LINEARISED,
    LINEARISED_RANGE,
    NO_POSITIVITY,
    PSEUDO_INVERSE,
    PSEUDO_INVERSE_POSITIVE,
)

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
    rates = full.fitted_linearisation().exp_rate
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
