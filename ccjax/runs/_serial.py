"""Models and worlds as the store's data-only entries (:mod:`ccjax._entries`, the one verified
read path of the cache).

A model's skeleton names
its classes as ``"module:qualname"``; they are looked up in an allow-list (a dict given by the
caller), never imported, and are rebuilt field by field without running their ``__init__``. The
digest is the sha256 of the entry's kind and key, the skeleton's canonical JSON and every array's
name, dtype, shape and bytes (:func:`digest`); an entry that does not verify raises :class:`Rejected`.
"""

from __future__ import annotations

import dataclasses
import enum
from collections.abc import Mapping
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ccjax._entries import Rejected, digest, read_entry, write_entry
from ccjax.camera import Camera
from ccjax.estimators.registry import qualified_name
from ccjax.world import World

WEAK_LIMIT = 4096
"""Largest weakly typed array a model may hold to be stored (rebuilt from Python scalars)."""

_NODES = {
    "$array": {"$array", "kind"},
    "$enum": {"$enum", "value"},
    "$tuple": {"$tuple"},
    "$dict": {"$dict"},
    "$module": {"$module", "fields"},
    "$dataclass": {"$dataclass", "fields"},
}
_ARRAY_KINDS = ("jax", "jax-weak", "numpy", "scalar")
_WORLD_ARRAYS = ("reflectances", "train_illuminants", "test_illuminants", "canonical", "sensors")


class Unserialisable(TypeError):
    """A value the store cannot write as data (a function, a class outside the allow-list)."""


# ---------------------------------------------------------------------------------------------
# models


def encode(tree: Any, allowed: Mapping[str, type], arrays: dict[str, np.ndarray]) -> Any:
    """A JSON skeleton of ``tree`` (allow-listed Modules, frozen dataclasses and enums, tuples,
    lists, string-keyed dicts, JSON scalars), its arrays added to ``arrays`` as ``a<i>``.

    Arguments:
        tree: a fitted model or a part of one.
        allowed: the allow-list ``{qualified name: class}``.
        arrays: filled with the arrays.

    Returns:
        The skeleton.

    Raises:
        Unserialisable: anything else.
    """
    if isinstance(tree, (jax.Array, np.ndarray, np.generic)):
        name = f"a{len(arrays)}"
        arrays[name] = np.asarray(tree)
        if isinstance(tree, jax.Array):
            weak = bool(tree.weak_type)
            if weak and (tree.size > WEAK_LIMIT or tree.dtype.kind not in "biufc"):
                raise Unserialisable(f"a weakly typed {tree.dtype} array of {tree.size} elements")
            kind = "jax-weak" if weak else "jax"
        else:
            kind = "numpy" if isinstance(tree, np.ndarray) else "scalar"
        return {"$array": name, "kind": kind}
    if tree is None or isinstance(tree, (bool, int, float, str)):
        return tree
    cls = type(tree)
    if isinstance(tree, enum.Enum):
        return {"$enum": _allowed_name(cls, allowed), "value": encode(tree.value, allowed, arrays)}
    if cls is tuple:
        return {"$tuple": [encode(item, allowed, arrays) for item in tree]}
    if cls is list:
        return [encode(item, allowed, arrays) for item in tree]
    if cls is dict and all(isinstance(name, str) for name in tree):
        return {"$dict": {name: encode(value, allowed, arrays) for name, value in tree.items()}}
    if isinstance(tree, eqx.Module) or (dataclasses.is_dataclass(tree) and not isinstance(tree, type)):
        fields = {f.name: encode(getattr(tree, f.name), allowed, arrays) for f in dataclasses.fields(tree)}
        tag = "$module" if isinstance(tree, eqx.Module) else "$dataclass"
        return {tag: _allowed_name(cls, allowed), "fields": fields}
    raise Unserialisable(f"cannot store a {cls.__module__}.{cls.__qualname__}")


