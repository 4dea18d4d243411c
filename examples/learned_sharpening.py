"""Learned end-to-end sharpening vs the thesis' new method (Barnard 1999 ch. 5; beyond the thesis).

T is learned by Adam through a differentiable estimator on synthetic scenes under the *training*
lights, then every transform is scored on held-out scenes under the *test* lights:

* GW with the chapter-5 mapping error (GW's chromaticity does not depend on T, §5.6);
* a non-linear estimator (default soft-RETINEX-t0.01) with the angular error.

Before the held-out table, each learned ``T`` is checked on the objective it was trained on: the
RMS training loss at ``T = I`` and at the learned ``T`` on one fixed batch of fresh scenes under the
training lights (the per-step losses are of fresh random batches each, too noisy to compare a few
steps; and with fewer than 40 steps the "first 20" and "last 20" steps would overlap).

Run:  python examples/learned_sharpening.py [--world barnard1999|default] [--camera NAME] [--steps 200]
(``--quick``: the default world, 40 steps, the new method at the lambda_P its search picks there,
200 held-out scenes: a smoke test).
"""

from __future__ import annotations

import argparse
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ccjax import sharpening
from ccjax.estimators import registry
from ccjax.experiments.chapter5 import evaluate_transforms
from ccjax.scenes import draw_scenes, sweep_keys
from ccjax.world import World

# lambda_P of the default world's new method as its search picks it (the full run prints it): --quick
# skips the search (8 candidate minimisations) and runs the one minimisation at that value.
QUICK_LAMBDA_P = 1e5


@eqx.filter_jit
def rms_loss(transform, label, loss, world, train, lights, surfaces, plain):
    """RMS of :func:`ccjax.sharpening.scene_losses` (the training objective) at ``transform``."""
    errors = sharpening.scene_losses(transform, label, loss, world, train, world.train_whites, lights, surfaces, plain)
    return jnp.sqrt(jnp.mean(errors**2))


def objective_before_after(world, label, loss, transform, n_scenes=2048, n_surfaces=8):
    """The training objective at ``T = I`` and at ``transform`` on one fixed batch of fresh scenes
    under the training lights (a different key from the training batches)."""
    train = sharpening.database_responses(world, world.train_illuminants)
    n_lights, n_reflectances = train.shape[:2]
    draws = draw_scenes(sweep_keys(jax.random.key(7), n_surfaces, 0, n_scenes), n_lights, n_reflectances, n_surfaces)
    plain = registry.fit(label, world)
    args = (label, loss, world, train, draws.light, draws.surfaces, plain)
    learned = jnp.asarray(transform, train.dtype)
    return float(rms_loss(jnp.eye(3, dtype=train.dtype), *args)), float(rms_loss(learned, *args))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").strip().split("\n")[0])
    parser.add_argument("--world", choices=["barnard1999", "default"], default="barnard1999")
    parser.add_argument("--camera", default=None, help="camera of the default world")
    parser.add_argument("--nonlinear", default="soft-RETINEX-t0.01", help="non-linear estimator trained on the angle")
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--scenes", type=int, default=1000, help="held-out test scenes")
    parser.add_argument("--quick", action="store_true", help="default world, 40 steps, 200 scenes (smoke test)")
    args = parser.parse_args(argv)
    lambda_p = None
    if args.quick:
        args.world, args.steps, args.scenes, lambda_p = "default", 40, 200, QUICK_LAMBDA_P

    world = World.barnard1999() if args.world == "barnard1999" else World.default(args.camera or "Canon EOS 5D Mark II")
    start = time.perf_counter()
    new = sharpening.new_sharpening(world, lambda_p=lambda_p)
    print(
        f"world {world.name}: new method lambda_P {new.lambda_p:g}, {new.iterations} iterations "
        f"({time.perf_counter() - start:.0f} s)"
    )
    rows = []
    for label, loss in (("GW", "mapping"), (args.nonlinear, "angular")):
        learned = sharpening.learned_sharpening(world, label, loss, steps=args.steps)
        window = max(1, min(20, args.steps // 4))  # the first and last windows never overlap
        head, tail = np.mean(learned.rms_errors[:window]), np.mean(learned.rms_errors[-window:])
        before, after = objective_before_after(world, label, loss, learned.transform)
        print(
            f"{label}: learned on {loss} in {learned.seconds:.0f} s; "
            f"training RMS error (mean of first/last {window} steps) {head:.3f} -> {tail:.3f}; "
            f"on a fixed batch of 2048 training scenes: T = I {before:.3f} -> learned {after:.3f}"
        )
        print(f"  learned T = {np.round(learned.transform, 4).tolist()}")
        transforms = {"none": np.eye(3), "new": new.transform, "learned": learned.transform}
        scores = evaluate_transforms(world, label, transforms, args.scenes, key=jax.random.key(0))
        for name, score in scores.items():
            rows.append((label, loss, name, score))
    print(f"\nheld-out: {args.scenes} scenes of 8 surfaces under test lights (RMS; mapping error in thesis units)")
    print(f"{'estimator':<22}{'trained on':<11}{'T':<9}{'mapping':>10}{'angle':>8}{'reverted':>10}")
    for label, loss, name, score in rows:
        print(
            f"{label:<22}{loss:<11}{name:<9}{score['map_rgb']:>10.2f}{score['angular']:>8.3f}{score['reverted']:>10d}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
