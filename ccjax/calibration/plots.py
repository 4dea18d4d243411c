"""The plots behind ``ccjax calibrate``: fitted sensor curves (Barnard 1999 Figs. 3.3-3.5) and
the robustness curves (Fig. 3.6)."""

from __future__ import annotations

import numpy as np

from ccjax.calibration.robustness import Robustness
from ccjax.calibration.table import JOINT, JOINT_RANGE, PSEUDO_INVERSE, PSEUDO_INVERSE_POSITIVE, CalibrationTable
from ccjax.io.files import new_figure, write_figure
from ccjax.spectra import WAVELENGTHS


def plot_sensors(table: CalibrationTable, path, *, truth: np.ndarray | None = None, title: str = "") -> None:
    """Fitted curves (Figs. 3.3–3.5): the proposed joint fit, the pseudo-inverse and the
    pseudo-inverse with positivity, each against the truth when it is known.

    Arguments:
        table: the fits of Table 3.1.
        path: the PNG to write (atomically, :func:`ccjax.io.files.write_figure`), or a binary file.
        truth: ``(101, 3)`` true sensors, drawn dashed when known.
        title: the figure title.

    Returns:
        None.
    """
    panels = (JOINT, PSEUDO_INVERSE_POSITIVE, PSEUDO_INVERSE)
    fig = new_figure(figsize=(16, 4.6))
    axes = fig.subplots(1, 3)
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
    write_figure(fig, path, dpi=110)


def plot_robustness(result: Robustness, path, *, title: str = "") -> None:
    """Fig. 3.6: log of RMS relative error against log of the number of measurements fitted.

    Arguments:
        result: the robustness experiment.
        path: the PNG to write (atomically, :func:`ccjax.io.files.write_figure`), or a binary file.
        title: the figure title.

    Returns:
        None.
    """
    fig = new_figure(figsize=(7.5, 5.5))
    ax = fig.subplots()
    for label, m in result.mean().items():
        if label in (JOINT, JOINT_RANGE):  # the proposed methods stand out
            ax.plot(result.sizes, 100 * m, marker="o", label=label, lw=2.5, color="k" if label == JOINT else "0.35")
        else:
            ax.plot(result.sizes, 100 * m, marker="o", label=label, lw=1.3)
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
    write_figure(fig, path, dpi=110)
