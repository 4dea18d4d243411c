"""How strong are the synthetic fluorescent surfaces? Table 7.2's baselines and FL's cost against
two knobs of the stand-ins (Table 7.2; thesis ch. 7).

The thesis' nine measured fluorescent surfaces are not available; :mod:`ccjax.materials` builds
nine synthetic ones (excitation and emission bands, quantum yields). Two kinds of numbers of
Table 7.2 bear on how strong the thesis' surfaces were:

* the **harm** they do to methods that ignore fluorescence (GW, DB-GW, C-by-C-MMSE,
  ECRULE-SCWIA-12 on scenes where each surface is fluorescent with p = 0.3), and
* the **cost** of FL-ECRULE-SCWIA-12 on matte scenes (its rg RMS over ECRULE-SCWIA-12's): the
  fluorescent points widen FL's canonical gamut.

For each configuration (every quantum yield times ``yield``, every excitation band's FWHM times
``width``; the rest of :data:`ccjax.materials.FLUORESCENT_SURFACES` unchanged) the script
characterises the surfaces as ``ccjax reproduce 7.2`` does (NNLS on the 11 lab lights, §7.1),
renders the fluorescent test surfaces through that characterisation (as the thesis' synthetic
scenes were), builds FL's gamut from it and prints both kinds of numbers beside the thesis'.
``--scenes`` scenes per condition (default 1000, the thesis' count) of 4 and 8 surfaces: the
scenes of ``ccjax reproduce 7.2``, so the row of the default surfaces (``1x1``) repeats its cells.
The defaults were chosen with it (:mod:`ccjax.materials._fluorescence`: the measured member whose
cost is within 3 % of the thesis' at both sizes with the most harm, bands up to 210 nm);
``2x0.3333`` is the first, physically chosen set.

Usage: ``python benchmarks/fluorescent_standins.py [--scenes 1000] [--configs 1x1,2x0.3333,1.1x1,1.2x1,1x1.3333]``
(``YIELDxWIDTH``; ``1x1`` is the default surfaces).
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ccjax import materials, metrics, scenes, thesis
from ccjax.estimators import gamut, registry
from ccjax.world import World

SIZES = (4, 8)
BASELINES = ("GW", "DB-GW", "C-by-C-MMSE")


@eqx.filter_jit
def _estimates(estimator, rgb, mask):
    return jax.vmap(estimator)(rgb, mask).illuminant


def _rms(estimator, batch) -> float:
    error = metrics.rg_error(_estimates(estimator, batch.rgb, batch.mask), batch.illuminant)
    return float(jnp.sqrt(jnp.mean(error**2)))


def _surfaces(yield_scale: float, width_scale: float) -> materials.FluorescentSurfaces:
    parameters = tuple(
        dataclasses.replace(
            p,
            quantum_yield=min(1.0, p.quantum_yield * yield_scale),
            excitation_fwhm=p.excitation_fwhm * width_scale,
        )
        for p in materials.FLUORESCENT_SURFACES
    )
    return materials.synthetic_fluorescent_surfaces(parameters)


def _config(text: str) -> tuple[float, float]:
    try:
        yield_scale, width_scale = (float(v) for v in text.split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--configs: expected YIELDxWIDTH such as 0.6x2, got {text!r}") from None
    if not (0 < yield_scale and 0 < width_scale):
        raise argparse.ArgumentTypeError(f"--configs: both factors must be positive, got {text!r}")
    return yield_scale, width_scale


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--scenes", type=int, default=1000)
    parser.add_argument("--configs", default="1x1,2x0.3333,1.1x1,1.2x1,1x1.3333")
    args = parser.parse_args()
    if args.scenes < 1:
        parser.error("--scenes: expected a positive count")
    configs = [_config(c) for c in args.configs.split(",")]

    world = World.barnard1999()
    print(f"device: {jax.devices()[0].device_kind}; {args.scenes} scenes per condition, barnard1999 world")
    baselines = {label: registry.fit(label, world) for label in BASELINES}
    base = gamut.GamutMapping(gamut.fit(world, constraint="ECRULE"), "SCWIA", 12)
    # The scenes of ``ccjax reproduce 7.2`` (key 0, each size's stream): the matte and fluorescent
    # conditions share lights and surfaces, and the default surfaces' row repeats its cells.
    key = jax.random.key(0)
    keys = {n: scenes.sweep_keys(key, n, 0, args.scenes) for n in SIZES}
    matte_tables = scenes.SceneTables.from_world(world)
    matte = {n: scenes.sample_batch(keys[n], matte_tables, n) for n in SIZES}
    base_matte = {n: _rms(base, matte[n]) for n in SIZES}

    table = thesis.TABLES["7.2"]
    labels = (*BASELINES, "ECRULE-SCWIA-12", "FL-ECRULE-SCWIA-12")
    columns = [(label, n) for label in labels for n in SIZES]
    names = [f"{label}@{n}" for label, n in columns]
    widths = [max(8, len(name)) for name in names]
    cells = lambda values: "  ".join(f"{v:>{w}.4f}" for v, w in zip(values, widths))
    print("rg RMS on scenes with fluorescent surfaces (p = 0.3), then FL's cost on matte scenes:")
    header = f"{'yield x':>7} {'width x':>7} {'peak L/E':>9}  " + "  ".join(f"{c:>{w}}" for c, w in zip(names, widths))
    header += "  " + "  ".join(f"{f'cost@{n}':>7}" for n in SIZES)
    print(header)
    thesis_row = [table[label][f"rg@{n}+FL"] for label, n in columns]
    thesis_cost = [table["FL-ECRULE-SCWIA-12"][f"rg@{n}"] / table["ECRULE-SCWIA-12"][f"rg@{n}"] for n in SIZES]
    print(f"{'thesis':>7} {'':>7} {'':>9}  " + cells(thesis_row) + "  " + "  ".join(f"{v:>6.3f}x" for v in thesis_cost))
    for yield_scale, width_scale in configs:
        start = time.perf_counter()
        surfaces = _surfaces(yield_scale, width_scale)
        peak = np.asarray(surfaces.total_radiance_factor(np.ones(101))).max(axis=1)
        characterised = gamut.characterised_fluorescents(world, surfaces)
        fl_model = gamut.fit(
            world, constraint="ECRULE", extension="FL", fluorescent=gamut.default_fluorescent(world, surfaces)
        )
        fl = gamut.GamutMapping(fl_model, "SCWIA", 12)
        values = []
        tables = scenes.SceneTables.from_world(world, fluorescent=characterised)
        fluorescent = {
            n: scenes.sample_batch(keys[n], tables, n, None, None, None, None, scenes.Fluorescent()) for n in SIZES
        }
        for estimator in (*baselines.values(), base, fl):
            values.extend(_rms(estimator, fluorescent[n]) for n in SIZES)
        costs = [_rms(fl, matte[n]) / base_matte[n] for n in SIZES]
        print(
            f"{yield_scale:>7.2f} {width_scale:>7.2f} {f'{peak.min():.2f}-{peak.max():.2f}':>9}  "
            + cells(values)
            + "  "
            + "  ".join(f"{v:>6.3f}x" for v in costs)
            + f"   ({time.perf_counter() - start:.0f} s)",
            flush=True,
        )
    reference = table["ECRULE-SCWIA-12"]
    matte_cells = (f"{n} surfaces {base_matte[n]:.4f} (thesis {reference[f'rg@{n}']:.3f})" for n in SIZES)
    print("matte ECRULE-SCWIA-12 rg RMS: " + ", ".join(matte_cells))


if __name__ == "__main__":
    main()