def _allowed_name(cls: type, allowed: Mapping[str, type]) -> str:
    name = qualified_name(cls)
    if allowed.get(name) is not cls:
        raise Unserialisable(f"{name} is not a class fitted models are rebuilt from")
    return name


def decode(node: Any, arrays: Mapping[str, np.ndarray], allowed: Mapping[str, type]) -> Any:
    """The inverse of :func:`encode`: classes come from ``allowed`` by name and are rebuilt field by
    field (``object.__new__``, as equinox unflattens a Module: no ``__init__`` runs).

    Arguments:
        node: a skeleton (or a part of one).
        arrays: the arrays it names.
        allowed: the allow-list ``{qualified name: class}``.

    Returns:
        The tree.

    Raises:
        Rejected: a node of unknown shape, a class outside ``allowed`` or of the wrong kind,
            fields other than the class's dataclass fields, a missing array.
    """
    if node is None or isinstance(node, (bool, int, float, str)):
        return node
    if isinstance(node, list):
        return [decode(item, arrays, allowed) for item in node]
    tag = next((name for name in _NODES if isinstance(node, dict) and name in node), None)
    if tag is None or set(node) != _NODES[tag]:
        raise Rejected(f"unknown skeleton node {str(node)[:80]}")
    if tag == "$array":
        return _array(node, arrays)
    if tag == "$tuple" and isinstance(node["$tuple"], list):
        return tuple(decode(item, arrays, allowed) for item in node["$tuple"])
    if tag == "$dict" and isinstance(node["$dict"], dict):
        return {name: decode(value, arrays, allowed) for name, value in node["$dict"].items()}
    if tag == "$enum":
        cls = _class(node["$enum"], allowed, enum.Enum)
        try:
            return cls(decode(node["value"], arrays, allowed))
        except ValueError:
            raise Rejected(f"{node['$enum']} has no value {node['value']!r}") from None
    if tag in ("$module", "$dataclass") and isinstance(node["fields"], dict):
        cls = _class(node[tag], allowed, eqx.Module if tag == "$module" else object)
        if tag == "$dataclass" and (issubclass(cls, eqx.Module) or not dataclasses.is_dataclass(cls)):
            raise Rejected(f"{node[tag]} is not a plain dataclass")
        names = [f.name for f in dataclasses.fields(cls)]
        if sorted(node["fields"]) != sorted(names):
            raise Rejected(f"{node[tag]}: fields {sorted(node['fields'])} are not the class's {sorted(names)}")
        instance = object.__new__(cls)
        for name in names:
            object.__setattr__(instance, name, decode(node["fields"][name], arrays, allowed))
        return instance
    raise Rejected(f"malformed skeleton node {tag}")


def _class(name: Any, allowed: Mapping[str, type], base: type) -> type:
    cls = allowed.get(name) if isinstance(name, str) else None
    if cls is None:
        raise Rejected(f"{name!r} is not a class fitted models are rebuilt from")
    if not issubclass(cls, base):
        raise Rejected(f"{name} is not a {base.__name__}")
    return cls


def _array(node: Mapping[str, Any], arrays: Mapping[str, np.ndarray]) -> Any:
    name, kind = node["$array"], node["kind"]
    if not isinstance(name, str) or name not in arrays or kind not in _ARRAY_KINDS:
        raise Rejected(f"array node {dict(node)} names no stored array")
    array = arrays[name]
    if array.dtype.kind not in "biufc":
        raise Rejected(f"array {name} has dtype {array.dtype}")
    if kind == "numpy":
        return array
    if kind == "scalar":
        if array.ndim:
            raise Rejected(f"array {name} is not a scalar")
        return array[()]
    if kind == "jax":
        # device_put, not jnp.asarray: the latter compiles a small copy program per shape.
        return jax.device_put(array)
    # A weak type (an array built from Python scalars) promotes differently; only Python scalars
    # make one, so the array is rebuilt from them.
    if array.size > WEAK_LIMIT:
        raise Rejected(f"array {name}: weakly typed arrays hold at most {WEAK_LIMIT} elements")
    if array.ndim == 0:
        return jnp.asarray(array.item())
    return jnp.stack([jnp.asarray(value) for value in array.ravel().tolist()]).reshape(array.shape)


