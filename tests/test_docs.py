"""The documentation site's generated pages (docs/hooks.py): the estimator catalogue has one entry per
registry family, the CLI reference has every command, the thesis-table pages show the numbers of
``ccjax reproduce --json``, and every page of the navigation exists (hand-written or generated)."""

import dataclasses
import importlib.util
import json
import pathlib
import re

import page_blocks
import pytest

from ccjax.cli import build_parser
from ccjax.estimators import registry

ROOT = pathlib.Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


@pytest.fixture(scope="module")
def hooks():
    spec = importlib.util.spec_from_file_location("docs_hooks", DOCS / "hooks.py")
    assert spec is not None and spec.loader is not None
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
    for name in sub.choices or {}:
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
    "docs/photographs.md": 145,
    "docs/training-loop.md": 27,
    "docs/training.md": 121,
}
"""Pages whose blocks take long (seconds measured on 2 shared CPU cores; photographs.md and
training.md at a load average of about 3.5, when the other three took 1.3 to 1.8 times their
seconds here): the README's tour and a sweep of 1,000 scenes; seven photographs rendered, FFCC
scored in 3 folds and trained, then estimate, correct and the posterior, each command a fresh
process; a training loop compiled for several models; the NUS-8 protocol over eight stand-in
folders with two learned methods and a sweep sharded over four host devices. They run with the
slow suite."""

MANUAL_PAGES = {
    "docs/camera-without-labels.md": 380,
}
"""Pages whose commands train on several folders many times (seconds as above): FFCC for a target
camera, leave-one-camera-out with FFCC and with any-camera over six stand-in folders. They run with
``pytest -m manual``: the slow suite has no room for them."""

RUN_ELSEWHERE = {
    "docs/a-raw-file.md": "tests/test_raw_transcript.py runs it on a stand-in raw file and opens every file it writes",
    "docs/photographer-session.md": "docs/scripts/photographer.py writes it from the commands' output on "
    "photographs it renders; tests/test_photographer_session.py reruns it and compares (manual: about 85 s)",
}
"""Pages whose commands another test runs, and why they are not run here."""

PAGES = [
    pytest.param(page, marks=pytest.mark.slow)
    if page in SLOW_PAGES
    else pytest.param(page, marks=pytest.mark.manual)
    if page in MANUAL_PAGES
    else page
    for page in [
        "README.md",
        *sorted(
            str(p.relative_to(ROOT))
            for p in DOCS.glob("*.md")
            if page_blocks.page_blocks(p.read_text()) and str(p.relative_to(ROOT)) not in RUN_ELSEWHERE
        ),
    ]
]

RUNNER = """
import json, subprocess, sys, time
start = time.perf_counter()
extras, blocks = json.loads(sys.argv[1]), json.load(sys.stdin)
if blocks["stand_ins"]:
    from page_blocks import write_stand_in_sets
    write_stand_in_sets(blocks["stand_ins"])
namespace = {"__name__": "__main__"}
for block in blocks["blocks"]:
    where = f"block of line {block['line']}"
    print(f"== {where} ({block['kind']}) at {time.perf_counter() - start:.1f} s", file=sys.stderr, flush=True)
    if block["kind"] == "shell":
        run = subprocess.run(["bash", "-e", "-o", "pipefail", "-c", block["code"]])
        if run.returncode:
            sys.exit(f"{where}: exit status {run.returncode}")
        continue
    try:
        exec(compile(block["code"], f"<{where}>", "exec"), namespace)
    except ModuleNotFoundError as error:
        if error.name not in extras:
            raise
        print(f"{where} needs {extras[error.name]}", flush=True)
"""
"""Runs a page's blocks in order, as a reader pastes them into one Python session and one shell in
the same folder: Python blocks in one namespace, shell blocks in bash (exit on the first failing
command); first the stand-in photo sets the commands name. A Python block whose import needs an
extra that is not installed is named and left out."""


