"""From an image to an estimator's input (Barnard 1999 §4.6, Table 4.6).

:func:`prepare` gives what a model is called with, per model by default
(``model.default_preprocessing``, overridable per call):

* ``pixels`` (statistics methods: grey world, shades of grey, max-RGB, grey edge): the image and
  its usable mask, every pixel that is not clipped, has no zero channel and lies inside the
  optional user mask (the field's protocol); :func:`run_model` gives surface models the pixel
  list (grey world: the masked mean, the same estimate from one reduction).
* ``ave5`` and the other Table 4.6 methods (:data:`TABLE_4_6`; world-based methods: gamut
  mapping, Colour by Correlation, nets, DB-GW): the thesis' surface list. Clipped pixels are
  dropped (§2.7), and too-dark ones (R+G+B below ``dark`` = 2 % of the 99th percentile of the
  usable pixels' R+G+B, :func:`usable_pixels`), then block averaging (default 5x5, "roughly
  optimal", §4.6), block averaging + RGB clustering, block averaging + convex-hull reduction, or
  region-growing segmentation reduce the image to a list of surfaces, padded to a power of two
  (:func:`padded_size`) so jit compiles once per size class.

Modules: :mod:`~ccjax.preprocessing._rules` (usable pixels), :mod:`~ccjax.preprocessing._reduction`
(block averages, clustering, hull reduction, segmentation), :mod:`~ccjax.preprocessing._methods`
(the methods by name, surface lists), :mod:`~ccjax.preprocessing._inputs` (each model's input,
running a model on it); every public name is importable from here.
"""

from ccjax.preprocessing._inputs import (
    estimate_image,
    estimate_pixels,
    input_key,
    input_rule,
    input_shapes,
    masked_mean,
    prepare,
    prepare_input,
    resolve,
    run_model,
)
from ccjax.preprocessing._methods import (
    TABLE_4_6,
    Preprocessing,
    as_preprocessing,
    padded_size,
    surfaces,
)
from ccjax.preprocessing._reduction import (
    block_average,
    cluster_rgb,
    hull_reduce,
    segment,
)
from ccjax.preprocessing._rules import (
    DEFAULT_DARK,
    DEFAULT_PERCENTILE,
    DEFAULT_PREPROCESSING,
    PIXELS,
    usable_pixels,
)

__all__ = [
    "DEFAULT_DARK",
    "DEFAULT_PERCENTILE",
    "DEFAULT_PREPROCESSING",
    "PIXELS",
    "TABLE_4_6",
    "Preprocessing",
    "as_preprocessing",
    "block_average",
    "cluster_rgb",
    "estimate_image",
    "estimate_pixels",
    "hull_reduce",
    "input_key",
    "input_rule",
    "input_shapes",
    "masked_mean",
    "padded_size",
    "prepare",
    "prepare_input",
    "resolve",
    "run_model",
    "segment",
    "surfaces",
    "usable_pixels",
]
