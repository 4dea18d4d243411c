"""The image commands' group: ``ccjax estimate``, ``ccjax correct`` and ``ccjax evaluate`` (linear
images, Barnard 1999 §4.4), each in its own module (:mod:`ccjax.cli.estimate`,
:mod:`ccjax.cli.correct`, :mod:`ccjax.cli.evaluate`) over the execution layer's folder calls; their
shared options are in :mod:`ccjax.cli.image_options`."""

from __future__ import annotations

from ccjax.cli.correct import add_correct
from ccjax.cli.estimate import add_estimate
from ccjax.cli.evaluate import add_evaluate

COMMANDS = [add_estimate, add_correct, add_evaluate]
