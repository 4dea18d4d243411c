"""Learn the Colour by Correlation matrix by gradient descent and compare it with the counted one.

The thesis counts the reflectances' (r,g) per training illuminant, smooths and logs the frequencies
(§4.5.4). Here the same 2-D C-by-C-MMSE estimator — hard (r,g) bins, posterior = softmax of the
summed matrix rows — gets its matrix from Adam instead: each column is ``log_softmax`` of free
parameters (so it stays a log-probability distribution over bins), and the loss is the mean squared
(r,g) error of the MMSE estimate on synthetic scenes under the *training* illuminants (4, 8, 16
and 32 surfaces in turn). Two starts:
uniform (learned from scratch) and the counted matrix (fine-tuned). Every matrix is then scored on
held-out scenes under the *test* illuminants (4x denser, none of them seen in training).

Run:  python examples/learn_correlation.py [--world barnard1999|default] [--steps 1500] [--surfaces 4,8,16,32]
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax

from ccjax import metrics
from ccjax.estimators import registry
from ccjax.experiments import sweep
from ccjax.scenes import SceneTables, sample_batch, scene_keys
from ccjax.world import World


def learn(model, start, tables, *, steps, batch, surfaces, learning_rate, key):
    """Adam on the matrix logits; returns the learned log-probability matrix and the loss trace."""

    def loss_fn(logits, scenes):
        candidate = dataclasses.replace(model, log_probability=jax.nn.log_softmax(logits, axis=0))
        estimate = jax.vmap(candidate)(scenes.rgb, scenes.mask).illuminant
        return jnp.mean(jnp.sum((metrics.rg(estimate) - metrics.rg(scenes.illuminant)) ** 2, axis=-1))

    optimiser = optax.adam(learning_rate)

    @eqx.filter_jit
    def step(logits, state, keys, n_surfaces):
        scenes = sample_batch(keys, tables, n_surfaces)
        loss, grad = jax.value_and_grad(loss_fn)(logits, scenes)
        updates, state = optimiser.update(grad, state)
        return optax.apply_updates(logits, updates), state, loss

    logits, state, losses = start, optimiser.init(start), []
    for index in range(steps):
        # Cycle through the surface counts so the matrix is trained for all of them.
        logits, state, loss = step(
            logits, state, scene_keys(key, index * batch, batch), surfaces[index % len(surfaces)]
        )
        losses.append(float(loss))
    return jax.nn.log_softmax(logits, axis=0), np.asarray(losses)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--world", choices=["barnard1999", "default"], default="barnard1999")
    parser.add_argument("--steps", type=int, default=1200)
    parser.add_argument("--batch", type=int, default=256, help="training scenes per step")
    parser.add_argument("--surfaces", default="4,8,16,32", help="surface counts of the training scenes, cycled")
    parser.add_argument("--learning-rate", type=float, default=0.01)
    parser.add_argument("--scenes", type=int, default=1000, help="held-out test scenes per surface count")
    args = parser.parse_args()

    world = World.barnard1999() if args.world == "barnard1999" else World.default()
    counted = registry.fit("C-by-C-MMSE", world)
    # Training scenes are drawn under the training illuminants only.
    training = SceneTables.from_world(dataclasses.replace(world, test_illuminants=world.train_illuminants))
    starts = {
        "learned (uniform start)": jnp.zeros_like(counted.log_probability),
        "fine-tuned (counted start)": counted.log_probability,
    }
    matrices = {"counted (thesis)": counted}
    for name, start in starts.items():
        begin = time.perf_counter()
        learned, losses = learn(
            counted,
            start,
            training,
            steps=args.steps,
            batch=args.batch,
            surfaces=[int(n) for n in args.surfaces.split(",")],
            learning_rate=args.learning_rate,
            key=jax.random.key(2024),
        )
        print(
            f"{name}: {args.steps} steps x {args.batch} scenes in {time.perf_counter() - begin:.0f} s; "
            f"training RMS rg error (first/last 50 steps) {np.sqrt(losses[:50].mean()):.4f} -> "
            f"{np.sqrt(losses[-50:].mean()):.4f}"
        )
        matrices[name] = dataclasses.replace(counted, log_probability=learned)

    result = sweep(world, list(matrices.items()), [4, 8, 16, 32], args.scenes, jax.random.key(7), progress=False)
    print(
        f"\nheld-out: {args.scenes} scenes per surface count under the "
        f"{world.test_illuminants.shape[0]} test illuminants ({world.name})"
    )
    print(result.table("rg"))
    print()
    print(result.table("angular"))


if __name__ == "__main__":
    main()
