"""Learned end-to-end sharpening vs the thesis' new method (Barnard 1999 ch. 5; beyond the thesis).

T is learned by Adam through a differentiable estimator on synthetic scenes under the *training*
lights, then every transform is scored on held-out scenes under the *test* lights:

* GW with the chapter-5 mapping error (GW's chromaticity does not depend on T, §5.6);
* a non-linear estimator (default soft-RETINEX-t0.01) with the angular error.

Run:  python examples/learned_sharpening.py [--world barnard1999|default] [--camera NAME] [--steps 200]
(``--quick``: the default world, 10 steps, 200 held-out scenes: a smoke test).
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np

from ccjax import sharpening
from ccjax.experiments.chapter5 import evaluate_transforms
from ccjax.world import World


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--world", choices=["barnard1999", "default"], default="barnard1999")
    parser.add_argument("--camera", default=None, help="camera of the default world")
    parser.add_argument("--nonlinear", default="soft-RETINEX-t0.01", help="non-linear estimator trained on the angle")
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--scenes", type=int, default=1000, help="held-out test scenes")
    parser.add_argument("--quick", action="store_true", help="default world, 10 steps, 200 scenes (smoke test)")
    args = parser.parse_args(argv)
    if args.quick:
        args.world, args.steps, args.scenes = "default", 10, 200

    world = World.barnard1999() if args.world == "barnard1999" else World.default(args.camera or "Canon EOS 5D Mark II")
    start = time.perf_counter()
    new = sharpening.new_sharpening(world)
    print(
        f"world {world.name}: new method lambda_P {new.lambda_p:g}, {new.iterations} iterations "
        f"({time.perf_counter() - start:.0f} s)"
    )
    rows = []
    for label, loss in (("GW", "mapping"), (args.nonlinear, "angular")):
        learned = sharpening.learned_sharpening(world, label, loss, steps=args.steps)
        head, tail = np.mean(learned.losses[:20]), np.mean(learned.losses[-20:])
        print(
            f"{label}: learned on {loss} in {learned.seconds:.0f} s; "
            f"training loss (mean of first/last 20 steps) {head:.3f} -> {tail:.3f}"
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
