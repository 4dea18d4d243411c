"""House rules that hold by themselves: small modules and one export style.

The import direction (layers, no cycles, private modules) is import-linter's job (``lint-imports``
in ``.ci/run``, contracts in ``pyproject.toml``); these are the rules it cannot state.
"""

from __future__ import annotations

import ast
import pathlib

import pytest

import ccjax

PACKAGE = pathlib.Path(ccjax.__file__).parent
MAX_LINES = 500
"""Modules stay under this many lines: one job each (CONTRIBUTING.md, "Conventions")."""
LONG_BY_NATURE = {"thesis.py"}
"""Transcribed thesis tables: data, not code, so their length is the thesis'."""


def modules() -> list[pathlib.Path]:
    return sorted(PACKAGE.rglob("*.py"))


def test_no_module_passes_the_line_limit():
    lengths = {
        path.relative_to(PACKAGE).as_posix(): len(path.read_text(encoding="utf-8").splitlines())
        for path in modules()
        if path.relative_to(PACKAGE).as_posix() not in LONG_BY_NATURE
    }
    assert len(lengths) > 50  # the modules were found
    too_long = {name: lines for name, lines in lengths.items() if lines > MAX_LINES}
    assert not too_long, f"modules over {MAX_LINES} lines (split them by job): {too_long}"


def _declared_all(path: pathlib.Path) -> list[str] | None:
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        targets = node.targets if isinstance(node, ast.Assign) else []
        if any(isinstance(target, ast.Name) and target.id == "__all__" for target in targets):
            return ast.literal_eval(node.value)
    return None


@pytest.mark.parametrize("init", sorted(PACKAGE.rglob("__init__.py")), ids=lambda p: p.parent.name)
def test_every_package_declares_its_public_names(init):
    """``__all__`` in every package (what ``from package import *``, the API reference and
    tests/test_docstrings.py read), not ``import X as X`` lists."""
    names = _declared_all(init)
    assert names is not None, f"{init.relative_to(PACKAGE.parent)} declares no __all__"
    assert len(set(names)) == len(names), f"{init}: a name is listed twice in __all__"
    source = init.read_text(encoding="utf-8")
    tree = ast.parse(source)
    redundant = [
        alias.name
        for node in ast.walk(tree)
        if isinstance(node, ast.ImportFrom)
        for alias in node.names
        if alias.asname == alias.name and not alias.name.startswith("__")
    ]
    assert not redundant, f"{init}: list these in __all__ instead of `import X as X`: {redundant}"


def test_no_module_reaches_up_to_the_top_level_package():
    """``ccjax/__init__.py`` imports lazily from every layer (``ccjax.fit`` from the runs layer),
    so a module that takes a name from it (``from ccjax import __version__``) points up; only
    submodules may be imported through it (``from ccjax import metrics``). import-linter does not
    see these imports of the root package, hence this test."""
    upward = []
    for path in modules():
        if path == PACKAGE / "__init__.py":
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import) and any(alias.name == "ccjax" for alias in node.names):
                upward.append(f"{path.relative_to(PACKAGE)}:{node.lineno} import ccjax")
            if isinstance(node, ast.ImportFrom) and node.module == "ccjax" and node.level == 0:
                for alias in node.names:
                    if not ((PACKAGE / alias.name).is_dir() or (PACKAGE / f"{alias.name}.py").is_file()):
                        upward.append(f"{path.relative_to(PACKAGE)}:{node.lineno} from ccjax import {alias.name}")
    assert not upward, f"names taken from the top-level package: {upward}"
