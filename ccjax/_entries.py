"""The one verified read path of the disk cache: every entry (fits, worlds, sweeps' results,
previews, pretraining renders) is a data-only pair, verified before use.

An entry is ``<key>.json`` (a record: schema, kind, key, content digest and the skeleton: for a
model its classes and fields, for arrays the facts of the key, such as the method and the counts)
and ``<key>.npz`` (uncompressed arrays, read without pickle). Reading checks, in order and before
any array is allocated: the record (bounded JSON, this schema, kind and key), the archive's
headers (stored members, no objects, sizes that add up, at most
:data:`ccjax.limits.CACHE_ENTRY_BYTES`), then the arrays' digest and, for arrays the caller
describes (:class:`Expect`), the names, dtypes, shapes and values (finite, in range). An entry
that fails any check is removed and recomputed, with one :class:`CacheEntryRejected` warning. A
file where the cache folder (or a kind's folder in it) should be is said once per process
(:class:`CacheFolderUnusable`); results are then computed and not cached.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import io
import json
import math
import os
import warnings
import zipfile
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ccjax import limits
from ccjax._cache import atomic_write, cache_directory, parse_record

SCHEMA = 2
"""Version of the entry layout; an entry of another schema is rejected (and replaced)."""

_RECORD = ("schema", "kind", "key", "digest", "skeleton")


class Rejected(ValueError):
    """An entry that does not verify: unreadable, another schema or key, a digest that does not
    match, arrays other than the caller asked for, a class outside the allow-list."""


class CacheEntryRejected(UserWarning):
    """A cache entry did not verify (damaged, edited, another schema, other facts or arrays than
    asked for); it is computed again and replaced."""


class CacheFolderUnusable(UserWarning):
    """The cache folder, or a folder inside it, is a file: nothing is read from or written to it
    under that folder, so results are computed and not cached (said once per process)."""


_UNUSABLE_SAID: set[str] = set()
"""The files in the cache's way already named by a :class:`CacheFolderUnusable` warning."""


def file_in_the_way(path: Path) -> Path | None:
    """The nearest existing folder above ``path`` when it is not a folder (a regular file where
    the cache folder, or a kind's folder in it, should be), else None.

    Arguments:
        path: a cache entry's path.

    Returns:
        The file in the way, or None when the nearest existing parent is a folder.
    """
    for parent in path.parents:
        # lexists is False below a file (ENOTDIR): the first existing parent decides.
        if os.path.lexists(parent):
            return None if parent.is_dir() else parent
    return None


def say_cache_unusable(blocker: Path, *, stacklevel: int = 4) -> None:
    """Warn once per process (per file in the way) that results are not cached.

    Arguments:
        blocker: the file where a cache folder should be (:func:`file_in_the_way`).
        stacklevel: as :func:`warnings.warn`'s.
    """
    if str(blocker) in _UNUSABLE_SAID:
        return
    _UNUSABLE_SAID.add(str(blocker))
    warnings.warn(
        f"cache folder {blocker} is a file, not a folder; results are not cached in this run "
        "(remove the file, or point CCJAX_CACHE at a folder)",
        CacheFolderUnusable,
        stacklevel=stacklevel,
    )


@dataclasses.dataclass(frozen=True)
class Expect:
    """What one stored array must be.

    Attributes:
        shape: its shape; ``None`` for an axis of any length.
        kinds: the NumPy dtype kinds accepted (``"f"`` float, ``"b"`` bool, ``"iu"`` integers).
        low, high: the range of its values (floats must also be finite).
    """

    shape: tuple[int | None, ...]
    kinds: str = "f"
    low: float = -math.inf
    high: float = math.inf


