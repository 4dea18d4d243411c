"""Chapter-5 reports (Barnard 1999 §5.7): Table 5.1 reproduced and compared with the thesis
(``ccjax reproduce 5.1``), what one transform does on a world and its sensor plot
(``ccjax sharpen``), and cameras ranked by sharpness (``ccjax sharpen --rank-cameras``).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ccjax.experiments.chapter5 import COMPARISONS, SHARPENINGS, chapter5_errors
from ccjax.experiments.sweep_results import sampling_error
from ccjax.experiments.sweeps import is_registered
from ccjax.precision import matmul
from ccjax.sharpening import (
    THESIS_SCALE,
    actual_error,
    best_linear_error,
    database_responses,
    diagonal_error,
    sharpness,
)
from ccjax.world import World


@dataclass
class Reproduction51:
    """Table 5.1 (Barnard 1999 §5.7) reproduced: one row per (method, sharpening, column) with
    ours, the thesis' value and ``ours / thesis - 1``; ``checks`` are the thesis' qualitative
    findings."""

    rows: list[dict]
    checks: list[dict]
    info: dict
    pending: list[str]

    def to_json(self) -> str:
        """The reproduction as JSON (``table``, ``rows``, ``checks``, ``info``, ``pending``)."""
        return json.dumps(
            {"table": "5.1", "rows": self.rows, "checks": self.checks, "info": self.info, "pending": self.pending},
            indent=1,
        )

    def text(self) -> str:
        """The reproduction as a text table, then the new method's details and the checks."""
        lines = ["Table 5.1 (Sony DXC-930): ours vs thesis (mapping errors in thesis units, white = 255)"]
        lines.append(
            f"{'method':<15}{'sharpening':<11}{'column':<9}{'ours':>10}{'thesis':>10}{'diff':>9}{'s.e.':>9}"
            f"{'reverted':>10}{'thesis':>8}"
        )
        for row in self.rows:
            diff = "" if row["relative_difference"] is None else f"{row['relative_difference']:+9.1%}"
            lines.append(
                f"{row['method']:<15}{row['sharpening']:<11}{row['column']:<9}{row['ours']:>10.4g}"
                f"{row['thesis']:>10.4g}{diff:>9}{row['sampling_error']:>9.2g}{row['reverted']:>10d}"
                f"{row['thesis_reverted']:>8d}"
            )
        lines.append("s.e.: standard error of ours over the scenes (delta method for the RMS)")
        for key, value in self.info.items():
            lines.append(f"{key}: {value}")
        lines.append("thesis behaviour:")
        for check in self.checks:
            lines.append(f"  [{'ok' if check['holds'] else 'FAILS'}] {check['check']}: {check['evidence']}")
        if self.pending:
            lines.append(f"pending (not registered): {', '.join(self.pending)}")
        return "\n".join(lines)


def _behaviour_checks(values: dict, worst: dict) -> list[dict]:
    """The thesis' findings for ``ave`` and ``opt`` (§5.7; their numbers depend on the lights):
    "ave" hurts BEST-DIAGONAL and ACTUAL, "opt" multiplies the simple methods' mapping error."""
    checks = []
    for method in ("BEST-DIAGONAL", "ACTUAL"):
        if (method, "ave") in values and (method, "none") in values:
            a, n = values[(method, "ave")], values[(method, "none")]
            checks.append(
                {"check": f"{method}: ave worse than none", "holds": a > n, "evidence": f"{a:.2f} vs {n:.2f}"}
            )
    for method in ("GW", "DB-GW", "RETINEX"):
        if (method, "opt") in values and (method, "none") in values:
            o, n = values[(method, "opt")], values[(method, "none")]
            worst_opt, worst_none = worst[(method, "opt")], worst[(method, "none")]
            evidence = f"{o:.1f} vs {n:.1f} ({o / n:.2f}x); worst scene {worst_opt:.1f} vs {worst_none:.1f}"
            checks.append(
                {"check": f"{method}: opt mapping error >= 3x none", "holds": o >= 3 * n, "evidence": evidence}
            )
    return checks


