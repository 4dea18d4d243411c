"""The API reference covers the public names: every name in a public ``__all__`` is rendered on a
page of ``docs/api/`` (a mkdocstrings ``:::`` entry of a page in the nav of mkdocs.yml), no private
name is rendered there, and every function the pages render documents each of its parameters and,
when it returns something, what it returns.

Fast: nothing is imported or built. The sources are read with griffe (what mkdocstrings reads),
the ``:::`` entries and their options from the pages, and which members an entry renders follows
mkdocstrings-python's rules with the options of mkdocs.yml (``filters``, ``members``,
``show_if_no_docstring``, ``show_submodules``; an imported member only when its module exports it).
The docstrings are parsed with mkdocs.yml's ``docstring_options`` and docs/roles.py's fixes of the
rows (a grouped ``a, b: ...`` parameter is one row per name), as the site shows them.

Run ``python -m pytest -q tests/test_api_pages.py -s`` (or ``python tests/test_api_pages.py``) for
the counts.
"""

from __future__ import annotations

import ast
import functools
import importlib.util
import pathlib
import re
import sys
import textwrap

import griffe
import yaml

ROOT = pathlib.Path(__file__).resolve().parents[1]
API = ROOT / "docs" / "api"
ENTRY = re.compile(r"^::: *(\S+)\s*$")
PARAMETER_KINDS = (griffe.DocstringSectionKind.parameters, griffe.DocstringSectionKind.other_parameters)
RETURN_KINDS = (griffe.DocstringSectionKind.returns, griffe.DocstringSectionKind.yields)


class _Loader(yaml.SafeLoader):
    """mkdocs.yml with its ``!ENV``/``!relative`` tags read as plain values."""


_Loader.add_multi_constructor("!", lambda loader, suffix, node: None)


@functools.cache
def mkdocs_config() -> dict:
    """mkdocs.yml, parsed."""
    return yaml.load((ROOT / "mkdocs.yml").read_text(encoding="utf-8"), Loader=_Loader)


def handler_options() -> dict:
    """The python handler's global options of mkdocs.yml."""
    for plugin in mkdocs_config()["plugins"]:
        if isinstance(plugin, dict) and "mkdocstrings" in plugin:
            return plugin["mkdocstrings"]["handlers"]["python"]["options"]
    raise AssertionError("mkdocs.yml has no mkdocstrings python handler")


def nav_pages() -> list[str]:
    """Every page of the nav of mkdocs.yml (paths under ``docs/``)."""
    pages: list[str] = []

    def walk(node):
        if isinstance(node, str):
            pages.append(node)
        elif isinstance(node, list):
            for item in node:
                walk(item)
        elif isinstance(node, dict):
            for value in node.values():
                walk(value)

    walk(mkdocs_config()["nav"])
    return pages


def entries() -> list[tuple[str, str, dict]]:
    """``(page, object path, local options)`` of each ``:::`` entry of the API pages."""
    out = []
    for page in sorted(API.glob("*.md")):
        lines = page.read_text(encoding="utf-8").splitlines()
        for index, line in enumerate(lines):
            match = ENTRY.match(line)
            if not match:
                continue
            block = []
            for following in lines[index + 1 :]:
                if following.strip() and not following.startswith(" "):
                    break
                block.append(following)
            options = (yaml.safe_load(textwrap.dedent("\n".join(block))) or {}).get("options", {})
            out.append((f"api/{page.name}", match.group(1), options))
    return out