def digest(kind: str, key: str, skeleton: Any, arrays: Mapping[str, np.ndarray]) -> str:
    """The content digest of an entry, bound to its kind and key: an entry moved to another key's
    name, or relabelled in its record, no longer verifies (another method's fit is never read as
    this one's). The digest is not keyed with a secret: whoever can write the cache folder can
    write a consistent entry (the trust model: the cache folder is as trusted as the code).

    Arguments:
        kind: what the entry holds.
        key: its cache key.
        skeleton: JSON-able description (a model's skeleton, a world's names, the key's facts).
        arrays: the arrays by name.

    Returns:
        sha256 hex digest of ``"<kind>\\n<key>\\n"``, then ``json.dumps(skeleton, sort_keys=True,
        separators=(",", ":"))``, then for each array name in sorted order
        ``"\\n<name> <dtype.str> <shape>\\n"`` and its C-order bytes.
    """
    hasher = hashlib.sha256(f"{kind}\n{key}\n".encode())
    hasher.update(json.dumps(skeleton, sort_keys=True, separators=(",", ":")).encode())
    for name in sorted(arrays):
        array = np.ascontiguousarray(arrays[name])
        hasher.update(f"\n{name} {array.dtype.str} {array.shape}\n".encode())
        hasher.update(array.tobytes())
    return hasher.hexdigest()


def write_entry(
    path: Path, kind: str, key: str, skeleton: Any, arrays: Mapping[str, np.ndarray], facts: Mapping[str, Any]
) -> None:
    """Write ``<path>.npz`` and then the record ``path`` (``.json``), each atomically.

    Arguments:
        path: the record's path (``<folder>/<key>.json``).
        kind: what the entry holds (``"fit"``, ``"world"``, ``"sweeps"``, ...).
        key: its cache key.
        skeleton: the JSON part the digest covers (and :func:`read_entry` hands back).
        arrays: the arrays by name.
        facts: JSON-able facts for people (label, world name, ...), not read back.

    Raises:
        OSError: the cache cannot be written.
    """
    arrays = {name: np.asarray(value) for name, value in arrays.items()}
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)  # pyright: ignore[reportArgumentType]
    atomic_write(path.with_suffix(".npz"), buffer.getvalue())
    record = {
        **{name: value for name, value in facts.items() if name not in _RECORD},
        "schema": SCHEMA,
        "kind": kind,
        "key": key,
        "digest": digest(kind, key, skeleton, arrays),
        "skeleton": skeleton,
    }
    atomic_write(path, json.dumps(record, default=str).encode())


def read_entry(
    path: Path, kind: str, key: str, expect: Mapping[str, Expect] | None = None
) -> tuple[Any, dict[str, np.ndarray]] | None:
    """The verified ``(skeleton, arrays)`` of the entry at ``path``, or None when there is none.

    Arguments:
        path: the record's path.
        kind: the kind it must hold.
        key: the key it must have.
        expect: when given, exactly these arrays, of these kinds, shapes and ranges.

    Returns:
        ``(skeleton, arrays)``, or None when ``path`` does not exist (a file where a folder above
        it should be is said once per process, :class:`CacheFolderUnusable`) or holds an entry of
        the layout before this schema (``{"format": 1, ...}`` without ``"schema"``), which the
        caller replaces without a warning.

    Raises:
        Rejected: the entry exists but does not verify.
    """
    try:
        if path.stat().st_size > limits.RECORD_BYTES.value:
            raise Rejected(f"the record is over {limits.RECORD_BYTES.value} bytes")
        text = path.read_bytes()
    except FileNotFoundError:
        return None
    except NotADirectoryError as error:
        # A file where the cache folder should be: no entry can be there, and it is said once
        # per process, not once per entry as a rejected one would be.
        blocker = file_in_the_way(path)
        if blocker is None:
            raise Rejected(f"unreadable record: {error}") from None
        say_cache_unusable(blocker)
        return None
    except OSError as error:
        raise Rejected(f"unreadable record: {error}") from None
    try:
        record = parse_record(text)
    except json.JSONDecodeError:
        raise Rejected("the record is not JSON") from None
    except ValueError as error:  # not UTF-8, or nested past the limit
        raise Rejected(f"the record: {error}") from None
    earlier = isinstance(record, dict) and (
        record.get("schema") == 1 or ("schema" not in record and record.get("format") == 1)
    )
    if earlier:
        # An entry of an earlier layout (ccjax 0.2's; schema 1, whose digest did not cover the key):
        # not damaged, replaced without a warning.
        return None
    if not isinstance(record, dict) or set(_RECORD) - set(record):
        raise Rejected("the record lacks schema, kind, key, digest or skeleton")
    if record["schema"] != SCHEMA:
        raise Rejected(f"schema {record['schema']!r}, expected {SCHEMA}")
    if record["kind"] != kind or record["key"] != key:
        raise Rejected(f"the record is of {record['kind']!r} {record['key']!r}, expected {kind!r} {key!r}")
    try:
        # Opened here, so that a damaged archive's file is closed too.
        with path.with_suffix(".npz").open("rb") as handle:
            _check_headers(handle, expect)
            handle.seek(0)
            with np.load(handle, allow_pickle=False) as stored:
                arrays = {name: stored[name] for name in stored.files}
    except Rejected:
        raise
    except Exception as error:  # any failure to read the arrays rejects the entry
        raise Rejected(f"unreadable arrays: {type(error).__name__}: {error}") from None
    if digest(kind, key, record["skeleton"], arrays) != record["digest"]:
        raise Rejected("the content digest does not match")
    for name, want in (expect or {}).items():
        _check_values(name, arrays[name], want)
    return record["skeleton"], arrays


