"""The package version, in one place: ``pyproject.toml`` reads it (setuptools' dynamic version),
``ccjax.__version__`` re-exports it, and the model files record it (:mod:`ccjax._cache`)."""

__version__ = "0.3.0"
