"""How far do Tables 8.2 and 8.3 depend on the metals? MET's gamut and the scenes' metallic
highlights against the knobs of the recipe (thesis §8.2-§8.3, spec ch08-12 A10/A11).

The thesis measured its metals' specular reflectance with a PR-650 and published neither the
spectra nor their scale; ccjax computes brass, copper, gold, aluminium, silver and steel from
optical constants (normal-incidence Fresnel reflectance), so three things are choices, not data:

* **the MET gamut's metal points and the metals' colour** — ``k_m * f`` times the unit-mean
  spectrum of ``rho^p`` under the canonical light for brass, copper and gold (A10: ``k_m = 8``,
  ``f = p = 1``; SP's white point stays at ``8 * w_C``), with the scenes' highlights ``rho^p`` too.
  ``f`` says how far the gamut reaches toward the metals, ``p`` how coloured every metal is
  (``p = 2``: light reflected twice by the same metal, more saturated than one normal-incidence
  reflection). What MET costs on scenes without metals (Table 8.2, columns 1-3) comes only from
  the extra maps the metal points admit.
* **the highlights' spectra** — ``s ~ U(0, 4 g)`` times each metal's own reflectance (ccjax's
  default: at most four times a perfect white, the thesis' words) or times the unit-mean spectrum
  (A11 read literally). Table 8.3's metal column for the methods that ignore specularities (GW,
  DB-GW, RETINEX) depends on nothing else, and so do the spreads of Table 8.3's claims.

For each gamut configuration it prints the six MET rows of Table 8.2 in all five columns (relative
to the thesis; ``*`` marks a cell outside the tolerance: 15 % in columns 1-3, 20 % in
4-5) and the table's claims (with the non-MET rows, which do not depend on it); for each scene
configuration Tables 8.2's and 8.3's rows in the two metal columns, the count of cells within
20 %, and both tables' claims. The scenes are those of ``ccjax reproduce 8.2`` / ``8.3`` (key 0,
1000 scenes of 8 surfaces per condition), so the default rows (``1x1``, ``reflectance:1``) repeat
its cells.

Usage: ``python benchmarks/metal_recipe.py [--scenes 1000] [--gamut 1x1,2x1,3x1,1x2]
[--highlights reflectance:1,unit-mean:1,unit-mean:0.75]`` (gamut: ``FxP``; highlights:
``SPECTRA:G``; an empty value skips that part)
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import jax
import numpy as np

from ccjax import materials, scenes, thesis
from ccjax.estimators import gamut
from ccjax.estimators.neural import MissingWeightsError
from ccjax.experiments import table_protocols as protocols
from ccjax.runs import store
from ccjax.world import World

SELECTORS = (("MV", 12.0), ("ICA", 12.0), ("SCWIA", 12.0))
TOLERANCE = (0.15, 0.15, 0.15, 0.20, 0.20)
"""The tolerance per column of Tables 8.2/8.3: 15 % in columns 1-3, 20 % in the metal columns."""
SPECTRA = {
    "reflectance": lambda: materials.scene_metal_spectra(),
    "unit-mean": lambda: materials.metal_spectra(materials.METALS, unit_mean=True),
}


def _pairs(text: str, name: str, separator: str, first=float) -> list[tuple]:
    out = []
    for item in (v for v in text.split(",") if v):
        try:
            a, b = item.split(separator)
            pair = (first(a), float(b))
        except (ValueError, KeyError):
            raise argparse.ArgumentTypeError(f"{name}: cannot read {item!r}") from None
        if not (pair[1] > 0 and np.isfinite(pair[1])):
            raise argparse.ArgumentTypeError(f"{name}: {item!r}: the factor must be positive")
        out.append(pair)
    return out


def _spectra_name(text: str) -> str:
    if text not in SPECTRA:
        raise KeyError(text)
    return text


def _fit_rows(world, labels) -> list[tuple]:
    """``(label, model)`` for every row that can be fitted here (the nets need trained weights)."""
    fitted = []
    for label in labels:
        try:
            fitted.append((label, store.fit(label, world)))
        except MissingWeightsError:
            print(f"  ({label}: no trained weights here, row skipped)")
    return fitted


def _label(extension: str, selector: str) -> str:
    return f"{extension}-ECRULE-{selector}" + ("-12" if selector == "SCWIA" else "")


def _values(world, fitted, conditions, n_scenes, statistic, metals=None) -> dict:
    """``(label, column) -> value`` in the thesis' units for every fitted model and condition."""
    results = protocols.run_conditions(
        world, fitted, conditions, n_scenes, jax.random.key(0), progress=False, metals=metals
    )
    scale = thesis.THESIS_RGB_SCALE if statistic == "brightness" else 1.0
    out = {}
    for condition, result in zip(conditions, results):
        (column,) = condition.columns
        for label, _ in fitted:
            if statistic in result.errors[label][condition.n_surfaces]:
                out[(label, column)] = scale * result.value(label, condition.n_surfaces, statistic)
    return out


def _cell(ours: float, target: float, tolerance: float, spec: str) -> str:
    difference = ours / target - 1.0
    return f"{ours:{spec}} ({difference:+5.0%}){'*' if abs(difference) > tolerance else ' '}"


def _claims(table: str, values: dict) -> None:
    for claim in thesis.CHECKS[table]:
        line = protocols.check_claim(claim, values)
        if line is not None:
            print("    " + line)


def _has_metal(condition) -> bool:
    return condition.options.metallic is not None