def _check_headers(handle, expect: Mapping[str, Expect] | None) -> None:
    """Refuse an archive whose members are compressed, hold objects, or claim more bytes than they
    have (a header's shape is allocated before its bytes are read), or arrays other than
    ``expect``'s, before any array is read."""
    total = 0
    with zipfile.ZipFile(handle) as archive:
        members = archive.infolist()
        names = [member.filename.removesuffix(".npy") for member in members]
        if expect is not None and sorted(names) != sorted(expect):
            raise Rejected(f"arrays {sorted(names)}, expected {sorted(expect)}")
        for name, member in zip(names, members, strict=True):
            if member.compress_type != zipfile.ZIP_STORED:
                raise Rejected(f"array {name} is compressed")
            with archive.open(member) as stream:
                version = np.lib.format.read_magic(stream)
                if version == (1, 0):
                    shape, _, dtype = np.lib.format.read_array_header_1_0(stream)
                else:
                    shape, _, dtype = np.lib.format.read_array_header_2_0(stream)
                header = stream.tell()
            if dtype.hasobject:
                raise Rejected(f"array {name} holds Python objects")
            size = math.prod(shape) * dtype.itemsize
            if header + size != member.file_size:
                raise Rejected(
                    f"array {name}: its header claims {size} bytes, the file holds {member.file_size - header}"
                )
            total += size
            if expect is not None:
                _check_layout(name, shape, dtype, expect[name])
        if total > limits.CACHE_ENTRY_BYTES.value:
            raise Rejected(f"the arrays hold {total} bytes, over the limit of {limits.CACHE_ENTRY_BYTES.value}")


def _check_layout(name: str, shape: tuple[int, ...], dtype: np.dtype, want: Expect) -> None:
    if dtype.kind not in want.kinds:
        raise Rejected(f"array {name} is {dtype}, expected kind {want.kinds!r}")
    if len(shape) != len(want.shape) or any(w is not None and s != w for s, w in zip(shape, want.shape, strict=False)):
        raise Rejected(f"array {name} has shape {shape}, expected {want.shape}")


def _check_values(name: str, array: np.ndarray, want: Expect) -> None:
    if array.size == 0:
        return
    if array.dtype.kind == "f" and not np.all(np.isfinite(array)):
        raise Rejected(f"array {name} holds non-finite values")
    if array.dtype.kind in "fiu" and (array.min() < want.low or array.max() > want.high):
        raise Rejected(f"array {name} holds values outside [{want.low:g}, {want.high:g}]")


