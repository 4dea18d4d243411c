"""The ``>>>`` examples of ccjax's docstrings run as written (doctest), each in a fresh folder, so
an example that writes a file (a figure) leaves nothing behind."""

from __future__ import annotations

import doctest
import importlib
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]


def _modules_with_examples() -> list[str]:
    """Modules of ccjax whose source has a ``>>>`` line (found without importing anything)."""
    names = []
    for path in sorted((ROOT / "ccjax").rglob("*.py")):
        if any(line.lstrip().startswith(">>> ") for line in path.read_text(encoding="utf-8").splitlines()):
            parts = path.relative_to(ROOT).with_suffix("").parts
            names.append(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
    return names


def _examples() -> list:
    found = []
    for name in _modules_with_examples():
        module = importlib.import_module(name)
        found += [test for test in doctest.DocTestFinder(recurse=True).find(module) if test.examples]
    return found


EXAMPLES = _examples()


def test_the_examples_are_found():
    assert {test.name.rsplit(".", 1)[-1] for test in EXAMPLES} >= {"plot_sweep", "adaptation_sharpening"}


@pytest.mark.parametrize("test", EXAMPLES, ids=lambda test: test.name)
def test_docstring_example_runs(test, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    test.globs = dict(test.globs)
    report: list[str] = []
    runner.run(test, out=report.append)
    assert runner.failures == 0, "".join(report)[-3000:]