@functools.cache
def roles():
    """docs/roles.py, the site's griffe extensions."""
    spec = importlib.util.spec_from_file_location("docs_roles", ROOT / "docs" / "roles.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@functools.cache
def package() -> griffe.Module:
    """ccjax as griffe reads it for the site: mkdocs.yml's docstring options and its extensions
    from docs/roles.py, in its order."""
    options = handler_options()
    extensions = [getattr(roles(), name.rpartition(":")[2])() for name in options.get("extensions", [])]
    return griffe.load(
        "ccjax",
        search_paths=[str(ROOT)],
        docstring_parser=options.get("docstring_style", "google"),
        docstring_options=options.get("docstring_options", {}),
        extensions=griffe.load_extensions(*extensions),
        resolve_aliases=True,
        resolve_external=False,
    )


def _modules(module: griffe.Module):
    yield module
    for member in module.modules.values():
        if not member.is_alias and not member.name.startswith("_"):
            yield from _modules(member)


def public_modules() -> list[griffe.Module]:
    """ccjax and each of its modules and packages that declares ``__all__``, none under a private name."""
    modules = list(_modules(package()))
    # An ``__all__`` griffe cannot read statically would drop its names from the check silently.
    unread = [
        m.path
        for m in modules
        if m.exports is None and isinstance(m.filepath, pathlib.Path) and "\n__all__" in m.filepath.read_text()
    ]
    assert not unread, f"__all__ not readable statically in {unread}"
    return [module for module in modules if module.exports is not None]


def public_names() -> list[str]:
    """``package.name`` for each name of each public ``__all__`` (``__version__`` and such dunders
    are metadata, not API)."""
    return [
        f"{module.path}.{name}"
        for module in public_modules()
        for name in module.exports or ()
        if not (name.startswith("__") and name.endswith("__"))
    ]


def _target(obj):
    try:
        return obj.final_target if obj.is_alias else obj
    except (griffe.AliasResolutionError, griffe.CyclicAliasError):
        return None


def _selected(obj, options: dict, root: bool) -> list:
    """The members an entry renders under ``obj`` (mkdocstrings-python's children template)."""
    members_list = options.get("members") if root else None
    candidates = [m for m in obj.members.values() if not m.inherited]
    if members_list is True:
        chosen = candidates
    elif members_list is False or members_list == []:
        chosen = []
    elif members_list is not None:
        chosen = [m for m in candidates if m.name in set(members_list)]
    else:
        filters = [(re.compile(f.removeprefix("!")), f.startswith("!")) for f in options.get("filters", [])]
        chosen = [m for m in candidates if _kept(m.name, filters)]
        if not options.get("show_if_no_docstring", False):
            chosen = [m for m in chosen if m.has_docstrings]
    out = []
    for member in chosen:
        if _target(member) is None:
            continue
        if not (members_list is not None or not member.is_imported or member.is_public):
            continue
        if member.is_module and not options.get("show_submodules", False):
            continue
        out.append(member)
    return out


def _kept(name: str, filters) -> bool:
    keep = True
    for pattern, exclude in filters:
        if pattern.search(name):
            keep = not exclude
    return keep


def rendered() -> dict[str, griffe.Object]:
    """``{shown path: the object shown}`` of everything the API pages render (an imported member
    is shown under the path it is imported at)."""
    shown: dict[str, griffe.Object] = {}
    defaults = handler_options()

    def render(obj, path: str, options: dict, root: bool) -> None:
        target = _target(obj)
        if target is None:
            return
        shown[path] = target
        if target.is_module or target.is_class:
            for member in _selected(target if not obj.is_alias else obj, options, root):
                render(member, f"{path}.{member.name}", options, False)

    for _, path, local in entries():
        render(package()[path.removeprefix("ccjax.")] if path != "ccjax" else package(), path, defaults | local, True)
    return shown


def _function_parameters(function: griffe.Function) -> list[str]:
    names = [p.name for p in function.parameters]
    if function.parent is not None and function.parent.is_class and names and "staticmethod" not in function.labels:
        names = names[1:]  # self, cls
    return names


def _documented_parameters(obj: griffe.Object) -> set[str]:
    names = set()
    for section in obj.docstring.parsed if obj.docstring else []:
        if section.kind in PARAMETER_KINDS:
            for parameter in section.value:
                names |= {part.strip().lstrip("*") for part in parameter.name.split(",")}
    return names


def _returns_something(function: griffe.Function) -> bool:
    if "property" in function.labels:
        return False
    if function.returns is not None:
        return str(function.returns) not in ("None", "NoReturn", "Never")
    try:
        tree = ast.parse(textwrap.dedent(function.source))
    except (SyntaxError, ValueError, OSError):
        return False
    body = tree.body[0]
    for node in ast.walk(body):
        if node is not body and isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda):
            continue
        if isinstance(node, ast.Return) and node.value is not None:
            return True
        if isinstance(node, ast.Yield | ast.YieldFrom):
            return True
    return False


def _documents_return(obj: griffe.Object) -> bool:
    return any(section.kind in RETURN_KINDS for section in (obj.docstring.parsed if obj.docstring else []))


