"""Experiments: synthetic sweeps, the thesis tables' protocols, reports, plots, camera studies.

* :mod:`ccjax.experiments.sweeps` -- sweeps over synthetic scenes (Barnard 1999 §4.7), a client of
  the engine (:mod:`ccjax.runs.synthetic`: chunking, padding, compile-ahead, sharding);
* :mod:`ccjax.experiments.sweep_results` -- :class:`SweepResult`: per-scene errors, summaries,
  sampling errors;
* :mod:`ccjax.experiments.table_protocols` -- the thesis tables behind ``ccjax reproduce`` (each
  condition a synthetic source of the same engine);
* :mod:`ccjax.experiments.reports` -- the tidy-rows :class:`Report` (text, CSV, JSON);
* :mod:`ccjax.experiments.plots` -- error versus number of surfaces (:func:`plot_sweep`), world chromaticities;
* camera studies (:mod:`ccjax.experiments._cameras`) -- the camera list, the SFU-321 camera check, the
  sharpness study and the ground truth's check against a camera (:func:`curve_check`).

The chapter-specific experiments (``chapter5``, ``indexing``) and ``pretraining`` (the learning
curve with and without pretraining from spectra) are submodules imported on their own
(``from ccjax.experiments import chapter5``), not from here, so importing this package stays
cheap. Photo evaluation (folders of photographs with ground truth) is :mod:`ccjax.evaluation`.
"""

from ccjax.evaluation.camera_check import CurveCheck, curve_check
from ccjax.experiments._cameras import (
    STUDY_METHODS,
    SharpeningStudy,
    camera_listing,
    plot_curve_check,
    sfu321_check,
    sharpening_study,
)
from ccjax.experiments.plots import plot, plot_sweep, plot_world  # plot: plot_sweep's deprecated alias
from ccjax.experiments.reports import Column, Report
from ccjax.experiments.sweep_results import SweepResult
from ccjax.experiments.sweeps import (
    is_registered,
    require_surface_estimator,
    resolve_methods,
    runnable_methods,
    sweep,
    weights_ready,
)
from ccjax.experiments.table_protocols import BASIC_COLUMNS, PROTOCOLS, Condition, Reproduction, reproduce

__all__ = [
    "BASIC_COLUMNS",
    "PROTOCOLS",
    "STUDY_METHODS",
    "Column",
    "Condition",
    "CurveCheck",
    "Report",
    "Reproduction",
    "SharpeningStudy",
    "SweepResult",
    "camera_listing",
    "curve_check",
    "is_registered",
    "plot",
    "plot_curve_check",
    "plot_sweep",
    "plot_world",
    "reproduce",
    "require_surface_estimator",
    "resolve_methods",
    "runnable_methods",
    "sfu321_check",
    "sharpening_study",
    "sweep",
    "weights_ready",
]
