"""The one on-disk cache: one directory rule, one content key, one serialisation.

Everything ccjax keeps between runs lives under :func:`cache_directory`: fitted arrays (``.npz`` +
``.json``), fitted models (equinox leaf serialisation + ``.json`` metadata with a format version,
so model files can be shared between users) and JAX's persistent compilation cache (``xla/``).
Nothing is pickled: a cache file can be read without running code from it.
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import hashlib
import importlib
import io
import json
import os
import sys
import tempfile
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, TypeVar

import equinox as eqx
import jax
import numpy as np

FORMAT_VERSION = 1
"""Version of the cache and model-file layout; a mismatch is rebuilt (cache) or refused (models)."""

ModelT = TypeVar("ModelT", bound=eqx.Module)


def cache_directory() -> Path:
    """``$CCJAX_CACHE``, else the platform's user cache directory + ``ccjax``.

    Returns:
        The directory (not created).
    """
    if os.environ.get("CCJAX_CACHE"):
        return Path(os.environ["CCJAX_CACHE"]).expanduser()
    if sys.platform == "win32":
        base = Path(os.environ.get("LOCALAPPDATA", Path.home() / "AppData" / "Local"))
    elif sys.platform == "darwin":
        base = Path.home() / "Library" / "Caches"
    else:
        base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "ccjax"


def enable_compilation_cache() -> None:
    """Keep XLA's compiled programs in ``<cache>/xla`` (unless the user configured a cache), so a
    second run of a command skips compilation as well as fitting."""
    # The option is a dynamic attribute of jax.config (pyright cannot see it).
    if not getattr(jax.config, "jax_compilation_cache_dir"):  # noqa: B009
        jax.config.update("jax_compilation_cache_dir", str(cache_directory() / "xla"))
        # Small programs too: a command compiles dozens of them, each well under a second.
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.05)


@functools.cache
def code_fingerprint() -> str:
    """A digest of ccjax's own source files, part of the key of cached fits: a fit cached by one
    version of the code is never read by another (editing a fit function invalidates its cache).

    Returns:
        A 16-character hex digest (computed once per process; about 10 ms).
    """
    digest = hashlib.sha256()
    root = Path(__file__).resolve().parent
    for path in sorted(root.rglob("*.py")):
        digest.update(str(path.relative_to(root)).encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def _update(digest: Any, part: Any) -> None:
    """Feed one key part to ``digest``: arrays by dtype, shape and bytes; PyTrees (worlds, cameras,
    models) by their static structure and leaves; everything else by its JSON text."""
    if isinstance(part, (np.ndarray, jax.Array)) or (np.isscalar(part) and isinstance(part, np.generic)):
        array = np.ascontiguousarray(np.asarray(part))
        digest.update(f"array{array.dtype}{array.shape}".encode())
        digest.update(array.tobytes())
    elif isinstance(part, eqx.Module):
        leaves, static = eqx.partition(part, eqx.is_array)
        digest.update(repr(jax.tree_util.tree_structure(leaves)).encode())
        digest.update(repr(jax.tree_util.tree_leaves(static)).encode())
        for leaf in jax.tree_util.tree_leaves(leaves):
            _update(digest, leaf)
    elif isinstance(part, Mapping):
        digest.update(b"{")
        for name in sorted(part, key=str):
            digest.update(str(name).encode())
            _update(digest, part[name])
        digest.update(b"}")
    elif isinstance(part, (list, tuple)):
        digest.update(b"[")
        for item in part:
            _update(digest, item)
        digest.update(b"]")
    else:
        digest.update(json.dumps(part, sort_keys=True, default=str).encode())


def content_key(kind: str, *parts: Any) -> str:
    """The cache key of ``kind`` built from ``parts`` (arrays, PyTrees, options, strings).

    Arguments:
        kind: what is cached (``"correlation-2d"``, ``"world"``, ``"neural"``, ...).
        *parts: everything the cached value depends on.

    Returns:
        A 24-character hex digest, stable across runs and machines.
    """
    digest = hashlib.sha256(f"ccjax-cache v{FORMAT_VERSION} {kind}".encode())
    for part in parts:
        _update(digest, part)
    return digest.hexdigest()[:24]


def atomic_write(path: Path, blob: bytes) -> None:
    """Write ``blob`` to ``path`` through a temporary file in the same folder and ``os.replace``, so
    readers never see a partial file; the file gets the usual permissions (umask)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    descriptor, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        with os.fdopen(descriptor, "wb") as handle:
            handle.write(blob)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(temporary, 0o666 & ~umask)  # mkstemp's 0600 is for the temporary name only
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise


def cached_arrays(
    kind: str, key: str, compute: Callable[[], Mapping[str, np.ndarray]], metadata: Mapping[str, Any] | None = None
) -> dict[str, np.ndarray]:
    """Load the arrays stored under (``kind``, ``key``), else ``compute()`` and store them.

    A damaged or unreadable entry is recomputed and replaced; an unwritable cache only costs time.

    Arguments:
        kind: sub-folder of the cache (one per kind of fitted data).
        key: :func:`content_key` of everything the arrays depend on.
        compute: builds the arrays (called only on a miss).
        metadata: JSON-able facts written beside the arrays (for people reading the cache).

    Returns:
        The arrays by name.
    """
    stored = read_arrays(kind, key)
    if stored is not None:
        return stored
    arrays = {name: np.asarray(value) for name, value in compute().items()}
    write_arrays(kind, key, arrays, metadata)
    return arrays


def read_arrays(kind: str, key: str) -> dict[str, np.ndarray] | None:
    """The arrays stored under (``kind``, ``key``), or None when absent, damaged or unreadable.

    Arguments:
        kind: sub-folder of the cache.
        key: :func:`content_key` of everything the arrays depend on.

    Returns:
        The arrays by name, or None.
    """
    path = cache_directory() / kind / f"{key}.npz"
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as stored:
            return {name: stored[name] for name in stored.files}
    except (OSError, ValueError, EOFError):
        return None


def write_arrays(
    kind: str, key: str, arrays: Mapping[str, np.ndarray], metadata: Mapping[str, Any] | None = None
) -> None:
    """Store ``arrays`` under (``kind``, ``key``) with a JSON record of ``metadata`` beside them;
    an unwritable cache is ignored (it only costs time).

    Arguments:
        kind: sub-folder of the cache.
        key: :func:`content_key` of everything the arrays depend on.
        arrays: the arrays by name.
        metadata: JSON-able facts written beside the arrays (for people reading the cache).
    """
    path = cache_directory() / kind / f"{key}.npz"
    try:
        buffer = io.BytesIO()
        np.savez(buffer, **{name: np.asarray(value) for name, value in arrays.items()})  # pyright: ignore[reportArgumentType]
        atomic_write(path, buffer.getvalue())
        record = {"format": FORMAT_VERSION, "kind": kind, **(metadata or {})}
        atomic_write(path.with_suffix(".json"), json.dumps(record, indent=1, default=str).encode())
    except OSError:
        pass


# ---------------------------------------------------------------------------------------------
# whole fitted models (skeleton as JSON, arrays as .npz), for the fit cache

# Classes a cached skeleton may name (imported by module path when read back).
_TRUSTED_MODULES = ("ccjax.", "equinox.")


class Unserialisable(TypeError):
    """A model holds something :func:`encode_tree` cannot write as JSON + arrays (a function, an
    object of an untrusted module); such models are fitted every time instead of cached."""


def _qualified(cls: type) -> str:
    name = f"{cls.__module__}:{cls.__qualname__}"
    if not cls.__module__.startswith(_TRUSTED_MODULES) or "<locals>" in cls.__qualname__:
        raise Unserialisable(f"{name} is not a ccjax or equinox class")
    return name


def _resolve(name: str) -> type:
    module, _, qualname = name.partition(":")
    if not module.startswith(_TRUSTED_MODULES):
        raise ValueError(f"cache: {name} is not a ccjax or equinox class")
    value: Any = importlib.import_module(module)
    for part in qualname.split("."):
        value = getattr(value, part)
    if not isinstance(value, type):
        raise ValueError(f"cache: {name} is not a class")
    return value


