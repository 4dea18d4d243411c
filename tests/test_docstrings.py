"""Every public name of ccjax is documented: each name in the ``__all__`` of ccjax, of each of its
subpackages and of any other module that declares one has a docstring with the sections its kind
needs (every package declares ``__all__``: tests/test_house_rules.py).

The rule (checked on the object the name refers to; jit wrappers are unwrapped):

* a **function** has a docstring; if it takes a named parameter (other than ``self``/``cls``) the
  docstring has an ``Arguments:`` section; if it returns something (a return annotation other than
  ``None``/``NoReturn``, or without annotation a ``return <value>`` or ``yield`` in its source) the
  docstring has a ``Returns:`` (or ``Yields:``) section;
* a **class** has a docstring; a class with fields (dataclass fields, ``equinox.Module`` fields,
  ``NamedTuple`` fields) has an ``Attributes:`` (or ``Arguments:``) section; an enum's docstring
  needs no section (its members are its documentation);
* a **module** listed in ``__all__`` has a module docstring;
* other values (constants, type aliases) are documented where they are assigned (attribute
  docstrings, read by the API reference); Python cannot see those at run time, so they are not
  checked here.
"""

from __future__ import annotations

import ast
import dataclasses
import enum
import importlib
import importlib.util
import inspect
import pathlib
import pkgutil
import textwrap
import types
import typing

import pytest

import ccjax

# Known offenders, exempted while they are fixed (empty: every public name is documented). The test
# fails on any other offender, and on a name here that is no longer one, so this list can only
# shrink; it is printed on every run.
PENDING: set[str] = set()

ARGUMENTS = ("Arguments:", "Args:", "Parameters:")
RETURNS = ("Returns:", "Yields:")
ATTRIBUTES = ("Attributes:", "Arguments:")


def packages() -> list[str]:
    """ccjax, every subpackage (a folder with ``__init__.py``) and every other module that declares
    ``__all__`` (read from its source, so modules that run on import, ``__main__``, are not imported)."""
    names = ["ccjax"]
    for info in pkgutil.walk_packages(ccjax.__path__, "ccjax."):
        if info.ispkg:
            names.append(info.name)
            continue
        spec = importlib.util.find_spec(info.name)
        origin = spec.origin if spec is not None else None
        if origin and "\n__all__" in pathlib.Path(origin).read_text(encoding="utf-8"):
            names.append(info.name)
    return names


def _has_section(doc: str, sections: tuple[str, ...]) -> bool:
    return any(line.strip() in sections or line.strip().startswith(sections) for line in doc.splitlines())


def _unwrap(obj):
    seen = 0
    while hasattr(obj, "__wrapped__") and seen < 10:
        obj = obj.__wrapped__
        seen += 1
    return obj


def _returns_something(function) -> bool:
    try:
        hints = typing.get_type_hints(function)
    except Exception:  # unresolvable annotations (jaxtyping strings, forward references): read the raw one
        hints = {}
    if "return" in hints:
        return hints["return"] not in (type(None), typing.NoReturn)
    raw = getattr(function, "__annotations__", {}).get("return")
    if raw is not None:
        return raw not in ("None", "NoReturn", None)
    try:
        source = textwrap.dedent(inspect.getsource(function))
    except (OSError, TypeError):
        return False
    tree = ast.parse(source)
    body = tree.body[0]
    for node in ast.walk(body):
        if node is not body and isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda):
            continue
        if isinstance(node, ast.Return) and node.value is not None:
            return True
        if isinstance(node, ast.Yield | ast.YieldFrom):
            return True
    return False


def _named_parameters(function) -> list[str]:
    try:
        signature = inspect.signature(function)
    except (TypeError, ValueError):
        return []
    return [name for name in signature.parameters if name not in ("self", "cls")]


def _fields(cls) -> list[str]:
    if dataclasses.is_dataclass(cls):
        return [f.name for f in dataclasses.fields(cls)]
    if hasattr(cls, "_fields") and isinstance(cls._fields, tuple):  # NamedTuple
        return list(cls._fields)
    own = getattr(cls, "__annotations__", {})
    return [name for name in own if not name.startswith("_") and typing.get_origin(own[name]) is not typing.ClassVar]