def test_blocks_are_read_in_page_order_with_marks_and_console_commands():
    page = (
        "Text.\n\n```python\nx = 1\n```\n\n<!-- not run: needs a GPU -->\n```bash\nnvidia-smi\n```\n\n"
        "```text\n$ not a command\n```\n\n```console\n$ ccjax evaluate cube_plus/ \\\n    --json e.json\n"
        "output line\n$ ls nus8-C1/\nimage-0000.png\n```\n\n```sh\nccjax train /path/to/nus8-Sony\n```\n"
    )
    blocks = page_blocks.page_blocks(page)
    assert [(b.kind, b.line, b.not_run) for b in blocks] == [
        ("python", 3, None),
        ("shell", 8, "needs a GPU"),
        ("shell", 16, None),
        ("shell", 24, None),
    ]
    assert blocks[2].code == "ccjax evaluate cube_plus/ \\\n    --json e.json\nls nus8-C1/\n"
    # Sets named by a path into another folder are the reader's own, not a stand-in's.
    assert page_blocks.stand_in_sets(blocks) == ["cube_plus", "nus8-C1"]
    with pytest.raises(ValueError, match="line 1 is not closed"):
        page_blocks.page_blocks("```bash\nls\n")


@pytest.mark.parametrize("page", PAGES)
def test_every_python_block_of_a_page_runs_as_pasted(page, tmp_path):
    """The ```python and shell blocks of the README and of each docs page run in page order, in one
    fresh process outside the checkout, with an empty cache and no external data (the embedded
    default world only), as a newcomer pastes them: Python blocks in one session, shell blocks in
    the same folder with this environment's ``ccjax`` and ``python``, a console block's ``$ ``
    lines only. The blocks create the files they use; the research photo sets a page's commands
    name (Cube+, NUS-8) are stand-in folders of rendered 16-bit PNGs with ground truth
    (``page_blocks.write_stand_in_sets``), since their photographs are not part of ccjax. A block
    marked ``<!-- not run: reason -->`` is left out (the mark must give a reason); a block that
    needs an optional extra that is not installed skips, naming it."""
    import os
    import subprocess
    import sys

    blocks = page_blocks.page_blocks((ROOT / page).read_text())
    assert blocks
    run_blocks = [block for block in blocks if block.not_run is None]
    assert all(block.not_run.strip() for block in blocks if block.not_run is not None)
    if not run_blocks:
        pytest.skip(f"{page}: every block is marked not run: " + "; ".join(b.not_run or "" for b in blocks))
    env = {k: v for k, v in os.environ.items() if k not in ("CCJAX_DATA", "CI")}
    env |= {"CCJAX_CACHE": str(tmp_path / "cache"), "MPLBACKEND": "Agg"}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), str(ROOT / "tests"), env.get("PYTHONPATH", "")])
    # The shell finds this interpreter's `python` and `ccjax` first (its virtual environment's bin).
    env["PATH"] = os.pathsep.join([str(pathlib.Path(sys.executable).parent), env.get("PATH", "")])
    payload = {
        "stand_ins": page_blocks.stand_in_sets(blocks),
        "blocks": [dataclasses.asdict(block) for block in run_blocks],
    }
    run = subprocess.run(
        [sys.executable, "-c", RUNNER, json.dumps(EXTRAS)],
        input=json.dumps(payload),
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert run.returncode == 0, f"{page}:\n{run.stdout[-2000:]}\n{run.stderr[-3000:]}"
    skipped = [line for line in run.stdout.splitlines() if re.fullmatch(r"block of line \d+ needs .*", line)]
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


def test_limits_page_shows_what_the_command_prints(capsys, monkeypatch):
    """docs/limits.md's example is what the command prints: its usage (options the command has; a
    newly added one may be missing from the page) and the error line, exactly."""
    text = (DOCS / "limits.md").read_text()
    (shown,) = re.findall(r"^```text\n\$ ccjax compare --scenes 1000000000\n(.*?)^```", text, re.S | re.M)
    monkeypatch.setenv("COLUMNS", "80")
    with pytest.raises(SystemExit) as exit_:
        build_parser().parse_args(["compare", "--scenes", "1000000000"])
    assert exit_.value.code == 2
    printed = capsys.readouterr().err.splitlines()
    *usage, error = shown.splitlines()
    assert error == printed[-1]
    assert usage[0].startswith("usage: ccjax compare [-h]")
    options = set(re.findall(r"--[\w-]+", "\n".join(printed[:-1])))
    assert set(re.findall(r"--[\w-]+", "\n".join(usage))) <= options
