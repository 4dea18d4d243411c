"""The documentation site's generated pages (docs/hooks.py): the estimator catalogue has one entry per
registry family, the CLI reference has every command, the thesis-table pages show the numbers of
``ccjax reproduce --json``, and every page of the navigation exists (hand-written or generated)."""

import importlib.util
import json
import pathlib
import re

import pytest

from ccjax.cli import build_parser
from ccjax.estimators import registry

ROOT = pathlib.Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


@pytest.fixture(scope="module")
def hooks():
    spec = importlib.util.spec_from_file_location("docs_hooks", DOCS / "hooks.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_catalogue_has_one_entry_per_registry_family(hooks):
    entries = registry.available()
    page = hooks.catalogue_markdown()
    headings = [line[3:] for line in page.splitlines() if line.startswith("## ")]
    assert headings == [f"`{entry.grammar}`" for entry in entries]
    summary = [line for line in page.splitlines() if line.startswith("| <code>")]
    assert len(summary) == len(entries)
    assert f"({len(entries)} families;" in page


def test_catalogue_numbers_come_from_the_data(hooks):
    entry = registry.available()[2]  # GW
    measured = {
        "n_scenes": 7,
        "speed_batch": {"8": 16, "64": 4},
        "machine": "test machine",
        "families": [
            {
                "grammar": entry.grammar,
                "example": entry.example,
                "rg_rms": {"8": 0.0123, "64": 0.0045},
                "rg_rms_se": {"8": 0.0011, "64": 0.0002},
                "angular_rms": {"8": 3.21, "64": 1.23},
                "ok_fraction": {"8": 1.0, "64": 0.5},
                "scenes_per_second": {"8": 12345.0, "64": 678.0},
            }
        ],
    }
    page = hooks.catalogue_markdown([entry], measured)
    assert "| 0.0123 | 0.0045 | 12,345 | 678 |" in page
    assert "rg RMS 0.0123 ± 0.0011 at 8 surfaces, 0.0045 ± 0.0002 at 64" in page
    assert "over 7 scenes" in page and "test machine" in page
    # A family without data says so.
    assert "Not measured" in hooks.catalogue_markdown([registry.available()[0]], {"families": []})


def test_thesis_sections_are_read_from_the_descriptions(hooks):
    assert hooks.thesis_section("grey world, 2 x mean RGB (§4.5.1)") == "§4.5.1"
    assert hooks.thesis_section("3-D Colour by Correlation in (r,g,L), brightness too (ch. 10)") == "ch. 10"
    assert hooks.thesis_section("Minkowski p-norm grey world (Finlayson & Trezzi)").startswith("–")


def test_cli_reference_has_every_command(hooks):
    page = hooks.cli_markdown()
    parser = build_parser()
    (sub,) = [a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction"]
    for name in sub.choices:
        assert f"## `ccjax {name}`" in page
    assert "usage: ccjax compare" in page


def test_table_page_shows_ours_thesis_difference_and_sampling_error(hooks):
    payload = {
        "table": "4.2",
        "rows": [
            {"method": "GW", "column": "rg", "ours": 0.0571, "thesis": 0.058, "relative_difference": -0.0155,
             "sampling_error": 0.0012, "ok_fraction": 1.0},
            {"method": "GW", "column": "angular", "ours": 8.0, "thesis": 10.0, "relative_difference": -0.2,
             "sampling_error": 0.25, "ok_fraction": 1.0},
        ],
    }  # fmt: skip
    page = hooks.table_markdown("4.2", payload)
    assert "| `GW` | 0.0571 | 0.0012 | 0.058 | -1.6% | 100% |" in page
    assert "**Cells**: 1/2 within ±10%, 1/2 within ±15%, 2/2 within ±20%; largest |diff| 20.0%." in page
    assert "![Table 4.2: ours against the thesis](table-4.2.png)" in page
    assert hooks.table_figure("4.2", payload)[:8] == b"\x89PNG\r\n\x1a\n"
    assert "Not generated yet" in hooks.table_markdown("4.2", None)


def test_committed_data_are_command_output():
    for path in sorted((DOCS / "data").glob("reproduce-*.json")):
        payload = json.loads(path.read_text())
        assert payload["table"] == path.stem.removeprefix("reproduce-")
        for row in payload["rows"]:
            assert {"method", "column", "ours", "thesis", "relative_difference"} <= set(row)
            if row["relative_difference"] is not None:
                assert row["relative_difference"] == pytest.approx(row["ours"] / row["thesis"] - 1)


def test_every_navigation_page_exists(hooks):
    yaml = pytest.importorskip("yaml")  # installed with the docs extra (mkdocs)
    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text().replace("!!python", "#"))
    pages = []

    def walk(node):
        if isinstance(node, str):
            pages.append(node)
        elif isinstance(node, list):
            for item in node:
                walk(item)
        elif isinstance(node, dict):
            for value in node.values():
                walk(value)

    walk(config["nav"])
    generated = hooks.generated_pages()
    missing = [page for page in pages if page not in generated and not (DOCS / page).is_file()]
    assert not missing
    # Every figure a generated page shows is generated too.
    for path, content in generated.items():
        if path.endswith(".md"):
            folder = pathlib.PurePosixPath(path).parent
            for image in re.findall(r"!\[[^\]]*\]\(([^)]+\.png)\)", content):
                assert str(folder / image).removeprefix("./") in generated, (path, image)


EXTRAS = {"cv2": "opencv-contrib-python-headless (the test extra)", "rawpy": "rawpy (the raw extra)"}
"""Modules that documented blocks may import from an optional extra, and what installs each."""

SLOW_PAGES = {
    "README.md": 40,
    "docs/getting-started.md": 32,
    "docs/photographs.md": 44,
    "docs/camera-without-labels.md": 30,
    "docs/training-loop.md": 27,
}
"""Pages whose blocks take long (seconds measured on 2 shared CPU cores): the README's tour and a
sweep of 1,000 scenes; FFCC trained on 16 images; two cameras' worlds, maps and a leave-one-camera-out
run; a training loop compiled for several models. They run with the slow suite."""

PAGES = [
    pytest.param(page, marks=pytest.mark.slow) if page in SLOW_PAGES else page
    for page in [
        "README.md",
        *sorted(str(p.relative_to(ROOT)) for p in DOCS.glob("*.md") if "```python" in p.read_text()),
    ]
]

RUNNER = """
import json, sys
extras = json.loads(sys.argv[1])
namespace = {"__name__": "__main__"}
for number, block in enumerate(json.load(sys.stdin), 1):
    try:
        exec(compile(block, f"<block {number}>", "exec"), namespace)
    except ModuleNotFoundError as error:
        if error.name not in extras:
            raise
        print(f"block {number} needs {extras[error.name]}", flush=True)
"""
"""Runs a page's blocks in order in one namespace, as a reader pastes them into one session; a
block whose import needs an extra that is not installed is named and left out."""


@pytest.mark.parametrize("page", PAGES)
def test_every_python_block_of_a_page_runs_as_pasted(page, tmp_path):
    """The ```python blocks of the README and of each docs page run in order, in one fresh process
    outside the checkout, with an empty cache and no external data (the embedded default world
    only), as a newcomer pastes them: the blocks create the files they use. A block that needs an
    optional extra that is not installed skips, naming it."""
    import os
    import subprocess
    import sys

    blocks = re.findall(r"^```python\n(.*?)^```", (ROOT / page).read_text(), re.S | re.M)
    assert blocks
    env = {k: v for k, v in os.environ.items() if k not in ("CCJAX_DATA", "CI")}
    env |= {"CCJAX_CACHE": str(tmp_path / "cache"), "MPLBACKEND": "Agg"}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
    run = subprocess.run(
        [sys.executable, "-c", RUNNER, json.dumps(EXTRAS)],
        input=json.dumps(blocks),
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert run.returncode == 0, f"{page}:\n{run.stderr[-3000:]}"
    skipped = [line for line in run.stdout.splitlines() if re.fullmatch(r"block \d+ needs .*", line)]
    if skipped:
        pytest.skip(f"{page}: " + "; ".join(skipped))


def test_nothing_cites_a_file_the_repository_does_not_have():
    """Docstrings, examples, tests and pages cite only files the repository has, not the design note
    (a design note kept outside it)."""
    assert not (ROOT / ("DESIGN" + ".md")).exists()
    files = [*ROOT.glob("ccjax/**/*.py"), *ROOT.glob("examples/*.py"), *ROOT.glob("tests/*.py"), *DOCS.glob("**/*.md")]
    files += [ROOT / "README.md", ROOT / "CONTRIBUTING.md"]
    word = "DESIGN" + ".md"  # spelled apart, so this file does not cite it either
    section = "DESIGN" + " §"
    citing = [str(path.relative_to(ROOT)) for path in files if word in path.read_text() or section in path.read_text()]
    assert citing == []