def same_tree(a: Any, b: Any) -> bool:
    """Whether two trees have the same structure, static parts, array types, dtypes, weak types
    and values (NaN equal to NaN).

    Arguments:
        a, b: the trees.

    Returns:
        True when they are the same.
    """
    leaves_a, tree_a = jax.tree_util.tree_flatten(a)
    leaves_b, tree_b = jax.tree_util.tree_flatten(b)
    if tree_a != tree_b:
        return False
    for x, y in zip(leaves_a, leaves_b, strict=True):
        if not isinstance(x, (jax.Array, np.ndarray, np.generic)):
            if type(x) is not type(y) or x != y:
                return False
            continue
        if type(x) is not type(y) or np.asarray(x).dtype != np.asarray(y).dtype:
            return False
        if isinstance(x, jax.Array) and x.weak_type != y.weak_type:  # pyright: ignore[reportAttributeAccessIssue]
            return False
        if not np.array_equal(np.asarray(x), np.asarray(y), equal_nan=np.asarray(x).dtype.kind in "fc"):
            return False
    return True


# ---------------------------------------------------------------------------------------------
# worlds: named arrays and names


def world_parts(world: World) -> tuple[dict[str, str], dict[str, np.ndarray]]:
    """``({"name", "camera_name"}, arrays)`` of ``world``.

    Arguments:
        world: the world.

    Returns:
        The names and the arrays (``reflectances``, ``train_illuminants``, ``test_illuminants``,
        ``canonical``, ``sensors``).

    Raises:
        Unserialisable: the camera has a linearisation (a function), or the world has fields this
            layout does not know.
    """
    known = {"reflectances", "train_illuminants", "test_illuminants", "canonical", "camera", "name"}
    if {f.name for f in dataclasses.fields(World)} != known:
        raise Unserialisable("World's fields changed; worlds are not stored")
    if world.camera.linearisation is not None:
        raise Unserialisable(f"world {world.name!r} has a camera linearisation (a function)")
    arrays = {name: np.asarray(getattr(world, name)) for name in _WORLD_ARRAYS[:-1]}
    arrays["sensors"] = np.asarray(world.camera.sensors)
    return {"name": world.name, "camera_name": world.camera.name}, arrays


def world_from_parts(names: Any, arrays: Mapping[str, np.ndarray]) -> World:
    """The inverse of :func:`world_parts`.

    Arguments:
        names: ``{"name", "camera_name"}`` (strings).
        arrays: the five arrays.

    Returns:
        The world (built by its constructor, which checks the shapes).

    Raises:
        Rejected: other names or arrays.
    """
    if not isinstance(names, dict) or set(names) != {"name", "camera_name"}:
        raise Rejected(f"world names {names!r}")
    if not all(isinstance(value, str) for value in names.values()):
        raise Rejected(f"world names {names!r}")
    if sorted(arrays) != sorted(_WORLD_ARRAYS) or any(arrays[n].dtype.kind != "f" for n in _WORLD_ARRAYS):
        raise Rejected(f"world arrays {sorted(arrays)}")
    # device_put, not jnp.asarray: the latter compiles a small copy program per shape.
    camera = Camera(sensors=jax.device_put(arrays["sensors"]), name=names["camera_name"])
    spectra = {name: jax.device_put(arrays[name]) for name in _WORLD_ARRAYS[:-1]}
    try:
        return World(**spectra, camera=camera, name=names["name"])
    except ValueError as error:
        raise Rejected(f"world arrays: {error}") from None


__all__ = [
    "Rejected",
    "Unserialisable",
    "decode",
    "digest",
    "encode",
    "read_entry",
    "same_tree",
    "world_from_parts",
    "world_parts",
    "write_entry",
]