@functools.cache
def report() -> dict:
    """The counts and the offenders (lists of paths, or ``path: why``)."""
    shown = rendered()
    covered = {obj.path for obj in shown.values()}  # an object shown under any path covers its names
    names = public_names()
    pkg = package()
    missing = []
    for name in names:
        target = _target(pkg[name.removeprefix("ccjax.")])
        if name not in shown and (target is None or target.path not in covered):
            missing.append(name)
    private = sorted(
        path for path in shown if any(part.startswith("_") for part in path.removeprefix("ccjax.").split("."))
    )
    functions = {obj.path: obj for obj in shown.values() if obj.is_function}
    undocumented = []
    no_returns = []
    for path, function in sorted(functions.items()):
        absent = [p for p in _function_parameters(function) if p not in _documented_parameters(function)]
        if absent:
            undocumented.append(f"{path}: {', '.join(absent)}")
        if _returns_something(function) and not _documents_return(function):
            no_returns.append(path)
    rows = []  # a parameter row naming no parameter, a Returns section of several rows or a named one
    for path, function in sorted(functions.items()):
        signature = {p.lstrip("*") for p in _function_parameters(function)}
        for section in function.docstring.parsed if function.docstring else []:
            if section.kind in PARAMETER_KINDS:
                rows += [f"{path}: row {p.name!r}" for p in section.value if p.name.lstrip("*") not in signature]
            if section.kind in RETURN_KINDS and (len(section.value) != 1 or section.value[0].name):
                rows.append(f"{path}: {len(section.value)} {section.kind.value} rows, named {section.value[0].name!r}")
    pages = set(nav_pages())
    off_nav = sorted({page for page, _, _ in entries() if page not in pages})
    return {
        "names": names,
        "missing": missing,
        "private": private,
        "functions": functions,
        "undocumented": undocumented,
        "no_returns": no_returns,
        "off_nav": off_nav,
        "rows": rows,
    }


def summary(found: dict) -> str:
    n, f = len(found["names"]), len(found["functions"])
    on = n - len(found["missing"])
    documented = f - len(found["undocumented"])
    returns = f - len(found["no_returns"])
    return (
        f"public names on API pages: {on}/{n} ({on / max(n, 1):.1%}); private names shown: {len(found['private'])}\n"
        f"functions shown: {f}; every parameter documented: {documented}/{f} ({documented / max(f, 1):.1%}); "
        f"Returns where something is returned: {returns}/{f} ({returns / max(f, 1):.1%})"
    )


def test_the_api_pages_cover_every_public_name():
    found = report()
    print(summary(found))
    assert len(found["names"]) > 300  # the __all__ lists were read
    assert not found["off_nav"], f"API pages not in the nav of mkdocs.yml: {found['off_nav']}"
    assert not found["missing"], f"{len(found['missing'])} public names on no API page:\n" + "\n".join(found["missing"])
    assert not found["private"], "private names on the API pages:\n" + "\n".join(found["private"])


def test_every_function_shown_documents_its_parameters_and_returns():
    found = report()
    assert len(found["functions"]) > 100
    undocumented, no_returns = found["undocumented"], found["no_returns"]
    assert not undocumented, f"{len(undocumented)} shown functions leave parameters undocumented:\n" + "\n".join(
        undocumented
    )
    assert not no_returns, f"{len(no_returns)} shown functions return something without Returns:\n" + "\n".join(
        no_returns
    )


def test_each_row_of_the_pages_is_one_parameter_or_the_one_return_value():
    """The rows the site shows: a parameter row names a parameter of the signature (so its type
    and default are the parameter's), a Returns section is one unnamed row."""
    rows = report()["rows"]
    assert not rows, f"{len(rows)} bogus rows:\n" + "\n".join(rows)


def test_grouped_parameters_become_one_row_each():
    text = (
        "Do.\n\nArguments:\n    x: one.\n    height, width: the size\n        in pixels.\n\nReturns:\n    a, b: kept.\n"
    )
    split = roles().split_grouped(text)
    assert "    height: the size\n        in pixels.\n    width: the size\n        in pixels.\n" in split
    assert "    a, b: kept." in split  # only parameter sections
    sections = griffe.Docstring(split, parser="google").parsed
    names = [p.name for s in sections if s.kind in PARAMETER_KINDS for p in s.value]
    assert names == ["x", "height", "width"]


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    result = report()
    print(summary(result))
    for key in ("missing", "private", "undocumented", "no_returns", "off_nav", "rows"):
        if "-v" in sys.argv:
            print(f"\n{key} ({len(result[key])}):\n  " + "\n  ".join(result[key]))