def encode_tree(tree: Any, arrays: dict[str, np.ndarray]) -> Any:
    """A JSON description of ``tree`` (equinox Modules and frozen dataclasses of ccjax, enums,
    tuples, lists, string-keyed dicts, JSON scalars), its arrays appended to ``arrays`` by name.

    Arguments:
        tree: a fitted model or any part of one.
        arrays: filled with ``"a<i>" -> np.ndarray``.

    Returns:
        The JSON-able skeleton (see :func:`decode_tree`).

    Raises:
        Unserialisable: for anything else (functions, foreign objects).
    """
    if isinstance(tree, (jax.Array, np.ndarray, np.generic)):
        name = f"a{len(arrays)}"
        arrays[name] = np.asarray(tree)
        kind = "jax" if isinstance(tree, jax.Array) else "numpy" if isinstance(tree, np.ndarray) else "scalar"
        return {"$array": name, "kind": kind}
    if tree is None or isinstance(tree, (bool, int, float, str)):
        return tree
    if isinstance(tree, enum.Enum):
        return {"$enum": _qualified(type(tree)), "value": tree.value}
    if isinstance(tree, eqx.Module) or (dataclasses.is_dataclass(tree) and not isinstance(tree, type)):
        fields = {f.name: encode_tree(getattr(tree, f.name), arrays) for f in dataclasses.fields(tree)}
        tag = "$module" if isinstance(tree, eqx.Module) else "$dataclass"
        return {tag: _qualified(type(tree)), "fields": fields}
    if isinstance(tree, tuple) and type(tree) is tuple:
        return {"$tuple": [encode_tree(item, arrays) for item in tree]}
    if isinstance(tree, list):
        return [encode_tree(item, arrays) for item in tree]
    if isinstance(tree, dict) and all(isinstance(k, str) for k in tree):
        return {"$dict": {k: encode_tree(v, arrays) for k, v in tree.items()}}
    raise Unserialisable(f"cannot cache a {type(tree).__module__}.{type(tree).__qualname__}")


def decode_tree(skeleton: Any, arrays: Mapping[str, np.ndarray]) -> Any:
    """The inverse of :func:`encode_tree`: Modules are rebuilt field by field as equinox unflattens
    them (no ``__init__``, so no refitting), other dataclasses through their constructor.

    Arguments:
        skeleton: from :func:`encode_tree`.
        arrays: the arrays it names.

    Returns:
        The tree.
    """
    if isinstance(skeleton, list):
        return [decode_tree(item, arrays) for item in skeleton]
    if not isinstance(skeleton, dict):
        return skeleton
    if "$array" in skeleton:
        array = arrays[skeleton["$array"]]
        # device_put, not jnp.asarray: the latter compiles a small copy program per shape.
        return {"jax": jax.device_put, "numpy": np.asarray}.get(skeleton["kind"], lambda a: a[()])(array)
    if "$enum" in skeleton:
        return _resolve(skeleton["$enum"])(skeleton["value"])
    if "$tuple" in skeleton:
        return tuple(decode_tree(item, arrays) for item in skeleton["$tuple"])
    if "$dict" in skeleton:
        return {k: decode_tree(v, arrays) for k, v in skeleton["$dict"].items()}
    fields = {name: decode_tree(value, arrays) for name, value in skeleton["fields"].items()}
    if "$dataclass" in skeleton:
        return _resolve(skeleton["$dataclass"])(**fields)
    cls = _resolve(skeleton["$module"])
    module = object.__new__(cls)
    for name, value in fields.items():
        object.__setattr__(module, name, value)
    return module


def _same_tree(a: Any, b: Any) -> bool:
    leaves_a, tree_a = jax.tree_util.tree_flatten(a)
    leaves_b, tree_b = jax.tree_util.tree_flatten(b)
    return tree_a == tree_b and all(
        type(x) is type(y) and np.array_equal(np.asarray(x), np.asarray(y), equal_nan=True)
        if isinstance(x, (jax.Array, np.ndarray, np.generic))
        else x == y
        for x, y in zip(leaves_a, leaves_b, strict=True)
    )


