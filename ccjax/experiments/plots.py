"""Figures of the experiments: error versus number of surfaces, and a world's chromaticities.

matplotlib is imported inside each function (with the non-interactive Agg backend), so importing
ccjax never needs it.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ccjax.experiments.results import SweepResult
from ccjax.io.files import write_figure
from ccjax.world import World

STATISTIC_LABELS = {
    "angular": "angular error (degrees)",
    "rg": "(r,g) error",
    "rgb": "RGB error",
    "brightness": "R+G+B error",
    "map_rg": "mapping (r,g) error",
    "map_rgb": "mapping RGB error",
}
"""Axis labels of the per-scene statistics."""


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot(result: SweepResult, path, statistics: Sequence[str] = ("rg", "angular"), summary: str = "rms", title=None):
    """Error versus number of surfaces (log2 x axis, as the figures of Barnard 1999 ch. 4), one panel per statistic.

    Arguments:
        result: a sweep.
        path: the PNG to write (atomically, :func:`ccjax.io.files.write_figure`), or a binary file.
        statistics: one panel per statistic.
        summary: the summary of the per-scene errors (``"rms"`` as in the thesis).
        title: the figure title (default: the scenes per point).
    """
    plt = _pyplot()
    fig, axes = plt.subplots(1, len(statistics), figsize=(5.5 * len(statistics), 4.2), squeeze=False)
    for ax, statistic in zip(axes[0], statistics, strict=False):
        for method in result.methods:
            points = [
                (n, result.value(method, n, statistic, summary))
                for n in result.surfaces
                if statistic in result.errors[method][n]
            ]
            if points:
                xs, ys = zip(*points, strict=True)
                ax.plot(np.log2(xs), ys, marker="o", label=method)
        ax.set_xticks(np.log2(result.surfaces))
        ax.set_xticklabels([str(n) for n in result.surfaces])
        ax.set_xlabel("number of surfaces (log2 scale)")
        ax.set_ylabel(f"{summary.upper()} {STATISTIC_LABELS.get(statistic, statistic)}")
        ax.grid(alpha=0.3)
    handles, names = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, names, fontsize=8, loc="center left", bbox_to_anchor=(1.0, 0.5))
    fig.suptitle(title or f"{result.n_scenes} scenes per point")
    fig.tight_layout()
    try:
        write_figure(fig, path, dpi=120, bbox_inches="tight")
    finally:
        plt.close(fig)


def plot_world(world: World, path) -> None:
    """The training and test illuminants and the reflectances in (r,g) (Barnard 1999 Fig. 4.1).

    Arguments:
        world: the world.
        path: the PNG to write (atomically, :func:`ccjax.io.files.write_figure`), or a binary file.
    """
    from ccjax._colour import rg_numpy

    plt = _pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.8), sharex=True, sharey=True)
    panels = [
        ("training illuminants", np.asarray(world.train_whites), 12),
        ("test illuminants", np.asarray(world.test_whites), 6),
        ("reflectances under the canonical light", np.asarray(world.canonical_rgb), 2),
    ]
    for ax, (title, rgb, size) in zip(axes, panels, strict=True):
        rg = rg_numpy(np.asarray(rgb, np.float64))
        ax.scatter(rg[:, 0], rg[:, 1], s=size, alpha=0.7)
        canon = rg_numpy(np.asarray(world.canonical_white, np.float64))
        ax.scatter([canon[0]], [canon[1]], marker="*", s=120, c="red", label="canonical")
        ax.set_title(f"{title} ({len(rgb)})")
        ax.set_xlabel("r")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("g")
    axes[0].legend()
    fig.suptitle(f"{world.name}: (r,g) chromaticities")
    fig.tight_layout()
    try:
        write_figure(fig, path, dpi=110)
    finally:
        plt.close(fig)