def reproduce_5_1(
    world: World,
    methods: Sequence[str] | None = None,
    n_scenes: int = 1000,
    key=None,
    progress: bool = True,
) -> Reproduction51:
    """Run Table 5.1's protocol (Barnard 1999 §5.7: 1000 scenes of 8 surfaces, Sony DXC-930) and
    compare with the thesis.

    Arguments:
        world: :meth:`World.barnard1999`.
        methods: rows (default: every row of the table that can run; unregistered ones, e.g.
            gamut mapping before it exists, are listed as pending).
        n_scenes: scenes (1000 in the thesis).
        key: PRNG key (default ``jax.random.key(0)``).
        progress: print each (method, sharpening) as it finishes.

    Returns:
        :class:`Reproduction51`.
    """
    from ccjax import thesis

    targets = thesis.TABLES["5.1"]
    if methods is None:
        methods = list(targets)
    unknown = [m for m in methods if m not in targets]
    if unknown:
        raise ValueError(f"methods: {unknown} are not rows of Table 5.1")
    runnable = [m for m in methods if m in COMPARISONS or is_registered(m)]
    pending = [m for m in methods if m not in runnable]
    result = chapter5_errors(world, runnable, SHARPENINGS, n_scenes, 8, key, progress=progress)
    rows, mapping = [], {}
    for row in result.rows():
        method, sharpening = row["method"], row["sharpening"]
        per_scene = dict(zip(("map_rgb", "angular"), result.errors[(method, sharpening)][:2]))
        if row["map_rgb"] is not None:
            mapping[(method, sharpening)] = row["map_rgb"]
        for column in ("map_rgb", "angular"):
            reference = targets[method].get(f"{column}@{sharpening}")
            if reference is None or row[column] is None:
                continue
            rows.append(
                {
                    "method": method,
                    "sharpening": sharpening,
                    "column": column,
                    "ours": row[column],
                    "thesis": reference,
                    "relative_difference": row[column] / reference - 1.0 if reference else None,
                    # The standard error of the cell's RMS over scenes, in the cell's units.
                    "sampling_error": sampling_error(per_scene[column]) * (THESIS_SCALE if column == "map_rgb" else 1),
                    "reverted": row["reverted"],
                    "thesis_reverted": targets[method].get(f"reverted@{sharpening}", 0),
                }
            )
    new = result.info["new"]
    info = {
        "new: lambda_P": new.lambda_p,
        "new: negative training responses": f"{new.negative_fraction:.4%}",
        "new: non-positive sharpened canonical responses + training whites": new.negative_calibration,
        "new: lambda_P search (lambda_P, negative fraction, calibration negatives, iterations)": new.search,
        "new: iterations": new.iterations,
        "new: E at identity -> final": f"{new.initial_mapping:.4f} -> {new.mapping:.4f}",
        "new: T": np.round(new.transform, 4).tolist(),
        "ave: T": np.round(result.info["T_ave"], 4).tolist(),
    }
    worst = {pair: float(np.max(errors[0])) * THESIS_SCALE for pair, errors in result.errors.items()}
    return Reproduction51(rows=rows, checks=_behaviour_checks(mapping, worst), info=info, pending=pending)


# ---------------------------------------------------------------------------------------------
# Summaries and plots (``ccjax sharpen``)


def negative_lobes(sensors: Float[Array, "101 3"]) -> np.ndarray:
    """Per sensor, the share of its absolute area that is negative (0 for a physical sensor;
    sharpened sensors have negative lobes, Barnard 1999 §5.1).

    Arguments:
        sensors: ``(101, 3)`` sensor curves (e.g. ``Q @ T``).

    Returns:
        ``(3,)`` fractions.
    """
    curves = np.asarray(sensors, dtype=np.float64)
    return np.sum(np.maximum(-curves, 0.0), axis=0) / np.sum(np.abs(curves), axis=0)


