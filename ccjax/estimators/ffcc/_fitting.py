"""Training FFCC (Barron & Tsai 2017, §3-§4): L-BFGS on the histograms of the training images,
computed once, in the preconditioned Fourier parametrisation of the filters and the bias map.

The regulariser of each filter and of the bias map is total variation (squared differences of
adjacent bins, periodic) plus L2 (FFCC §3, eq. 10-12), diagonal in the Fourier domain: bin ``k``
costs ``(tv * TV(k) + l2) |fft2(F)(k)|^2``. The model is optimised in the variables ``z`` with
``fft2(F) = fft2(z) / (n sqrt(tv * TV + l2))``, where the regulariser is ``||z||^2`` (FFCC §3.2,
"preconditioning"; the reference code's ``Fft2RegularizerToPreconditioner``), so L-BFGS sees a
well-conditioned problem. Two passes as in the reference code: 16 iterations of the convex
cross-entropy loss, then 64 of the von Mises negative log-likelihood of the true light (FFCC §4).
Hyperparameters: by default the reference code's, tuned by its authors for the Canon 600D
thumbnails of the NUS-8 set (``ChengCanon600DThumbHyperparams``); the training layer chooses
among the reference's settings for seven NUS-8 cameras inside the training images
(:func:`ccjax.estimators.ffcc.choose`). The histogram's origin and bin size are fitted to the
training lights (:func:`fit_origin`, :func:`fit_grid`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jaxtyping import Array, Bool, Complex, Float

from ccjax.backends import block_scenes
from ccjax.estimators.ffcc._model import FFCC
from ccjax.estimators.ffcc._vonmises import fit_von_mises, gaussian_nll
from ccjax.estimators.neural import log_chroma
from ccjax.precision import matmul

__all__ = [
    "Hyperparameters",
    "TrainingRecord",
    "fit_grid",
    "fit_origin",
    "from_latent",
    "histograms",
    "loss",
    "preconditioner",
    "to_latent",
    "train",
]


FILL = 0.75
"""The largest share of the histogram's width the training lights' log-chroma range may fill
(:func:`fit_grid`)."""

PAD = 128
"""Training sets of at least this many images are padded (with images of weight 0) to a multiple
of it; smaller ones to the next power of two (at least 8), so that the halves a hyperparameter
choice trains on are not padded to ten times their size."""


def padded_count(count: int) -> int:
    """The number of images a training set of ``count`` is padded to (:data:`PAD`): few compiled
    solvers serve every size, and a small set costs a small solver.

    Arguments:
        count: the training images.

    Returns:
        The next power of two at or above ``count`` (at least 8) below :data:`PAD`, else the next
        multiple of :data:`PAD`.
    """
    if count >= PAD:
        return -(-count // PAD) * PAD
    return max(8, 1 << (count - 1).bit_length())


@dataclass(frozen=True)
class Hyperparameters:
    """FFCC's training settings (the reference code's ``HYPERPARAMS`` and ``TRAINING`` names).

    Attributes:
        crossent: weight of the cross-entropy loss (first pass).
        vonmises: weight of the von Mises negative log-likelihood (second pass).
        expected_error: weight of the expected squared log-chroma error under the fitted
            distribution, ``E||x - truth||^2 * 32`` (the reference code's ``expected_squared_error``
            loss, an expected angular error; 0: the likelihood alone, the reference default).
        filter_tv, filter_l2: total-variation and L2 weights of the pixel and edge filters.
        bias_tv, bias_l2: those of the bias map.
        diagonal: variance added to the fitted covariance, bins^2.
        pretrain_iterations, iterations: L-BFGS iterations of the two passes.
        memory: L-BFGS history length.
    """

    crossent: float = 2**-25.25
    vonmises: float = 2**-1.5
    expected_error: float = 0.0
    filter_tv: tuple[float, float] = (2**-27.5, 2**-24.5)
    filter_l2: tuple[float, float] = (2**-39.25, 2**-38.75)
    bias_tv: float = 2**-21.75
    bias_l2: float = 2**-44.75
    diagonal: float = 1.0
    pretrain_iterations: int = 16
    iterations: int = 64
    memory: int = 32


@dataclass
class TrainingRecord:
    """What one fit did.

    Attributes:
        losses: the objective after each L-BFGS pass.
        seconds: the fit's wall-clock seconds.
    """

    losses: list[float]
    seconds: float


def preconditioner(n: int, tv: float, l2: float) -> Float[Array, "n n"]:
    """``1 / (n sqrt(tv * TV(k) + l2))`` at every FFT bin ``k`` of an ``n x n`` map, with
    ``TV(k) = sum over the two axes of |1 - exp(-2 pi i k / n)|^2 / 8`` (the reference code's
    difference filters ``[-1, 1] / sqrt(8)``).

    Arguments:
        n: the map's size.
        tv, l2: the regulariser's weights (``l2 > 0``).

    Returns:
        ``(n, n)`` the scale of ``fft2(z)`` that gives ``fft2(F)``.
    """
    frequency = 2 * jnp.pi * jnp.arange(n, dtype=float) / n
    variation = (2 - 2 * jnp.cos(frequency)) / 8
    regulariser = tv * (variation[:, None] + variation[None, :]) + l2
    return 1.0 / (n * jnp.sqrt(regulariser))


def _latent_fft(latent: Float[Array, "... n n"], scale: Float[Array, "... n n"]) -> Array:
    """``rfft2`` of the map whose preconditioned variables are ``latent`` (``scale`` is symmetric,
    so the map is real and its half spectrum is all there is)."""
    spectrum = jnp.fft.rfft2(latent)
    return spectrum * scale[..., : spectrum.shape[-1]].astype(spectrum.dtype)


def from_latent(latent: Float[Array, "... n n"], scale: Float[Array, "... n n"]) -> Float[Array, "... n n"]:
    """The map whose preconditioned variables are ``latent`` (FFCC §3.3's parametrisation).

    Arguments:
        latent: the preconditioned variables of one or more ``n x n`` maps.
        scale: :func:`preconditioner` of the map's size and weights.

    Returns:
        The maps in the histogram's domain.
    """
    return jnp.fft.irfft2(_latent_fft(latent, scale), s=latent.shape[-2:]).astype(latent.dtype)


def to_latent(maps: Float[Array, "... n n"], scale: Float[Array, "... n n"]) -> Float[Array, "... n n"]:
    """The preconditioned variables of ``maps``: the inverse of :func:`from_latent`.

    Arguments:
        maps: one or more ``n x n`` maps in the histogram's domain.
        scale: :func:`preconditioner` of their size and weights.

    Returns:
        ``latent`` with ``from_latent(latent, scale) == maps``.
    """
    spectrum = jnp.fft.rfft2(maps)
    spectrum = spectrum / scale[..., : spectrum.shape[-1]].astype(spectrum.dtype)
    return jnp.fft.irfft2(spectrum, s=maps.shape[-2:]).astype(maps.dtype)


def histograms(
    model: FFCC, images: Float[Array, "N H W 3"], masks: Bool[Array, "N H W"], chunk: int = 256
) -> Float[Array, "N 2 n n"]:
    """Every image's histogram on ``model``'s grid, computed in chunks (bounded memory).

    Arguments:
        model: the FFCC model whose grid and channels are used.
        images: ``(N, H, W, 3)`` linear camera RGB.
        masks: ``(N, H, W)`` usable pixels.
        chunk: images per compiled call.

    Returns:
        ``(N, 2, n, n)`` pixel and edge histograms.
    """
    parts = [
        _histograms(model, images[start : start + chunk], masks[start : start + chunk])
        for start in range(0, len(images), chunk)
    ]
    return jnp.concatenate(parts)


@eqx.filter_jit
def _histograms(model: FFCC, images: Float[Array, "N H W 3"], masks: Bool[Array, "N H W"]) -> Float[Array, "N 2 n n"]:
    return jax.vmap(lambda image, mask: model.histogram(image, mask))(images, masks)


def fit_origin(truth_uv: Float[Array, "N 2"], bins: int, bin_size) -> Float[Array, "2"]:
    """The grid's origin that centres the training lights' log-chroma range on the histogram
    (on whole bins), so that the torus holds every training light (a choice made on the training
    images only).

    Arguments:
        truth_uv: ``(N, 2)`` the training lights' log-chroma.
        bins: the histogram's size ``n``.
        bin_size: one bin's width in log-chroma units.

    Returns:
        ``(2,)`` the ``(u, v)`` of bin ``(0, 0)``.
    """
    middle = 0.5 * (jnp.min(truth_uv, axis=0) + jnp.max(truth_uv, axis=0))
    return bin_size * jnp.round(middle / bin_size) - bin_size * (bins // 2)


def fit_grid(truth_uv: Float[Array, "N 2"], bins: int, bin_size: float, fill: float = FILL) -> float:
    """The bin size: ``bin_size`` doubled until the training lights' log-chroma range fills at
    most ``fill`` of the histogram's width on each axis. The histogram wraps (FFCC §3), so the
    colours of a scene lit near the window's edge alias onto its far side; a window the lights
    nearly fill leaves no margin for them (a choice made on the training lights only).

    Arguments:
        truth_uv: ``(N, 2)`` the training lights' log-chroma.
        bins: bins per axis.
        bin_size: the narrowest bin considered.
        fill: the largest share of the width the lights' range may take.

    Returns:
        The bin size.
    """
    spread = float(jnp.max(jnp.max(truth_uv, axis=0) - jnp.min(truth_uv, axis=0)))
    while spread > fill * bins * bin_size:
        bin_size *= 2
    return bin_size


def _bilinear(target: Float[Array, "2"], n: int) -> Float[Array, "n n"]:
    """The ground truth as a PMF: bilinear weights on the 4 bins around ``target`` (in bins)."""
    low = jnp.floor(target)
    weight = target - low
    rows = jnp.stack([1 - weight[0], weight[0]])
    cols = jnp.stack([1 - weight[1], weight[1]])
    i = jnp.mod(low[0].astype(jnp.int32) + jnp.arange(2, dtype=jnp.int32), n)
    j = jnp.mod(low[1].astype(jnp.int32) + jnp.arange(2, dtype=jnp.int32), n)
    return jnp.zeros((n, n), target.dtype).at[i[:, None], j[None, :]].add(rows[:, None] * cols[None, :])


def loss(
    latent: tuple[Float[Array, "2 n n"], Float[Array, "n n"]],
    scales: tuple[Float[Array, "2 n n"], Float[Array, "n n"]],
    histogram_fft: Complex[Array, "N 2 n m"],
    truth: Float[Array, "N 2"],
    weights: Float[Array, "3"],
    diagonal: float,
    bin_size: Float[Array, ""] | float,
    counted: Float[Array, " N"] | None = None,
    anchor: tuple[Float[Array, "2 n n"], Float[Array, "n n"]] | None = None,
) -> Float[Array, ""]:
    """FFCC's training objective in the preconditioned variables (FFCC §3-§4): the mean over the
    images of ``weights . (cross-entropy, von Mises NLL, expected squared error)`` plus
    ``0.5 ||latent - anchor||^2`` (the regulariser, centred on a prior model's variables, or on
    zero without one).

    Arguments:
        latent: ``(filters (2, n, n), bias (n, n))`` preconditioned variables.
        scales: their :func:`preconditioner` maps.
        histogram_fft: ``(N, 2, n, n // 2 + 1)`` real FFTs (``rfft2``) of the training histograms.
        truth: ``(N, 2)`` the true lights' positions on the grid, in bins from the origin.
        weights: ``(3,)`` the weights of the three losses.
        diagonal: variance added to the fitted covariance, bins^2.
        bin_size: log-chroma width of a bin.
        counted: ``(N,)`` weight of each image in the mean (None: 1 each); padding images
            weigh 0.
        anchor: the prior model's preconditioned variables (None: zero).

    Returns:
        The objective.
    """
    filters_latent, bias_latent = latent
    filters_fft = _latent_fft(filters_latent, scales[0])
    bias = from_latent(bias_latent, scales[1])
    n = bias.shape[0]

    def one(x_fft, target):
        scores = jnp.fft.irfft2(jnp.sum(x_fft * filters_fft, axis=0), s=(n, n)).astype(bias.dtype) + bias
        log_p = jax.nn.log_softmax(scores.reshape(-1)).reshape(n, n)
        crossent = -jnp.sum(_bilinear(target, n) * log_p)
        mean, covariance = fit_von_mises(jnp.exp(log_p), diagonal)
        nll = gaussian_nll(target, mean, covariance) - jnp.log(2 * jnp.pi * diagonal)
        # Expected squared log-chroma error times 32 (the reference's isotropic error scale).
        expected = 32.0 * bin_size**2 * (jnp.sum((mean - target) ** 2) + jnp.trace(covariance))
        return matmul(jnp.stack([crossent, nll, expected]), weights)

    # Blocks of images mapped one after another keep each block's spectra, softmax and moments in
    # cache (measured 1.3x faster than one vmap over a Cube+ fold on a CPU).
    block = block_scenes(jax.default_backend())
    per_image = jax.lax.map(lambda pair: one(*pair), (histogram_fft, truth), batch_size=block)
    data = jnp.mean(per_image) if counted is None else jnp.sum(counted * per_image) / jnp.sum(counted)
    if anchor is not None:
        filters_latent, bias_latent = filters_latent - anchor[0], bias_latent - anchor[1]
    return data + 0.5 * (jnp.sum(filters_latent**2) + jnp.sum(bias_latent**2))


@eqx.filter_jit
def _minimise(
    latent, anchor, scales, histogram_fft, truth, counted, weights, diagonal, bin_size, iterations, memory: int
):
    def objective(params):
        return loss(params, scales, histogram_fft, truth, weights, diagonal, bin_size, counted, anchor)

    solver = optax.lbfgs(memory_size=memory)
    value_and_grad = optax.value_and_grad_from_state(objective)

    def step(_, carry):
        params, state = carry
        value, grad = value_and_grad(params, state=state)
        updates, state = solver.update(grad, state, params, value=value, grad=grad, value_fn=objective)
        return optax.apply_updates(params, updates), state

    with jax.numpy_dtype_promotion("standard"):
        latent, _ = jax.lax.fori_loop(0, iterations, step, (latent, solver.init(latent)))
    return latent, objective(latent)


def train(
    model: FFCC,
    images: Float[Array | np.ndarray, "N H W 3"],
    masks: Bool[Array | np.ndarray, "N H W"],
    illuminants: Float[Array | np.ndarray, "N 3"],
    hyperparameters: Hyperparameters = Hyperparameters(),
    prior: FFCC | None = None,
    *,
    window: Float[Array | np.ndarray, "M 3"] | None = None,
) -> tuple[FFCC, TrainingRecord]:
    """Train FFCC on images with ground truth (module docstring).

    With ``prior`` (a model trained elsewhere, e.g. on rendered images,
    :func:`ccjax.training.pretrain`) the fit keeps the prior's bin size, starts from the
    prior's filters and bias map and centres the regulariser on them: ``0.5 ||z - z_prior||^2``
    in the preconditioned variables, a Gaussian prior whose mean is the prior model and whose
    covariance is FFCC's regulariser (the "L2-SP" transfer of Li, Grandvalet & Davoine, ICML
    2018, in FFCC's parametrisation). The filters act by convolution, so a grid re-centred on
    the training lights by whole bins moves only the bias map (rolled by the same bins).

    Arguments:
        model: the start (its bin count is kept and its bin size the narrowest considered,
            :func:`fit_grid`; its filters are not used: training starts from zero, as the
            objective's first pass is convex).
        images: ``(N, H, W, 3)`` linear RGB, 1.0 = saturation.
        masks: ``(N, H, W)`` usable pixels.
        illuminants: ``(N, 3)`` the true lights (camera RGB, any scale, every channel positive).
        hyperparameters: the :class:`Hyperparameters`.
        prior: a trained FFCC of ``model``'s bin count to fine-tune (None: train from zero).
        window: ``(M, 3)`` lights the histogram must hold besides the training lights (every
            channel positive): the grid's bin size and origin are fitted to both, so a light
            outside the training set's range but in ``window`` does not wrap onto the far side of
            the torus (a model that will see other cameras' lights; None: the training lights
            alone, the reference code's choice). With ``prior`` the bin size stays the prior's and
            the window only moves the origin.

    Returns:
        ``(trained FFCC, TrainingRecord)``.

    Raises:
        ValueError: no image, a light with a channel at or below 0, or a prior of another bin
            count.
    """
    start = time.perf_counter()
    illuminants = jnp.asarray(illuminants)
    if illuminants.shape[0] == 0:
        raise ValueError("images: FFCC needs at least one training image")
    if not bool(jnp.all(illuminants > 0)):
        raise ValueError("illuminants: every channel of every training light must be positive")
    h = hyperparameters
    n = model.bins
    if prior is not None and prior.bins != n:
        raise ValueError(f"prior: expected a model of {n} bins (the model's), got {prior.bins}")
    truth_uv = log_chroma(illuminants)
    held = truth_uv
    if window is not None:
        window = jnp.asarray(window, truth_uv.dtype)
        if window.ndim != 2 or window.shape[-1] != 3 or not bool(jnp.all(window > 0)):
            raise ValueError(f"window: expected (M, 3) lights with every channel positive, got shape {window.shape}")
        held = jnp.concatenate([truth_uv, log_chroma(window)])
    grid = float(model.bin_size) if prior is None else float(prior.bin_size)
    size = jnp.asarray(grid if prior is not None else fit_grid(held, n, grid), model.bias.dtype)
    origin = fit_origin(held, n, size).astype(model.bias.dtype)
    model = eqx.tree_at(lambda m: (m.origin, m.bin_size), model, (origin, size))
    histogram_fft = jnp.fft.rfft2(histograms(model, jnp.asarray(images), jnp.asarray(masks)))
    truth = (truth_uv - origin) / size
    # Pad the training set with images that weigh 0: training sets of nearby sizes (the folds of a
    # cross-validation) share one compiled solver.
    count = truth.shape[0]
    extra = padded_count(count) - count
    counted = jnp.concatenate([jnp.ones(count, truth.dtype), jnp.zeros(extra, truth.dtype)])
    histogram_fft = jnp.concatenate([histogram_fft, jnp.repeat(histogram_fft[:1], extra, axis=0)])
    truth = jnp.concatenate([truth, jnp.repeat(truth[:1], extra, axis=0)])
    scales = (
        jnp.stack([preconditioner(n, tv, l2) for tv, l2 in zip(h.filter_tv, h.filter_l2, strict=True)]),
        preconditioner(n, h.bias_tv, h.bias_l2),
    )
    latent = (jnp.zeros((2, n, n), model.bias.dtype), jnp.zeros((n, n), model.bias.dtype))
    anchor = None
    if prior is not None:
        shift = jnp.round((origin - prior.origin) / size).astype(jnp.int32)
        bias = jnp.roll(prior.bias, (-int(shift[0]), -int(shift[1])), axis=(0, 1))
        anchor = (to_latent(prior.filters, scales[0]), to_latent(bias, scales[1]))
        latent = anchor
    losses = []
    passes = ((h.pretrain_iterations, [h.crossent, 0.0, 0.0]), (h.iterations, [0.0, h.vonmises, h.expected_error]))
    for iterations, weights in passes:
        if iterations == 0:
            continue
        latent, value = _minimise(
            latent,
            anchor,
            scales,
            histogram_fft,
            truth,
            counted,
            jnp.asarray(weights, model.bias.dtype),
            h.diagonal,
            size,
            jnp.asarray(iterations, jnp.int32),  # traced: both passes share one compiled solver
            h.memory,
        )
        losses.append(float(value))
    filters = from_latent(latent[0], scales[0])
    bias = from_latent(latent[1], scales[1])
    trained = FFCC(filters, bias, origin, bin_size=size, diagonal=h.diagonal, minimum=model.minimum, pool=model.pool)
    return trained, TrainingRecord([float(x) for x in np.asarray(losses)], time.perf_counter() - start)