def problem(obj) -> str | None:
    """What is missing from an object's docstring under the module's rule, or None."""
    if isinstance(obj, types.ModuleType):
        return None if (obj.__doc__ or "").strip() else "module without a docstring"
    if inspect.isclass(obj):
        doc = inspect.getdoc(obj) or ""
        own = obj.__dict__.get("__doc__")
        if not (own or "").strip():
            return "class without a docstring"
        if issubclass(obj, enum.Enum) or issubclass(obj, BaseException):
            return None
        if _fields(obj) and not _has_section(doc, ATTRIBUTES):
            return f"class with fields {_fields(obj)[:4]} but no Attributes: section"
        return None
    function = _unwrap(obj)
    if callable(function) and (
        inspect.isfunction(function) or inspect.isbuiltin(function) or inspect.ismethod(function)
    ):
        doc = inspect.getdoc(function) or ""
        if not doc.strip():
            return "function without a docstring"
        missing = []
        if _named_parameters(function) and not _has_section(doc, ARGUMENTS):
            missing.append("Arguments:")
        if _returns_something(function) and not _has_section(doc, RETURNS):
            missing.append("Returns:")
        return f"function docstring without {' and '.join(missing)}" if missing else None
    return None  # constants and aliases: see the module docstring


def public_names() -> list[tuple[str, str, object]]:
    out = []
    for package in packages():
        module = importlib.import_module(package)
        for name in getattr(module, "__all__", []):
            out.append((package, name, getattr(module, name)))
    return out


def offenders() -> tuple[dict[str, str], int, int]:
    """``({public name: what is missing}, names checked, distinct objects)``."""
    names = public_names()
    found, seen = {}, {}
    for package, name, obj in names:
        key = id(obj)
        if key not in seen:
            seen[key] = problem(obj)
        if seen[key] is not None:
            where = getattr(_unwrap(obj), "__module__", package)
            found[f"{package}.{name}"] = f"(defined in {where}): {seen[key]}"
    return found, len(names), len(seen)


def test_every_public_name_is_documented():
    found, checked, distinct = offenders()
    print(f"checked {checked} public names ({distinct} distinct objects) in {len(packages())} packages and modules")
    pending = sorted(set(found) & PENDING)
    if pending:
        print(f"{len(pending)} pending: " + ", ".join(pending))
    assert checked > 50  # the packages' __all__ lists were found
    new = {name: why for name, why in found.items() if name not in PENDING}
    assert not new, f"{len(new)} of {checked} public names lack documentation:\n" + "\n".join(
        f"{name} {why}" for name, why in sorted(new.items())
    )
    public = {f"{package}.{name}" for package, name, _ in public_names()}
    fixed = sorted((PENDING & public) - set(found))  # pending names that are now documented
    assert not fixed, f"documented now, remove from PENDING: {fixed}"


def _doc(text):
    def function(x, y=1):
        return x + y

    function.__doc__ = text
    return function


@pytest.mark.parametrize(
    ("doc", "expected"),
    [
        (None, "function without a docstring"),
        ("Add.", "function docstring without Arguments: and Returns:"),
        ("Add.\n\nArguments:\n    x: a.\n    y: b.\n", "function docstring without Returns:"),
        ("Add.\n\nArguments:\n    x: a.\n\nReturns:\n    The sum.\n", None),
    ],
)
def test_the_rule_on_functions(doc, expected):
    assert problem(_doc(doc)) == expected


def test_the_rule_on_classes_and_procedures():
    @dataclasses.dataclass
    class Fields:
        """Documented, but not its fields."""

        a: int = 0

    @dataclasses.dataclass
    class Described:
        """Documented.

        Attributes:
            a: a number.
        """

        a: int = 0

    def procedure(path):
        """Write something.

        Arguments:
            path: where.
        """
        del path

    assert "no Attributes: section" in problem(Fields)
    assert problem(Described) is None
    assert problem(procedure) is None  # returns nothing: no Returns: needed
    assert problem(types.ModuleType("empty")) == "module without a docstring"