def cached_model(
    kind: str, key: str, compute: Callable[[], ModelT], metadata: Mapping[str, Any] | None = None
) -> tuple[ModelT, bool]:
    """Load the model stored under (``kind``, ``key``), else ``compute()`` and store it.

    The model is written as a JSON skeleton (``.json``, with ``format`` and ``metadata``) and its
    arrays (``.npz``); it is stored only if reading it back gives the same tree and arrays, so a
    model that cannot be cached (:class:`Unserialisable`) is simply computed each time. A damaged
    entry is recomputed and replaced; an unwritable cache only costs time.

    Arguments:
        kind: sub-folder of the cache.
        key: :func:`content_key` of everything the model depends on (include
            :func:`code_fingerprint` for fits).
        compute: builds the model (called only on a miss).
        metadata: JSON-able facts written beside it.

    Returns:
        ``(model, from_cache)``.
    """
    path = cache_directory() / kind / f"{key}.json"
    if path.is_file():
        try:
            record = json.loads(path.read_text())
            if record.get("format") == FORMAT_VERSION:
                with np.load(path.with_suffix(".npz"), allow_pickle=False) as stored:
                    arrays = {name: stored[name] for name in stored.files}
                return decode_tree(record["skeleton"], arrays), True
        except (OSError, ValueError, EOFError, KeyError, TypeError, AttributeError, ImportError):
            pass
    model = compute()
    try:
        arrays: dict[str, np.ndarray] = {}
        skeleton = encode_tree(model, arrays)
        stored = decode_tree(skeleton, arrays)
        if not _same_tree(stored, model):
            return model, False
        # Hand back what a later run reads (same values; array types such as JAX's weak types
        # can differ), so both runs trace the same programs and share XLA's compilation cache.
        model = stored
        buffer = io.BytesIO()
        np.savez(buffer, **arrays)  # pyright: ignore[reportArgumentType]
        atomic_write(path.with_suffix(".npz"), buffer.getvalue())
        record = {"format": FORMAT_VERSION, "kind": kind, **(metadata or {}), "skeleton": skeleton}
        atomic_write(path, json.dumps(record, default=str).encode())
    except (Unserialisable, OSError, TypeError, ValueError):
        pass
    return model, False


def save_model(path: Path, model: eqx.Module, metadata: Mapping[str, Any]) -> Path:
    """Write ``model``'s array leaves (``eqx.tree_serialise_leaves``) to ``path`` and a JSON record
    (``format``, ccjax version, ``metadata``) beside it (``path.with_suffix(".json")``), atomically.

    Arguments:
        path: the model file (``.eqx``).
        model: any fitted model.
        metadata: what is needed to rebuild the model's skeleton (label, options, world, ...).

    Returns:
        ``path``.
    """
    from ccjax import __version__

    path = Path(path)
    buffer = io.BytesIO()
    eqx.tree_serialise_leaves(buffer, model)
    atomic_write(path, buffer.getvalue())
    record = {"format": FORMAT_VERSION, "ccjax": __version__, **metadata}
    atomic_write(path.with_suffix(".json"), json.dumps(record, indent=1, default=str).encode())
    return path


def read_model_metadata(path: Path) -> dict[str, Any]:
    """The JSON record of a model file; ``ValueError`` when it is missing, unreadable or of another
    format version."""
    record_path = Path(path).with_suffix(".json")
    try:
        record = json.loads(record_path.read_text())
    except (OSError, ValueError) as error:
        raise ValueError(f"model: cannot read the metadata {record_path}: {error}") from None
    if record.get("format") != FORMAT_VERSION:
        raise ValueError(f"model: {path} has format {record.get('format')!r}; this ccjax reads format {FORMAT_VERSION}")
    return record


def load_model(path: Path, like: ModelT) -> ModelT:
    """Read a model written by :func:`save_model` into the skeleton ``like`` (same structure and
    shapes, e.g. a freshly fitted or initialised model).

    Arguments:
        path: the model file.
        like: a model of the same type, structure and leaf shapes.

    Returns:
        ``like`` with the stored leaves.
    """
    read_model_metadata(path)
    try:
        return eqx.tree_deserialise_leaves(path, like)
    except (OSError, ValueError, RuntimeError) as error:
        raise ValueError(f"model: {path} does not fit a {type(like).__name__}: {error}") from None
