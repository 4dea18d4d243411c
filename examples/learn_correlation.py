"""A jitted training step with ccjax losses and augmentation: the Colour by Correlation matrix learned on
synthetic images, compared on held-out images with the thesis' estimators and grey edge.

The thesis counts the reflectances' (r,g) per training illuminant, smooths and logs the frequencies
(§4.5.4). Here the same 2-D C-by-C-MMSE estimator gets its matrix from Adam instead, starting from
the counted one. One compiled step does everything:

* draws a batch from a fixed pool of Mondrian layouts and relights it spectrally under random
  *training* lights (``ccjax.augment.relight_mondrians``: the same surfaces, a new light and its
  ground truth, fresh shading and noise);
* turns every image into a surface list (every 4th pixel in each direction, as a camera
  thumbnail would);
* runs ``vmap(model)`` and takes the angular loss (``ccjax.losses.angular_loss``, safe gradients);
* applies an Adam update (optax) to the matrix.

Held-out images are rendered under the *test* lights (none of them seen in training) from other
layouts; the learned matrix is scored beside the counted one, grey world, grey edge (1, 6, 2) and
gamut mapping (ECRULE-MV and ND-ECRULE-SCWIA-12).

Run:  python examples/learn_correlation.py [--steps 300] [--images 500]; ``--quick``: a smoke test.
"""

from __future__ import annotations

import argparse
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax

from ccjax import augment, losses, scenes
from ccjax.estimators import registry
from ccjax.world import World

SIZE = 64
STRIDE = 4
GAMUT = ("ECRULE-MV", "ND-ECRULE-SCWIA-12")


def as_surfaces(images):
    """``(B, H, W, 3)`` -> every ``STRIDE``-th pixel as a surface list ``(B, P, 3)`` and its mask."""
    pixels = images[:, ::STRIDE, ::STRIDE].reshape(images.shape[0], -1, 3)
    return pixels, jnp.sum(pixels, axis=-1) > 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--batch", type=int, default=64, help="training images per step")
    parser.add_argument("--pool", type=int, default=512, help="Mondrian layouts the batches are drawn from")
    parser.add_argument("--images", type=int, default=500, help="held-out test images")
    parser.add_argument("--learning-rate", type=float, default=0.05)
    parser.add_argument("--quick", action="store_true", help="20 steps, 100 held-out images (smoke test)")
    args = parser.parse_args(argv)
    gamut = GAMUT
    if args.quick:
        args.steps, args.batch, args.pool, args.images, gamut = 20, 32, 64, 100, GAMUT[:1]

    world = World.default()
    counted = registry.fit("C-by-C-MMSE", world)
    # Training images are rendered under the training lights only.
    training_world = eqx.tree_at(lambda w: w.test_illuminants, world, world.train_illuminants)
    train_tables = scenes.SceneTables.from_world(training_world)
    pool = scenes.sample_mondrians(jax.random.key(1), training_world, args.pool, height=SIZE, width=SIZE, n_patches=12)
    noise = scenes.ShotNoise(a=1e-4, b=0.0)
    optimiser = optax.adam(args.learning_rate)

    def loss_of(matrix, images, truth):
        model = eqx.tree_at(lambda m: m.log_probability, counted, matrix)
        rgb, mask = as_surfaces(images)
        return losses.angular_loss(jax.vmap(model)(rgb, mask).illuminant, truth)

    @jax.jit
    def step(matrix, state, key):
        key_pick, key_light = jax.random.split(key)
        chosen = jax.random.choice(key_pick, args.pool, (args.batch,), replace=False)
        batch = jax.tree_util.tree_map(lambda x: x[chosen], pool)
        relit = augment.relight_mondrians(key_light, train_tables, batch, noise=noise)
        loss, grad = jax.value_and_grad(loss_of)(matrix, relit.image, relit.illuminant)
        updates, state = optimiser.update(grad, state)
        return optax.apply_updates(matrix, updates), state, loss

    matrix, state, trace = counted.log_probability, optimiser.init(counted.log_probability), []
    start = time.perf_counter()
    for index in range(args.steps):
        matrix, state, loss = step(matrix, state, jax.random.fold_in(jax.random.key(2), index))
        trace.append(float(loss))
    seconds = time.perf_counter() - start
    window = max(1, min(20, args.steps // 4))
    print(
        f"C-by-C-MMSE matrix: {args.steps} jitted steps x {args.batch} relit images in {seconds:.0f} s; "
        f"training angular loss (first/last {window} steps) {np.mean(trace[:window]):.3f} -> "
        f"{np.mean(trace[-window:]):.3f} deg"
    )
    learned = eqx.tree_at(lambda m: m.log_probability, counted, matrix)

    held_out = scenes.sample_mondrians(
        jax.random.key(99), world, args.images, height=SIZE, width=SIZE, n_patches=12, noise=noise
    )
    rgb, mask = as_surfaces(held_out.image)
    models = {"C-by-C-MMSE (learned)": learned, "C-by-C-MMSE (counted)": counted}
    models |= {label: registry.fit_cached(label, world) for label in ("GW", *gamut)}
    errors = {}
    for name, model in models.items():
        estimate = jax.jit(jax.vmap(model))(rgb, mask).illuminant
        errors[name] = np.asarray(losses.angular_errors(estimate, held_out.illuminant))
    edge = registry.fit_cached("grey-edge-1-6-2", world)
    image_mask = jnp.ones(held_out.image.shape[:3], bool)
    estimate = jax.jit(jax.vmap(edge))(held_out.image, image_mask).illuminant
    errors["grey-edge-1-6-2"] = np.asarray(losses.angular_errors(estimate, held_out.illuminant))

    lights = world.test_illuminants.shape[0]
    print(f"\nheld-out: {args.images} Mondrians of {SIZE}x{SIZE} under the {lights} test lights")
    print(f"{'method':<26}{'median':>8}{'mean':>8}{'worst25':>9}")
    for name, values in sorted(errors.items(), key=lambda item: np.median(item[1])):
        worst = np.mean(np.sort(values)[-max(1, len(values) // 4) :])
        print(f"{name:<26}{np.median(values):>8.3f}{np.mean(values):>8.3f}{worst:>9.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
