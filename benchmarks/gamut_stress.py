"""Stress command: every gamut-mapping selector and every extended estimator on many scenes.

Gamut mapping: for CRULE and ECRULE with each canonical-gamut extension (none, ND, FL, SP, MET and
the combinations SP-ND, MET-ND, SP-FL, MET-FL; ch. 6-9) it runs every selector (MV, AVE, ICA for
ECRULE, SCWIA-3/6/12/24) from one evaluation of the direction grid. Colour by Correlation: the
extended labels (FL-, SPEC-, FL-SPEC- C-by-C and RGB-C-by-C, MAP and MMSE; ch. 7, 10). The scenes
are ``--scenes`` synthetic scenes per surface count (default 10^4 at each of 4, 8, ..., 1024) of the
thesis world with every material on (``--materials all``: dielectric highlights p = 0.25, metallic
highlights p = 0.25 of the six metals, fluorescent surfaces p = 0.3 from the physical model, so
the inputs are the ones the extensions exist for and beyond them) or matte (``--materials
none``), chunked to bound memory. Per estimator and surface count it prints the NaN count (must be
0), the share of scenes not ok (relaxed; fell back: no solution at any level or no data), for
gamut mapping the share whose observation reduction overflowed, the rg RMS, and the time.

Usage: python benchmarks/gamut_stress.py [--scenes 10000] [--surfaces 4,8,...,1024] [--chunk 50]
[--extensions none,ND,FL,SP,MET,SP-ND,MET-ND,SP-FL,MET-FL] [--cbc all|none] [--materials all|none]
"""

from __future__ import annotations

import argparse
import os
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ccjax import materials, metrics
from ccjax.estimators import gamut, registry
from ccjax.estimators.base import Status
from ccjax.scenes import Fluorescent, Metallic, SceneTables, Specular, sample_batch, scene_keys
from ccjax.world import World

EXTENSIONS = ("none", "ND", "FL", "SP", "MET", "SP-ND", "MET-ND", "SP-FL", "MET-FL")
CBC_LABELS = (
    "FL-C-by-C-MAP",
    "FL-C-by-C-MMSE",
    "SPEC-C-by-C-MMSE",
    "FL-SPEC-C-by-C-MMSE",
    "FL-RGB-C-by-C-MAP",
    "FL-RGB-C-by-C-MMSE",
    "SPEC-RGB-C-by-C-MMSE",
    "FL-SPEC-RGB-C-by-C-MMSE",
)
SIZES = (4, 8, 16, 32, 64, 128, 256, 512, 1024)
POWERS = (3, 6, 12, 24)


def _summary(estimate, truth):
    return {
        "nan": jnp.sum(~jnp.isfinite(estimate.illuminant)),
        "relaxed": estimate.status == Status.RELAXED,
        "fell_back": (estimate.status == Status.EMPTY_SET) | (estimate.status == Status.NO_DATA),
        "rg": metrics.rg_error(estimate.illuminant, truth),
    }


def _scenes(tables, keys, n_surfaces, materials_on):
    if not materials_on:
        return sample_batch(keys, tables, n_surfaces, None, None, None)
    return sample_batch(keys, tables, n_surfaces, Specular(), None, None, Metallic(), Fluorescent())


@eqx.filter_jit
def _gamut_chunk(model, tables, keys, n_surfaces, materials_on):
    batch = _scenes(tables, keys, n_surfaces, materials_on)
    out = jax.vmap(lambda r, m: gamut.estimate_all(model, r, m, powers=POWERS))(batch.rgb, batch.mask)
    # The diagnostic re-runs the (cheap) locating stage and reduction; the estimates are unaffected.
    exact = jax.vmap(gamut.GamutMapping(model, "MV").reduction_exact)(batch.rgb, batch.mask)
    return {name: {**_summary(e, batch.illuminant), "inexact": ~exact} for name, e in out.items()}


@eqx.filter_jit
def _model_chunk(model, tables, keys, n_surfaces, materials_on):
    batch = _scenes(tables, keys, n_surfaces, materials_on)
    return {"": _summary(jax.vmap(model)(batch.rgb, batch.mask), batch.illuminant)}


def _run(chunk, model, tables, key, n_surfaces, args):
    parts = []
    for first in range(0, args.scenes, args.chunk):
        count = min(args.chunk, args.scenes - first)
        keys = scene_keys(jax.random.fold_in(key, n_surfaces), first, count)
        parts.append(jax.device_get(chunk(model, tables, keys, n_surfaces, args.materials == "all")))
    return jax.tree_util.tree_map(lambda *x: np.concatenate([np.atleast_1d(v) for v in x]), *parts)


def _print(label, values, n_surfaces, seconds, cpu):
    nan = int(np.sum(values["nan"]))
    overflow = f"   reduction overflow {np.mean(values['inexact']):6.2%}" if "inexact" in values else ""
    print(
        f"  {label:<26} n={n_surfaces:<5} NaN {nan:>3}   relaxed {np.mean(values['relaxed']):6.2%}   "
        f"fell back {np.mean(values['fell_back']):6.2%}{overflow}   "
        f"rg RMS {np.sqrt(np.mean(np.square(values['rg']))):.4f}   {seconds:.0f} s ({cpu:.0f} s CPU)",
        flush=True,
    )
    return nan


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--scenes", type=int, default=10_000)
    parser.add_argument("--surfaces", default=",".join(map(str, SIZES)))
    parser.add_argument("--chunk", type=int, default=50)
    parser.add_argument("--extensions", default=",".join(EXTENSIONS), help="gamut extensions ('none' = matte)")
    parser.add_argument("--constraints", default="CRULE,ECRULE")
    parser.add_argument("--cbc", default="all", help="'all' (the extended C-by-C labels), 'none' or labels")
    parser.add_argument("--materials", choices=("all", "none"), default="all")
    args = parser.parse_args()
    sizes = [int(s) for s in args.surfaces.split(",")]

    world = World.barnard1999()
    tables = SceneTables.from_world(world, metals=True, fluorescent=materials.synthetic_fluorescent_surfaces())
    key = jax.random.key(2024)
    total_nan = 0
    # Models are fitted one at a time and the compiled code dropped after each (peak memory: one
    # model's gamut and one chunk's grid, not every model's).
    jobs = []
    for extension in [e for e in args.extensions.split(",") if e]:
        for constraint in args.constraints.split(","):
            ext = None if extension == "none" else extension
            label = ("" if ext is None else ext + "-") + constraint
            jobs.append((label, _gamut_chunk, lambda c=constraint, e=ext: gamut.fit(world, constraint=c, extension=e)))
    cbc = CBC_LABELS if args.cbc == "all" else [] if args.cbc == "none" else args.cbc.split(",")
    jobs += [(label, _model_chunk, lambda label=label: registry.fit(label, world)) for label in cbc]
    for label, chunk, build in jobs:
        model = build()
        print(f"{label} ({args.scenes} scenes per size, materials {args.materials}):", flush=True)
        for n in sizes:
            start, cpu = time.perf_counter(), time.process_time()
            merged = _run(chunk, model, tables, key, n, args)
            seconds, cpu = time.perf_counter() - start, time.process_time() - cpu
            for name, values in merged.items():
                total_nan += _print(label + ("-" + name if name else ""), values, n, seconds, cpu)
        del model
        jax.clear_caches()
    load = os.getloadavg()
    print(f"load average {load[0]:.1f} {load[1]:.1f} {load[2]:.1f}")
    print("no NaN" if total_nan == 0 else f"FAILED: {total_nan} NaN estimates")


if __name__ == "__main__":
    main()
