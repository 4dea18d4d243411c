"""The neural-net estimator: an MLP on the binarised (r,g) histogram (Barnard 1999 §4.5.5).

The thesis' net (Cardei, Funt & Barnard [63-67]): a multi-layer
perceptron ``2500 -> 400 -> 30 -> 2``. Input ``b`` of the 2500 is 1 when at least one scene
chromaticity falls in the (r,g) bin ``b`` of a 50 x 50 grid of 0.02-wide cells; the two outputs are
the illuminant's (r,g). It is trained on synthetic scenes of the world's reflectances under its
TRAINING illuminants, with the true illuminant chromaticity as target and small Gaussian noise on
the training data. NEURAL-NET is trained on matte scenes, SP-NEURAL-NET on scenes with
specularities generated with statistics different from the test protocol's (§4.5.5, [64]).

What the thesis leaves open is fixed here and recorded in :class:`Recipe` and :class:`Schedule`:

* sigmoid hidden units, linear outputs, mean squared (r,g) error;
* Adam (optax) in place of back-propagation without momentum: 3000
  steps of 256 fresh scenes, learning rate 1e-2 with cosine decay, reach the thesis' Table 4.2
  accuracy in a few CPU minutes (plain SGD was not tried);
* a fully connected first layer instead of the thesis' rewiring of dormant links, which was a
  speed device (§4.5.5); it is evaluated sparsely (:func:`occupied_bins`), which is exact;
* the number of surfaces of a training scene is log-uniform on 1..64 (the test protocol's 8 is
  inside, and the net sees both sparse and rich histograms);
* noise: each training RGB is multiplied per channel by ``1 + 0.01 N(0, 1)`` ("small amount of
  normally distributed noise", 1 % of the signal);
* SP-NEURAL-NET's training specularities: each surface specular with probability 0.5 and
  ``U(0, 1)`` times the perfect white added (the test protocol uses 0.25 and ``U(0, 2)``), a
  different recipe as the thesis reports (§4.5.5, Table 4.3 discussion).

Trained weights live in the ccjax cache (:func:`ccjax._cache.cache_directory`) under ``neural/``,
keyed by :func:`ccjax._cache.content_key` of the world arrays the training reads (reflectances,
training illuminants, camera sensors) and of the :class:`Recipe`. The optimisation budget
(:class:`Schedule`) is recorded in the JSON file beside the weights; training again replaces them.
``ccjax train-net`` trains and saves; building NEURAL-NET for a world without weights raises
:class:`MissingWeightsError` saying how to train them (nothing is trained silently).

Modules: :mod:`._model` (input encoding, :class:`Mlp`, :class:`NeuralNet`), :mod:`._training`
(:class:`Recipe`, :class:`Schedule`, :func:`train`), :mod:`._weights` (the weight files),
:mod:`._log_chroma` (a baseline beyond the thesis: an MLP on the log-chroma histogram, trained on
photographs by ``ccjax train --method log-chroma-mlp``).
"""

from __future__ import annotations

from ccjax._cache import cache_directory as cache_dir
from ccjax.estimators.neural._log_chroma import LogChromaNet, init_log_chroma_net, log_chroma, log_chroma_histogram
from ccjax.estimators.neural._model import (
    BINS,
    N_INPUTS,
    SIMPLEX_MARGIN,
    Mlp,
    NeuralNet,
    binarised_histogram,
    histogram_bins,
    occupied_bins,
)
from ccjax.estimators.neural._training import (
    RECIPES,
    Recipe,
    Schedule,
    TrainingLog,
    train,
    training_batch,
    training_loss,
    training_world,
)
from ccjax.estimators.neural._weights import (
    MissingWeightsError,
    cache_key,
    has_weights,
    is_net_label,
    load,
    save,
    train_and_save,
    train_command,
    weights_path,
)
from ccjax.estimators.registry import register
from ccjax.estimators.simple import average_illuminant
from ccjax.world import World


def fit_neural(world: World, label: str = "NEURAL-NET") -> NeuralNet:
    """The estimator with the cached weights of net ``label`` for ``world`` (never trains).

    Raises:
        MissingWeightsError: no weights cached; the message gives the command that trains them.

    Arguments:
        world: the world the net was trained for.
        label: ``"NEURAL-NET"`` or ``"SP-NEURAL-NET"``.

    Returns:
        The :class:`NeuralNet` estimator.
    """
    return NeuralNet(net=load(world, label), fallback=average_illuminant(world))


@register(
    r"NEURAL-NET",
    example="NEURAL-NET",
    description="MLP on the binarised (r,g) histogram, matte training (§4.5.5; ccjax train-net)",
    input_kind="surfaces",
    # The fit reads weights that `ccjax train-net` replaces: a stored model could go stale.
    stored=False,
)
def _build_neural_net(world, match, **options):
    return fit_neural(world, "NEURAL-NET", **options)


@register(
    r"SP-NEURAL-NET",
    example="SP-NEURAL-NET",
    description="the MLP trained with specularities (§4.5.5; ccjax train-net --specular)",
    input_kind="surfaces",
    stored=False,
)
def _build_sp_neural_net(world, match, **options):
    return fit_neural(world, "SP-NEURAL-NET", **options)


@register(
    r"log-chroma-mlp",
    example="log-chroma-mlp",
    description="MLP on the log-chroma histogram (beyond the thesis; untrained until ccjax train)",
    input_kind="surfaces",
    untrained=True,
)
def _build_log_chroma(world, match, *, seed: int = 0, **options):
    import jax

    return init_log_chroma_net(jax.random.key(seed), average_illuminant(world), **options)


__all__ = [
    "BINS",
    "N_INPUTS",
    "RECIPES",
    "SIMPLEX_MARGIN",
    "LogChromaNet",
    "MissingWeightsError",
    "Mlp",
    "NeuralNet",
    "Recipe",
    "Schedule",
    "TrainingLog",
    "binarised_histogram",
    "cache_dir",
    "cache_key",
    "fit_neural",
    "has_weights",
    "histogram_bins",
    "init_log_chroma_net",
    "is_net_label",
    "load",
    "log_chroma",
    "log_chroma_histogram",
    "occupied_bins",
    "save",
    "train",
    "train_and_save",
    "train_command",
    "training_batch",
    "training_loss",
    "training_world",
    "weights_path",
]
