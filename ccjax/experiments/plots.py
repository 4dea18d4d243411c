"""Figures of the experiments: error versus number of surfaces (:func:`plot_sweep`, a sweep's
figure), a world's chromaticities, and the per-image errors of an image evaluation.

matplotlib is imported inside each function (with the non-interactive Agg backend), so importing
ccjax never needs it.
"""

from __future__ import annotations

import os
import typing
import warnings
from collections.abc import Sequence

import numpy as np

from ccjax.experiments.sweep_results import SweepResult
from ccjax.io.files import new_figure, write_figure
from ccjax.world import World

if typing.TYPE_CHECKING:  # importing ccjax.experiments stays cheap: evaluation loads on use
    from ccjax.evaluation import ImageResults

STATISTIC_LABELS = {
    "angular": "angular error (degrees)",
    "rg": "(r,g) error",
    "rgb": "RGB error",
    "brightness": "R+G+B error",
    "map_rg": "mapping (r,g) error",
    "map_rgb": "mapping RGB error",
}
"""Axis labels of the per-scene statistics."""


def _finish(fig, path, title: str) -> None:
    """Title, lay out and write a figure (atomically, :func:`ccjax.io.files.write_figure`)."""
    fig.suptitle(title)
    fig.tight_layout()
    write_figure(fig, path, dpi=120, bbox_inches="tight")


MARKERS = ("o", "s", "^", "D", "v", "P", "X")
"""Markers of the methods' lines, in turn: seven, a number prime to the ten colours of
matplotlib's cycle, so two methods that share a marker never share a colour (within 70 methods)."""


def method_styles(count: int) -> list[dict]:
    """Line styles that tell ``count`` methods apart: the colour cycle's colours with a marker
    each (:data:`MARKERS`), dashed from the eleventh method on. Colours alone were not enough:
    the cycle's red and pink (the default comparison's DB-GW and ND-ECRULE-MV) look alike.

    Arguments:
        count: the number of methods.

    Returns:
        ``count`` keyword dicts for ``Axes.plot`` (``color``, ``marker``, ``linestyle``).
    """
    return [
        {"color": f"C{index % 10}", "marker": MARKERS[index % len(MARKERS)], "linestyle": "-" if index < 10 else "--"}
        for index in range(count)
    ]


def plot_sweep(
    result: SweepResult,
    path,
    statistics: str | Sequence[str] = ("rg", "angular"),
    summary: str = "rms",
    title: str | None = None,
) -> None:
    """Plot a sweep: error versus number of surfaces (log2 x axis, as the figures of Barnard 1999
    ch. 4), one panel per statistic, one line per method, written as a PNG.

    Arguments:
        result: a sweep (:func:`ccjax.experiments.sweep`).
        path: the PNG to write (atomically, :func:`ccjax.io.files.write_figure`), or a binary file.
        statistics: a statistic (``"angular"``) or several, one panel each; any of the result's
            (:data:`STATISTIC_LABELS` names them).
        summary: the summary of the per-scene errors (``"rms"`` as in the thesis; see
            :func:`ccjax.metrics.summarise`).
        title: the figure title (default: the scenes per point).

    Returns:
        None; the figure is written to ``path``.

    Raises:
        ValueError: a statistic no method of ``result`` has.

    Examples:
        >>> import jax
        >>> from ccjax import World, experiments
        >>> result = experiments.sweep(World.default(), ["GW"], (4, 16), 20, jax.random.key(0), progress=False)
        >>> experiments.plot_sweep(result, "sweep.png", statistics="angular")
    """
    statistics = [statistics] if isinstance(statistics, str) else list(statistics)
    present = {name for cells in result.errors.values() for cell in cells.values() for name in cell} - {"ok"}
    unknown = [name for name in statistics if name not in present]
    if not statistics or unknown:
        raise ValueError(f"statistics: expected some of {sorted(present)}, got {statistics}")
    fig = new_figure(figsize=(5.5 * len(statistics), 4.2))
    axes = fig.subplots(1, len(statistics), squeeze=False)
    styles = method_styles(len(result.methods))
    for ax, statistic in zip(axes[0], statistics, strict=False):
        for method, style in zip(result.methods, styles, strict=True):
            points = [
                (n, result.value(method, n, statistic, summary))
                for n in result.surfaces
                if statistic in result.errors[method][n]
            ]
            if points:
                xs, ys = zip(*points, strict=True)
                ax.plot(np.log2(xs), ys, label=method, **style)
        ax.set_xticks(np.log2(result.surfaces))
        ax.set_xticklabels([str(n) for n in result.surfaces])
        ax.set_xlabel("number of surfaces (log2 scale)")
        ax.set_ylabel(f"{summary.upper()} {STATISTIC_LABELS.get(statistic, statistic)}")
        ax.grid(alpha=0.3)
    handles, names = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, names, fontsize=8, loc="center left", bbox_to_anchor=(1.0, 0.5))
    _finish(fig, path, title or f"{result.n_scenes} scenes per point")