def gamut_sweep(world, configs, n_scenes) -> None:
    """Table 8.2's MET rows and claims against MET's metal points (how far, how coloured)."""
    table = thesis.TABLES["8.2"]
    conditions = protocols.PROTOCOLS["8.2"]
    columns = [next(iter(c.columns)) for c in conditions]
    others = [label for label in table if "CRULE" in label and not label.startswith("MET-")]
    start = time.perf_counter()
    others = [(label, store.fit(label, world)) for label in others]
    fixed = _values(world, others, [c for c in conditions if not _has_metal(c)], n_scenes, "rg")
    print(f"Table 8.2, the {len(others)} non-MET gamut rows without metals: {time.perf_counter() - start:.0f} s")
    reflectance = materials.metal_spectra(materials.COLOURED_METALS, unit_mean=False)
    print(f"Table 8.2 MET rows, rg RMS (relative to the thesis; * outside the tolerance); {', '.join(columns)}")
    with_metals: dict[float, dict] = {}
    for factor, power in configs:
        start = time.perf_counter()
        # Every metal is reflectance^power: the MET gamut's points and the scenes' highlights.
        scene_metals = materials.scene_metal_spectra() ** power
        if power not in with_metals:
            metal_conditions = [c for c in conditions if _has_metal(c)]
            with_metals[power] = _values(world, others, metal_conditions, n_scenes, "rg", metals=scene_metals)
        coloured = reflectance**power
        metals = factor * coloured / coloured.mean(axis=1, keepdims=True)
        fitted = []
        for extension in ("MET", "MET-ND"):
            model = gamut.fit(world, constraint="ECRULE", extension=extension, metals=metals)
            fitted += [(_label(extension, s), gamut.GamutMapping(model, s, p)) for s, p in SELECTORS]
        values = {**fixed, **with_metals[power], **_values(world, fitted, conditions, n_scenes, "rg", scene_metals)}
        outside = sum(
            abs(values[(label, c)] / table[label][c] - 1.0) > TOLERANCE[i]
            for label, _ in fitted
            for i, c in enumerate(columns[:3])
        )
        print(
            f"metals reflectance^{power:g} (scenes), MET's points {8 * factor:g} x their unit-mean spectra: "
            f"{outside} of {3 * len(fitted)} MET cells of columns 1-3 outside 15 %"
            f"   ({time.perf_counter() - start:.0f} s)"
        )
        for label, _ in fitted:
            cells = [_cell(values[(label, c)], table[label][c], TOLERANCE[i], "7.4f") for i, c in enumerate(columns)]
            print(f"  {label:<24}" + "  ".join(cells))
        _claims("8.2", values)


def scene_sweep(world, configs, n_scenes) -> None:
    """Tables 8.2 and 8.3 in the metal columns against the highlights' spectra and brightness."""
    tables = {name: thesis.TABLES[name] for name in ("8.2", "8.3")}
    statistic = {"8.2": "rg", "8.3": "brightness"}
    fitted = {name: _fit_rows(world, tables[name]) for name in tables}
    start = time.perf_counter()
    fixed = {
        name: _values(world, fitted[name], [c for c in protocols.PROTOCOLS[name] if not _has_metal(c)], n_scenes, stat)
        for name, stat in statistic.items()
    }
    print(f"Tables 8.2 and 8.3, the columns without metals: {time.perf_counter() - start:.0f} s")
    for spectra_name, factor in configs:
        start = time.perf_counter()
        spectra = SPECTRA[spectra_name]()
        print(f"highlights s ~ U(0, 4 x {factor:g}) x the metal's {spectra_name} spectrum (mean {spectra.mean():.2f})")
        for name, stat in statistic.items():
            metal = [
                dataclasses.replace(
                    c, options=dataclasses.replace(c.options, metallic=scenes.Metallic(max_amount=4.0 * factor))
                )
                for c in protocols.PROTOCOLS[name]
                if _has_metal(c)
            ]
            columns = [next(iter(c.columns)) for c in metal]
            values = {**fixed[name], **_values(world, fitted[name], metal, n_scenes, stat, metals=spectra)}
            rows = [label for label, _ in fitted[name]]
            within = [
                abs(values[(label, c)] / tables[name][label][c] - 1.0) <= TOLERANCE[3]
                for label in rows
                for c in columns
            ]
            print(f"  Table {name} ({', '.join(columns)}): {sum(within)} of {len(within)} cells within 20 %")
            spec = "7.4f" if stat == "rg" else "7.1f"
            for label in rows:
                reference = tables[name][label]
                cells = "  ".join(_cell(values[(label, c)], reference[c], TOLERANCE[3], spec) for c in columns)
                print(f"    {label:<24}{cells}")
            _claims(name, values)
        print(f"  ({time.perf_counter() - start:.0f} s)")


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--scenes", type=int, default=1000)
    parser.add_argument("--gamut", default="1x1,2x1,3x1,1x2", help="FxP: MET's metal points 8 f x reflectance^p")
    parser.add_argument(
        "--highlights",
        default="reflectance:1,unit-mean:1,unit-mean:0.75",
        help="SPECTRA:G, SPECTRA reflectance or unit-mean: highlights s ~ U(0, 4 g) x the spectrum",
    )
    args = parser.parse_args()
    if args.scenes < 1:
        parser.error("--scenes: expected a positive count")
    try:
        gamut_configs = _pairs(args.gamut, "--gamut", "x")
        scene_configs = _pairs(args.highlights, "--highlights", ":", _spectra_name)
    except argparse.ArgumentTypeError as error:
        parser.error(str(error))
    world = World.barnard1999()
    print(f"device: {jax.devices()[0].device_kind}; {args.scenes} scenes per condition, barnard1999 world")
    if gamut_configs:
        gamut_sweep(world, gamut_configs, args.scenes)
    if scene_configs:
        scene_sweep(world, scene_configs, args.scenes)


if __name__ == "__main__":
    main()