def reject(path: Path, why: Exception, action: str, *, stacklevel: int = 4) -> None:
    """Remove the entry's files (a new entry replaces them) and say so in one warning line.

    Arguments:
        path: the record's path.
        why: what did not verify.
        action: what happens instead (``"refitting"``).
        stacklevel: as :func:`warnings.warn`'s.
    """
    # Removed first: where warnings are errors, the next run then starts from a clean entry.
    for stale in (path, path.with_suffix(".npz")):
        with contextlib.suppress(OSError):
            stale.unlink()
    reason = " ".join(str(why).split())
    warnings.warn(
        f"cache entry {path} does not verify ({reason}); {action} and replacing it",
        CacheEntryRejected,
        stacklevel=stacklevel,
    )


def normal_facts(facts: Mapping[str, Any]) -> Any:
    """The facts as the record holds them (a JSON round trip).

    Arguments:
        facts: JSON-able facts.

    Returns:
        Their JSON round trip (what :func:`read_arrays` compares with).
    """
    return json.loads(json.dumps(dict(facts), sort_keys=True, default=str))


def read_arrays(
    kind: str, key: str, expect: Mapping[str, Expect], facts: Mapping[str, Any]
) -> dict[str, np.ndarray] | None:
    """The verified arrays stored under (``kind``, ``key``), or None when absent or rejected (a
    rejected entry is removed, with one :class:`CacheEntryRejected` warning).

    Arguments:
        kind: sub-folder of the cache.
        key: :func:`ccjax._cache.content_key` of everything the arrays depend on.
        expect: the arrays the caller asks for (names, kinds, shapes, ranges).
        facts: the key's facts (method, counts, ...), which the entry must hold.

    Returns:
        The arrays by name, or None.
    """
    path = cache_directory() / kind / f"{key}.json"
    try:
        entry = read_entry(path, kind, key, expect)
        if entry is None:
            return None
        if entry[0] != normal_facts(facts):
            raise Rejected(f"facts {entry[0]!r}, expected {normal_facts(facts)!r}")
        return entry[1]
    except Rejected as why:
        reject(path, why, "computing it again")
        return None


def write_arrays(kind: str, key: str, arrays: Mapping[str, np.ndarray], facts: Mapping[str, Any]) -> None:
    """Store ``arrays`` under (``kind``, ``key``) with the key's ``facts`` (:func:`write_entry`);
    an unwritable cache is ignored (it only costs time).

    Arguments:
        kind: sub-folder of the cache.
        key: :func:`ccjax._cache.content_key` of everything the arrays depend on.
        arrays: the arrays by name.
        facts: JSON-able facts of the key, checked when read back.
    """
    path = cache_directory() / kind / f"{key}.json"
    with contextlib.suppress(OSError):
        write_entry(path, kind, key, normal_facts(facts), arrays, facts)


def cached_arrays(
    kind: str,
    key: str,
    compute: Callable[[], Mapping[str, np.ndarray]],
    expect: Mapping[str, Expect],
    facts: Mapping[str, Any],
) -> dict[str, np.ndarray]:
    """The verified arrays stored under (``kind``, ``key``), else ``compute()``, stored.

    Arguments:
        kind: sub-folder of the cache.
        key: :func:`ccjax._cache.content_key` of everything the arrays depend on.
        compute: builds the arrays (called only on a miss or a rejected entry).
        expect: the arrays (:func:`read_arrays`).
        facts: the key's facts.

    Returns:
        The arrays by name.
    """
    stored = read_arrays(kind, key, expect, facts)
    if stored is not None:
        return stored
    arrays = {name: np.asarray(value) for name, value in compute().items()}
    write_arrays(kind, key, arrays, facts)
    return arrays


__all__ = [
    "SCHEMA",
    "CacheEntryRejected",
    "CacheFolderUnusable",
    "Expect",
    "Rejected",
    "cached_arrays",
    "digest",
    "file_in_the_way",
    "normal_facts",
    "read_arrays",
    "read_entry",
    "reject",
    "say_cache_unusable",
    "write_arrays",
    "write_entry",
]