def plot(result: SweepResult, path, *args, **kwargs) -> None:
    """Deprecated alias of :func:`plot_sweep` (named like the other plots); it warns and will be
    removed in the next release.

    Arguments:
        result: a sweep.
        path: the PNG to write, or a binary file.
        *args: :func:`plot_sweep`'s ``statistics``, ``summary``, ``title``, in order.
        **kwargs: the same by name.

    Returns:
        None; the figure is written to ``path``.
    """
    warnings.warn(
        "ccjax.experiments.plot is deprecated: use ccjax.experiments.plot_sweep", DeprecationWarning, stacklevel=2
    )
    plot_sweep(result, path, *args, **kwargs)


def plot_world(world: World, path) -> None:
    """The training and test illuminants and the reflectances in (r,g) (Barnard 1999 Fig. 4.1).

    Arguments:
        world: the world.
        path: the PNG to write (atomically, :func:`ccjax.io.files.write_figure`), or a binary file.
    """
    from ccjax._colour import rg_numpy

    fig = new_figure(figsize=(15, 4.8))
    axes = fig.subplots(1, 3, sharex=True, sharey=True)
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
    write_figure(fig, path, dpi=110)


FILE_NAME_TICKS = 40
"""Up to this many images, :func:`plot_image_errors` names each image under its errors."""


def plot_image_errors(results: ImageResults, path, title: str | None = None) -> None:
    """Per-image angular errors of every method: their cumulative distribution (the share of
    images within each error) and each image's error, images ordered by the first method's error
    and named by their files (up to :data:`FILE_NAME_TICKS` images); estimates that fell back or
    relaxed (not ok) are drawn hollow. Both panels have a legend.

    Arguments:
        results: an evaluation with ground truth (:class:`ccjax.evaluation.ImageResults`).
        path: the image file to write (atomically, :func:`ccjax.io.files.write_figure`), or a binary file.
        title: the figure title (default: the number of images).
    """
    methods = list(results.estimates)
    errors = {method: results.angular(method) for method in methods}
    order = np.argsort(errors[methods[0]], kind="stable") if methods else np.array([], int)
    fig = new_figure(figsize=(12, 4.2))
    cumulative, each = fig.subplots(1, 2)
    share = np.arange(len(results.paths) + 1) / max(len(results.paths), 1)  # from 0 at no error
    for index, method in enumerate(methods):
        colour = f"C{index % 10}"
        cumulative.step(np.r_[0.0, np.sort(errors[method])], share, where="post", color=colour, label=method)
        ok = np.asarray(results.ok[method], bool)[order]
        positions = np.arange(len(order))
        values = errors[method][order]
        each.plot(positions[ok], values[ok], "o", color=colour, markersize=4, label=method)
        each.plot(positions[~ok], values[~ok], "o", markerfacecolor="none", color=colour, markersize=4)
    cumulative.set_xlabel(STATISTIC_LABELS["angular"])
    cumulative.set_ylabel("share of images with at most this error")
    each.set_xlabel(f"image (ordered by {methods[0]}'s error)" if methods else "image")
    each.set_ylabel(STATISTIC_LABELS["angular"])
    names = [os.path.basename(str(results.paths[i])) for i in order]
    if 0 < len(names) <= FILE_NAME_TICKS:  # few enough images to name each one under its errors
        each.set_xticks(np.arange(len(names)), names, rotation=90, fontsize=6)
    else:
        each.xaxis.get_major_locator().set_params(integer=True)
    for ax in (cumulative, each):
        ax.grid(alpha=0.3)
    cumulative.legend(fontsize=8, loc="lower right")
    if methods:
        each.legend(fontsize=8, loc="upper left")
    _finish(fig, path, title or f"angular error over {len(results.paths)} images (hollow: fell back or relaxed)")
