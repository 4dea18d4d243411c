"""The one on-disk cache: one directory rule, one content key, one serialisation.

Everything ccjax keeps between runs lives under :func:`cache_directory`: verified data-only entries
(``.npz`` + ``.json``: fitted models, worlds, results, previews, renders; :mod:`ccjax._entries`), model
files (equinox leaf serialisation + ``.json`` metadata with a format version, so model files can be
shared between users) and JAX's persistent compilation cache (``xla/``). Nothing is pickled: a
cache file can be read without running code from it.
"""

from __future__ import annotations

import dataclasses
import errno
import functools
import hashlib
import io
import json
import os
import re
import sys
import tempfile
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any, BinaryIO, TypeVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ccjax import limits
from ccjax._folder_lock import folders_locked
from ccjax._signals import interrupts_held
from ccjax._version import __version__

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
    second run of a command skips compilation as well as fitting. Empty programs a full disk left
    there are removed first (:func:`remove_empty_programs`).

    Returns:
        None.
    """
    # The option is a dynamic attribute of jax.config (pyright cannot see it).
    if not getattr(jax.config, "jax_compilation_cache_dir"):  # noqa: B009
        folder = cache_directory() / "xla"
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError:
            return
        if not os.access(folder, os.W_OK | os.X_OK):
            # A read-only cache only costs compile time; JAX would warn on every program it compiles.
            return
        remove_empty_programs(folder)
        jax.config.update("jax_compilation_cache_dir", str(folder))
        # Small programs too: a command compiles dozens of them, each well under a second.
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.05)


COMPILED_SUFFIX = "-cache"
"""The name ending of a compiled program in JAX's persistent compilation cache (its other files,
``-atime`` stamps and the ``.lockfile``, are kept)."""


def remove_empty_programs(folder: str | os.PathLike) -> list[Path]:
    """Remove the empty compiled programs from JAX's compilation cache ``folder``.

    JAX writes an entry in place (``Path.write_bytes``): a full disk leaves a zero-byte file, which
    every later run fails to read ("Error reading persistent compilation cache entry") and never
    replaces. One directory scan (sizes from ``os.scandir``, no file opened); a file that cannot be
    removed is left (it costs a warning, not a result).

    Arguments:
        folder: the compilation cache folder.

    Returns:
        The files removed (none when ``folder`` cannot be listed).
    """
    removed: list[Path] = []
    try:
        with os.scandir(folder) as entries:
            empty = [
                entry.path
                for entry in entries
                if entry.name.endswith(COMPILED_SUFFIX)
                and entry.is_file(follow_symlinks=False)
                and entry.stat(follow_symlinks=False).st_size == 0
            ]
    except OSError:
        return removed
    for path in empty:
        try:
            os.unlink(path)
        except OSError:
            continue
        removed.append(Path(path))
    return removed


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


_NO_HARD_LINKS = (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EXDEV, errno.EMLINK)
"""``os.link`` errors of file systems without hard links (FAT, some network mounts)."""


def put_in_place(temporary: str | os.PathLike, path: str | os.PathLike, *, overwrite: bool) -> None:
    """Move a finished temporary file (in ``path``'s folder) to ``path``.

    With ``overwrite`` it replaces whatever is at ``path`` (``os.replace``: a symbolic link there
    is replaced, never followed). Without, a hard link makes the new name, which fails rather
    than replace a file that appeared since the command's check; where the file system has no
    hard links, ``path`` is checked again just before the rename.

    Arguments:
        temporary: the complete file (removed in every case).
        path: its final name.
        overwrite: whether a file at ``path`` may be replaced.

    Returns:
        None.

    Raises:
        FileExistsError: without ``overwrite``, ``path`` exists (the message names it).
    """
    appeared = FileExistsError(
        errno.EEXIST, "appeared while ccjax was working and is kept (use --overwrite to replace it)", str(path)
    )
    try:
        if overwrite:
            os.replace(temporary, path)
            return
        try:
            os.link(temporary, path)
        except FileExistsError:
            raise appeared from None
        except OSError as error:
            if error.errno not in _NO_HARD_LINKS:
                raise
            if os.path.lexists(path):
                raise appeared from None
            os.replace(temporary, path)
    finally:
        Path(temporary).unlink(missing_ok=True)


def _write_temporary(path: Path, blob: bytes | Callable[[BinaryIO], object]) -> str:
    """Write ``blob`` to a new temporary file in ``path``'s folder (the usual permissions, umask);
    return its name. The temporary is removed when the write fails (a full disk names ``path``)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    descriptor, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        os.close(descriptor)
        # Opened by name: writers such as tifffile ask the file object for its path.
        with open(temporary, "wb") as handle:
            if callable(blob):
                blob(handle)
            else:
                handle.write(blob)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(temporary, 0o666 & ~umask)  # mkstemp's 0600 is for the temporary name only
    except BaseException as error:
        Path(temporary).unlink(missing_ok=True)
        if isinstance(error, OSError) and error.filename is None:  # a full disk: say which file
            raise OSError(error.errno, error.strerror, str(path)) from None
        raise
    return temporary


def atomic_write(path: Path, blob: bytes | Callable[[BinaryIO], object], *, replace: bool = True) -> None:
    """Write ``blob`` to ``path`` through a temporary file in the same folder put in place
    (:func:`put_in_place`), so readers never see a partial file; the file gets
    the usual permissions (umask). Without ``replace`` an existing ``path`` is kept
    (``FileExistsError``). ``blob`` may be a function that writes to the open binary file."""
    atomic_write_files({Path(path): blob}, replace=replace)


def atomic_write_files(files: Mapping[Path, bytes | Callable[[BinaryIO], object]], *, replace: bool = True) -> None:
    """Write several files that belong together (a model and its record) so that they appear
    together or not at all: every file is first written whole to a temporary (where a full disk
    or an error stops the write, nothing has appeared), then each is put in place
    (:func:`put_in_place`, a rename); should putting one in place fail, the ones this call put in
    place before it are removed again. While several files are put in place their folders are
    locked (``folders_locked``), so two writers of one pair do not interleave.

    Arguments:
        files: path -> bytes, or a function that writes to the open binary file; put in place in
            this order (put the file a reader opens last, e.g. the model after its record).
        replace: replace existing files (else ``FileExistsError`` naming the first that exists,
            before anything is written).

    Returns:
        None.
    """
    paths = [Path(path) for path in files]
    if not replace and len(paths) > 1:  # (one file: put_in_place refuses it without a race)
        for path in paths:
            if os.path.lexists(path):
                raise FileExistsError(
                    errno.EEXIST,
                    "appeared while ccjax was working and is kept (use --overwrite to replace it)",
                    str(path),
                )
    temporaries: list[str] = []
    placed: list[Path] = []
    try:
        for path, blob in zip(paths, files.values(), strict=True):
            temporaries.append(_write_temporary(path, blob))
        # Ctrl-C (and SIGTERM, where the command asked) wait until every file is in place: a pair
        # is never left half old, half new by a signal, nor by another writer of the same pair.
        with interrupts_held(), folders_locked({path.parent for path in paths} if len(paths) > 1 else ()):
            for path, temporary in zip(paths, temporaries, strict=True):
                put_in_place(temporary, path, overwrite=replace)
                placed.append(path)
    except BaseException:
        if len(paths) > 1 and not replace:
            for path in placed:  # new files of this call only: replaced ones cannot come back
                path.unlink(missing_ok=True)
        raise
    finally:
        for temporary in temporaries:
            Path(temporary).unlink(missing_ok=True)


def parse_record(text: str | bytes) -> Any:
    """A JSON record, parsed with its nesting bounded (:data:`ccjax.limits.NESTING`): a record
    nested 100,000 deep is a ``ValueError``, not Python's ``RecursionError``.

    Arguments:
        text: the JSON text.

    Returns:
        The parsed value.

    Raises:
        ValueError: not JSON, or nested deeper than the limit.
    """
    if isinstance(text, bytes):
        text = text.decode("utf-8", errors="strict")
    depth = _nesting(text)
    if depth > limits.NESTING.value:
        raise ValueError(f"nested {depth} deep, over the limit of {limits.NESTING.value}")
    return json.loads(text)


def _nesting(text: str) -> int:
    """The deepest nesting of ``[``/``{`` in JSON text, outside strings (one pass, no recursion)."""
    # Strings are removed first (escaped quotes included), so brackets inside them do not count.
    bare = re.sub(r'"(?:[^"\\]|\\.)*"', "", text)
    depth = deepest = 0
    for match in re.finditer(r"[\[\]{}]", bare):
        depth += 1 if match.group() in "[{" else -1
        deepest = max(deepest, depth)
    return deepest


def save_model(path: Path, model: eqx.Module, metadata: Mapping[str, Any], *, replace: bool = True) -> Path:
    """Write ``model``'s array leaves (``eqx.tree_serialise_leaves``) to ``path`` and a JSON record
    (``format``, ccjax version, ``metadata``) beside it (``path.with_suffix(".json")``), atomically.

    Arguments:
        path: the model file (``.eqx``).
        model: any fitted model.
        metadata: what is needed to rebuild the model's skeleton (label, options, world, ...).
        replace: replace existing files (else ``FileExistsError``, :func:`atomic_write`).

    Returns:
        ``path``.
    """
    path = Path(path)
    buffer = io.BytesIO()
    eqx.tree_serialise_leaves(buffer, model)
    # The record names the exact model bytes it describes: a record beside another run's model
    # (two writers, or files copied apart) is refused when read, never loaded as a pair.
    weights = {WEIGHTS_DIGEST: hashlib.sha256(buffer.getvalue()).hexdigest()}
    record = {"format": FORMAT_VERSION, "ccjax": __version__, **metadata, **weights}
    text = json.dumps(record, indent=1, default=str).encode()
    # One pair: both written whole before either appears; the model last (readers open the
    # record first, and a model without its record cannot be loaded).
    atomic_write_files({path.with_suffix(".json"): text, path: buffer.getvalue()}, replace=replace)
    return path


WEIGHTS_DIGEST = "weights_sha256"
"""The model record's field holding the sha256 of the model file it belongs to."""

MAX_RECORD_BYTES = int(limits.RECORD_BYTES.value)
"""Largest model record read (a written one is a few kilobytes): :data:`ccjax.limits.RECORD_BYTES`."""


def read_model_metadata(path: Path) -> dict[str, Any]:
    """The JSON record of a model file; ``ValueError`` when it is missing, unreadable or of another
    format version."""
    record_path = Path(path).with_suffix(".json")
    try:
        if not record_path.is_file() or record_path.stat().st_size > MAX_RECORD_BYTES:
            raise ValueError(f"not a regular file of at most {MAX_RECORD_BYTES} bytes")
        record = parse_record(record_path.read_bytes())
    except (OSError, ValueError) as error:
        raise ValueError(f"model: cannot read the metadata {record_path}: {error}") from None
    if not isinstance(record, dict):
        raise ValueError(f"model: the metadata {record_path} is a JSON {type(record).__name__}, not an object")
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

    Raises:
        ValueError: an unreadable or mismatched pair, leaves that do not fit ``like``, non-finite
            leaves, leaves a class's own checks refuse, or a ``fallback`` light that is not finite
            and non-negative with a positive channel (each message names the file).
    """
    record = read_model_metadata(path)
    # A file far larger than the skeleton's leaves is not this model: refused before it is read.
    expected = sum(leaf.nbytes for leaf in jax.tree_util.tree_leaves(eqx.filter(like, eqx.is_array)))
    try:
        if Path(path).stat().st_size > 2 * expected + (1 << 20):
            kind = type(like).__name__
            raise ValueError(f"model: {path} is far larger than a {kind}'s parameters ({expected} bytes)")
        blob = Path(path).read_bytes()
    except OSError as error:
        raise ValueError(f"model: cannot read {path}: {error}") from None
    # Records written before the digest existed have none: those pairs are read as they are.
    if WEIGHTS_DIGEST in record and record[WEIGHTS_DIGEST] != hashlib.sha256(blob).hexdigest():
        raise ValueError(
            f"model: {path} is not the model its record {Path(path).with_suffix('.json')} describes (another run's "
            "file, or an edited one); write the pair again (ccjax train ... --out)"
        )
    try:
        model = eqx.tree_deserialise_leaves(io.BytesIO(blob), like)
    except (OSError, ValueError, RuntimeError) as error:
        raise ValueError(
            f"model: {path} does not fit a {type(like).__name__} ({error}); a model written before this "
            "method's parameters changed must be trained again"
        ) from None
    for leaf in jax.tree_util.tree_leaves(eqx.filter(model, eqx.is_array)):
        if jnp.issubdtype(leaf.dtype, jnp.inexact) and not bool(jnp.all(jnp.isfinite(leaf))):
            raise ValueError(f"model: {path} holds non-finite values")
    try:
        _check_modules(model)
        _check_fallback_lights(model)
    except ValueError as error:
        raise ValueError(f"model: {path}: {error}") from None
    return model


def _modules(tree: Any) -> Iterator[eqx.Module]:
    """Every equinox Module in ``tree`` (itself included), through Module and dataclass fields,
    lists, tuples and dicts."""
    if isinstance(tree, eqx.Module):
        yield tree
    if isinstance(tree, eqx.Module) or (dataclasses.is_dataclass(tree) and not isinstance(tree, type)):
        for field in dataclasses.fields(tree):
            yield from _modules(getattr(tree, field.name, None))
    elif isinstance(tree, (list, tuple)):
        for item in tree:
            yield from _modules(item)
    elif isinstance(tree, dict):
        for item in tree.values():
            yield from _modules(item)


def _check_modules(tree: Any) -> None:
    """Run equinox's ``__check_init__`` of every Module in ``tree`` again: deserialised leaves
    never went through a constructor, and a file's leaves must meet the class's own checks."""
    for module in _modules(tree):
        for cls in type(module).__mro__:
            check = cls.__dict__.get("__check_init__")
            if check is not None:
                check(module)


def _check_fallback_lights(tree: Any) -> None:
    """Refuse a ``fallback`` light (a model's answer for a scene without data) that is not a light,
    by the rule of :func:`ccjax.estimators.known.known_light`: finite, non-negative, with a positive
    channel. A model file's leaves never went through the fit that made them, and a fallback of
    ``[-1, -1, -1]`` or ``[0, 0, 0]`` would otherwise be written into corrected images."""
    for module in _modules(tree):
        light = getattr(module, "fallback", None)
        if not isinstance(light, (jax.Array, np.ndarray)):
            continue
        values = np.asarray(light, np.float64)
        if not (np.all(np.isfinite(values)) and np.all(values >= 0) and np.any(values > 0)):
            raise ValueError(
                f"the fallback light of its {type(module).__name__} is {values.tolist()}; a fallback light must be "
                "finite and non-negative with a positive channel"
            )
