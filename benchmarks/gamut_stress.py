"""Stress command: every gamut-mapping selector on many large scenes, with and without ND.

For CRULE, ECRULE, ND-CRULE and ND-ECRULE it runs every selector (MV, AVE, ICA for ECRULE,
SCWIA-3/12/24) from one evaluation of the direction grid on ``--scenes`` synthetic scenes of
``--surfaces`` surfaces (default 10^4 scenes of 1024 surfaces, where the diagonal model fails
often without ND), and prints per model: NaN count (must be 0), the fraction of scenes that
needed relaxation, that fell back (no solution at any level), whose observation reduction
overflowed, the rg RMS of each selector, and the time.

Usage: python benchmarks/gamut_stress.py [--scenes 10000] [--surfaces 1024] [--chunk 256]
"""

from __future__ import annotations

import argparse
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ccjax import metrics
from ccjax.estimators import gamut
from ccjax.estimators.base import Status
from ccjax.scenes import SceneTables, resolve_options, sample_batch, scene_keys
from ccjax.world import World


@eqx.filter_jit
def _chunk(model, tables, keys, n_surfaces):
    batch = sample_batch(keys, tables, n_surfaces, None, None, None)
    out = jax.vmap(lambda r, m: gamut.estimate_all(model, r, m, powers=(3, 12, 24)))(batch.rgb, batch.mask)
    # The diagnostic re-runs the (cheap) locating stage and reduction; the estimates are unaffected.
    exact = jax.vmap(gamut.GamutMapping(model, "MV").reduction_exact)(batch.rgb, batch.mask)
    summary = {}
    for name, estimate in out.items():
        summary[name] = {
            "nan": jnp.sum(~jnp.isfinite(estimate.illuminant)),
            "relaxed": estimate.status == Status.RELAXED,
            "fell_back": (estimate.status == Status.EMPTY_SET) | (estimate.status == Status.NO_DATA),
            "inexact": ~exact,
            "rg": metrics.rg_error(estimate.illuminant, batch.illuminant),
        }
    return summary


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", type=int, default=10_000)
    parser.add_argument("--surfaces", type=int, default=1024)
    parser.add_argument("--chunk", type=int, default=256)
    args = parser.parse_args()
    resolve_options(None, None, None)

    world = World.barnard1999()
    tables = SceneTables.from_world(world)
    key = jax.random.key(2024)
    total_nan = 0
    for extension in (None, "ND"):
        for constraint in ("CRULE", "ECRULE"):
            model = gamut.fit(world, constraint=constraint, extension=extension)
            label = ("ND-" if extension else "") + constraint
            start = time.perf_counter()
            parts = []
            for first in range(0, args.scenes, args.chunk):
                parts.append(jax.device_get(_chunk(model, tables, scene_keys(key, first, args.chunk), args.surfaces)))
            elapsed = time.perf_counter() - start
            merged = jax.tree_util.tree_map(lambda *x: np.concatenate([np.atleast_1d(v) for v in x]), *parts)
            print(
                f"{label} ({args.scenes} scenes x {args.surfaces} surfaces, "
                f"{elapsed:.0f} s, {args.scenes / elapsed:.0f} scenes/s incl. compile):"
            )
            for name, values in merged.items():
                n = args.scenes
                nan = int(np.sum(values["nan"]))
                total_nan += nan
                print(
                    f"  {label + '-' + name:<20} NaN {nan:>3}   relaxed {np.mean(values['relaxed'][:n]):6.1%}   "
                    f"fell back {np.mean(values['fell_back'][:n]):6.2%} "
                    f"  reduction overflow {np.mean(values['inexact'][:n]):6.2%}   "
                    f"rg RMS {np.sqrt(np.mean(np.square(values['rg'][:n]))):.4f}"
                )
    print("no NaN" if total_nan == 0 else f"FAILED: {total_nan} NaN estimates")


if __name__ == "__main__":
    main()
