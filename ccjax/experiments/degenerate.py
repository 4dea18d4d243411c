"""The degenerate-input sweep: every buildable label on scenes that carry no or odd data.

Each label is fitted on a world and run on one ordinary synthetic scene turned degenerate in seven
ways (:data:`CASES`): all zero, all masked, one valid surface, identical surfaces, scaled by 1e6
and by 1e-12, and one channel zeroed. Image estimators get the surfaces as a tiny image (each
surface a ``block x block`` patch). A label passes when every estimate is finite, every estimate
whose status is not ``ESTIMATED`` is the model's fallback light with ``ok=False``, and the two
scenes without data (all zero, all masked) give ``ok=False``.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import jax
import numpy as np

from ccjax.estimators import registry
from ccjax.estimators.base import AbstractEstimator, Status, input_kind_of
from ccjax.estimators.neural import MissingWeightsError
from ccjax.runs import store
from ccjax.scenes import sample
from ccjax.world import World

CASES = ("zeros", "all masked", "one surface", "identical surfaces", "x1e6", "x1e-12", "one zero channel")
"""The degenerate inputs, in table order."""

NO_DATA_CASES = ("zeros", "all masked")
"""Cases without usable data: every label must answer ``ok=False`` on them."""

EXTRA_LABELS = ("shades-of-grey-p1000", "soft-RETINEX-t0.01", "CRULE-MV")
"""Labels swept besides each family's registry example: the extreme shades-of-grey power, the
sharpest soft-RETINEX and the plain gamut rule, whose degenerate cases differ from their family's
example."""


@dataclass(frozen=True)
class Row:
    """One (label, case) cell of the sweep.

    Attributes:
        label: the method label.
        case: one of :data:`CASES`.
        finite: every component of the estimate is finite.
        ok: the estimate's ``ok``.
        status: the :class:`Status` name.
        fallback_honest: where ``status`` is ``NO_DATA`` or ``EMPTY_SET`` the answer is the model's
            fallback light and ``ok`` is False; wherever ``status != ESTIMATED``, ``ok`` is False.
        no_data_flagged: False only on a no-data case (:data:`NO_DATA_CASES`) answered with ``ok=True``.
    """

    label: str
    case: str
    finite: bool
    ok: bool
    status: str
    fallback_honest: bool
    no_data_flagged: bool

    @property
    def passed(self) -> bool:
        """The cell satisfies the contract."""
        return self.finite and self.fallback_honest and self.no_data_flagged


@dataclass(frozen=True)
class Sweep:
    """The sweep's result.

    Attributes:
        rows: one :class:`Row` per label and case.
        skipped: ``(label, reason)`` for labels that could not be built (e.g. nets without cached weights).
    """

    rows: tuple[Row, ...]
    skipped: tuple[tuple[str, str], ...]

    def failures(self) -> list[Row]:
        """The rows that break the contract."""
        return [row for row in self.rows if not row.passed]

    def table(self) -> str:
        """The tidy table as text: one line per label with the count of non-finite estimates, of
        dishonest fallbacks and of no-data cases flagged ok, then the status of each case."""
        labels = list(dict.fromkeys(row.label for row in self.rows))
        width = max([len(label) for label in labels] + [5])
        head = f"{'label':<{width}}  non-finite  dishonest  no-data-ok  " + "  ".join(f"{c:>10.10}" for c in CASES)
        lines = [head, "-" * len(head)]
        for label in labels:
            rows = [row for row in self.rows if row.label == label]
            cells = {row.case: ("ok " if row.ok else "") + row.status[:7] + ("" if row.passed else "!") for row in rows}
            lines.append(
                f"{label:<{width}}  {sum(not r.finite for r in rows):>10}"
                f"  {sum(not r.fallback_honest for r in rows):>9}"
                f"  {sum(not r.no_data_flagged for r in rows):>10}  "
                + "  ".join(f"{cells.get(c, '-'):>10}" for c in CASES)
            )
        lines.extend(f"skipped {label}: {reason}" for label, reason in self.skipped)
        return "\n".join(lines)


def degenerate_inputs(world: World, n_surfaces: int = 8, seed: int = 0) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """The degenerate versions of one ordinary synthetic scene.

    Arguments:
        world: the world the scene is drawn from.
        n_surfaces: surfaces of the scene (at least 2).
        seed: the scene's PRNG seed.

    Returns:
        ``{case: (rgb (P, 3) float32, mask (P,) bool)}`` for every case of :data:`CASES`.
    """
    if n_surfaces < 2:
        raise ValueError(f"n_surfaces: expected at least 2 (one case keeps one of them), got {n_surfaces}")
    scene = sample(jax.random.key(seed), world, 1, n_surfaces)
    rgb = np.asarray(scene.rgb[0], np.float32)
    everything = np.ones(n_surfaces, bool)
    one = np.zeros(n_surfaces, bool)
    one[0] = True
    zero_channel = rgb.copy()
    zero_channel[:, 0] = 0.0
    return {
        "zeros": (np.zeros_like(rgb), everything),
        "all masked": (rgb, np.zeros(n_surfaces, bool)),
        "one surface": (rgb, one),
        "identical surfaces": (np.repeat(rgb[:1], n_surfaces, axis=0), everything),
        "x1e6": ((rgb * np.float32(1e6)).astype(np.float32), everything),
        "x1e-12": ((rgb * np.float32(1e-12)).astype(np.float32), everything),
        "one zero channel": (zero_channel, everything),
    }


def as_image(rgb: np.ndarray, mask: np.ndarray, block: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """Surfaces as a ``(block, P * block, 3)`` image of square patches, with the matching mask.

    Arguments:
        rgb: ``(P, 3)`` surface RGBs.
        mask: ``(P,)`` valid surfaces.
        block: patch side in pixels.

    Returns:
        ``(image, mask)`` for an image estimator.
    """
    image = np.repeat(np.repeat(rgb[None], block, axis=0), block, axis=1)
    pixels = np.repeat(np.repeat(mask[None], block, axis=0), block, axis=1)
    return image.astype(np.float32), pixels


def fallback_of(model: AbstractEstimator) -> np.ndarray | None:
    """The light a model answers without data: its ``fallback`` (a constant's answer), or None."""
    light = getattr(model, "fallback", None)
    if light is None:
        light = getattr(model, "illuminant", None)
    return None if light is None else np.asarray(light)


def sweep_labels() -> list[str]:
    """Every family's registry example and :data:`EXTRA_LABELS`, without repeats."""
    return list(dict.fromkeys([entry.example for entry in registry.available()] + list(EXTRA_LABELS)))


def run_label(label: str, model: AbstractEstimator, inputs: dict[str, tuple[np.ndarray, np.ndarray]]) -> list[Row]:
    """The sweep's rows for one fitted model.

    Arguments:
        label: the model's label (for the rows).
        model: the fitted estimator.
        inputs: :func:`degenerate_inputs`.

    Returns:
        One :class:`Row` per case.
    """
    estimate = jax.jit(lambda m, x, k: m(x, k))
    fallback = fallback_of(model)
    rows = []
    for case, (rgb, mask) in inputs.items():
        x, valid = as_image(rgb, mask) if input_kind_of(model) == "image" else (rgb, mask)
        result = estimate(model, x, valid)
        light = np.asarray(result.illuminant)
        ok = bool(result.ok)
        status = Status(int(result.status))
        honest = ok == (status == Status.ESTIMATED)
        if status in (Status.NO_DATA, Status.EMPTY_SET) and fallback is not None:
            honest = honest and bool(np.array_equal(light, fallback))
        rows.append(
            Row(
                label=label,
                case=case,
                finite=bool(np.all(np.isfinite(light))),
                ok=ok,
                status=status.name,
                fallback_honest=honest,
                no_data_flagged=not (ok and case in NO_DATA_CASES),
            )
        )
    return rows


def degenerate_sweep(
    world: World, labels: Iterable[str] | None = None, *, n_surfaces: int = 8, seed: int = 0, progress=None
) -> Sweep:
    """Run every label on every degenerate input.

    Arguments:
        world: the world the models are fitted on and the scene drawn from.
        labels: the labels (default :func:`sweep_labels`).
        n_surfaces: surfaces of the base scene.
        seed: the base scene's seed.
        progress: optional ``progress(label)`` callback, called before each label.

    Returns:
        :class:`Sweep`; nets without cached weights are skipped with the reason.
    """
    inputs = degenerate_inputs(world, n_surfaces, seed)
    rows: list[Row] = []
    skipped: list[tuple[str, str]] = []
    for label in sweep_labels() if labels is None else labels:
        if progress is not None:
            progress(label)
        try:
            model = store.fit(label, world)
        except MissingWeightsError as error:
            skipped.append((label, f"no cached weights ({error})"))
            continue
        rows.extend(run_label(label, model, inputs))
    return Sweep(rows=tuple(rows), skipped=tuple(skipped))
