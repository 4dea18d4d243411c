"""Deprecated: renamed to :mod:`ccjax.evaluation.scored_folder` (a name that says what it holds). It
warns on import and on each use of a name, naming the replacement, and will be removed in the next
release."""

from ccjax._deprecation import moved_names, warn_moved_module

warn_moved_module("ccjax.evaluation.folders", "ccjax.evaluation.scored_folder")
__getattr__, __dir__ = moved_names("ccjax.evaluation.folders", "ccjax.evaluation.scored_folder")