def summary(world: World, transform) -> dict:
    """What a transform does on ``world`` (``ccjax sharpen``; Barnard 1999 §5.7).

    Arguments:
        world: the world.
        transform: ``(3, 3)`` sharpening ``T``.

    Returns:
        ``{"negative_lobes", "negative_training_responses", "best_linear",
        "best_diagonal_unsharpened", "best_diagonal_sharpened", "actual_unsharpened",
        "actual_sharpened"}``: the sharpened sensors' negative lobes, the share of negative
        sharpened training responses, and RMS mapping errors over the test illuminants (thesis
        units) of BEST-LINEAR, and of BEST-DIAGONAL and ACTUAL with and without ``T``.
    """
    t = jnp.asarray(transform, world.canonical_rgb.dtype)
    identity = jnp.eye(3, dtype=t.dtype)
    sources = database_responses(world, world.test_illuminants)
    target, whites, white = world.canonical_rgb, world.test_whites, world.canonical_white

    def rms(values):
        return float(jnp.sqrt(jnp.mean(values**2))) * THESIS_SCALE

    out = {
        "negative_lobes": negative_lobes(matmul(world.camera.sensors, t)).tolist(),
        "negative_training_responses": float(
            jnp.mean(matmul(database_responses(world, world.train_illuminants), t) < 0)
        ),
        "best_linear": rms(jax.jit(jax.vmap(best_linear_error, (0, None)))(sources, target)),
    }
    diagonal = jax.jit(jax.vmap(diagonal_error, (0, None, None)))
    actual = jax.jit(jax.vmap(actual_error, (0, None, None, 0, None)))
    for name, m in (("unsharpened", identity), ("sharpened", t)):
        out[f"best_diagonal_{name}"] = rms(diagonal(sources, target, m))
        out[f"actual_{name}"] = rms(actual(sources, target, m, whites, white))
    return out


def plot_sensors(world: World, transform, path, title: str | None = None) -> None:
    """Plot the original and sharpened sensor curves, each normalised to a peak |value| of 1
    (the figures of Barnard 1999 §5.2).

    Arguments:
        world: the world (its camera's sensors ``Q``).
        transform: ``(3, 3)`` sharpening ``T`` (sharpened sensors ``Q @ T``).
        path: PNG file to write.
        title: figure title (default: the camera's name).
    """
    from ccjax.io.files import new_figure, write_figure
    from ccjax.spectra import WAVELENGTHS

    original = np.asarray(world.camera.sensors, dtype=np.float64)
    sharp = original @ np.asarray(transform, dtype=np.float64)
    fig = new_figure(figsize=(11, 4))
    axes = fig.subplots(1, 2, sharey=True)
    for ax, curves, name in ((axes[0], original, "original"), (axes[1], sharp, "sharpened")):
        for k, colour in enumerate("rgb"):
            ax.plot(WAVELENGTHS, curves[:, k] / np.max(np.abs(curves[:, k])), color=colour)
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_title(f"{name} sensors")
        ax.set_xlabel("wavelength (nm)")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("relative sensitivity")
    fig.suptitle(title or world.camera.name)
    fig.tight_layout()
    write_figure(fig, path, dpi=110)  # atomic for paths; file objects pass through


def rank_cameras(data_dir=None, names: Sequence[str] | None = None, progress: bool = False) -> list[dict]:
    """Sharpness (BEST-LINEAR / BEST-DIAGONAL over the test lights, Barnard 1999 §5.7) of every
    available camera, each in ``World.default(camera=...)``, least sharp first.

    Arguments:
        data_dir: external data directory (its cameras are ranked too when it is found).
        names: cameras to rank (default: every available camera).
        progress: print each camera's ratio as it is computed.

    Returns:
        ``[{"camera", "source", "ratio", "best_linear", "best_diagonal"}]`` sorted by ratio.
    """
    from ccjax.camera import Camera, cameras

    available = cameras(data_dir)
    rows = []
    for name in names or list(available):
        world = World.default(Camera.from_name(name, data_dir))
        out = sharpness(world)
        rows.append({"camera": name, "source": available.get(name, "?"), **out})
        if progress:
            print(f"  {name:<36}{out['ratio']:.3f}", flush=True)
    return sorted(rows, key=lambda row: row["ratio"])
