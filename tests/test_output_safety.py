"""``ccjax correct`` never replaces its inputs, outputs never collide,
existing outputs need ``--overwrite``, every file is written atomically, and paths and labels are
checked before any work with one-line errors (exit 2; Ctrl-C: 130)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from fork_client import ForkServer
from image_files import bad_files

import ccjax.io
from ccjax import cli, io
from ccjax.cli import common
from ccjax.cli import estimate as estimate_command
from ccjax.io import writing
from ccjax.io.outputs import path_key
from ccjax.runs import folders


@pytest.fixture(scope="module")
def world(small_test_world):
    return small_test_world


@pytest.fixture
def setup(small_world_commands, monkeypatch):
    """The small world for every command, a private cache, the identity preview matrix (fast)."""
    monkeypatch.setattr(ccjax.io, "preview_matrix_cached", lambda w: np.eye(3, dtype=np.float32))
    return small_world_commands


def _image(path, colour=(0.5, 0.4, 0.3)):
    rgb = np.broadcast_to(np.asarray(colour), (6, 6, 3)).copy()
    rgb[::2, ::3] *= 0.5  # some texture
    writing.write_linear(path, rgb)
    return path


def _snapshot(folder):
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def _no_reads(monkeypatch):
    monkeypatch.setattr(ccjax.io, "read_image", lambda *a, **k: pytest.fail("an image was read before the check"))


def _one_line_error(captured, *needles):
    assert captured.out == "" and "Traceback" not in captured.err
    lines = [line for line in captured.err.strip().splitlines() if ": notice: " not in line]
    assert len(lines) == 1 and lines[0].startswith("ccjax "), captured.err
    for needle in needles:
        assert str(needle) in lines[0], (needle, lines[0])


# ---------------------------------------------------------------------------------------------
# Item 1: inputs are never replaced; outputs never collide; existing outputs need --overwrite


def test_correct_in_place_is_refused_naming_both_paths(setup, monkeypatch, capsys):
    source = _image(setup / "in.png")
    before = source.read_bytes()
    _no_reads(monkeypatch)
    assert cli.main(["correct", str(source), str(source), "--method", "GW", "--no-progress"]) == 2
    _one_line_error(capsys.readouterr(), "would overwrite the input", source)
    assert source.read_bytes() == before and sorted(p.name for p in setup.iterdir()) == ["in.png"]


@pytest.mark.parametrize("spelling", ["same", "dot", "trailing-slash"])
def test_correct_folder_onto_itself_is_refused(setup, monkeypatch, capsys, spelling):
    folder = setup / "d"
    folder.mkdir()
    _image(folder / "a.png")
    _image(folder / "b.tif", (0.2, 0.3, 0.6))
    before = _snapshot(folder)
    target = {"same": str(folder), "dot": f"{folder}/.", "trailing-slash": str(folder) + "/"}[spelling]
    _no_reads(monkeypatch)
    assert cli.main(["correct", str(folder), target, "--method", "GW", "--no-progress"]) == 2
    _one_line_error(capsys.readouterr(), "input folder", folder, target)
    assert _snapshot(folder) == before


@pytest.mark.parametrize("clash", ["input", "output"])
def test_preview_equal_to_an_input_or_output_is_refused(setup, monkeypatch, capsys, clash):
    source = _image(setup / "in.png")
    before = source.read_bytes()
    out = setup / "out.png"
    preview = {"input": source, "output": out}[clash]
    _no_reads(monkeypatch)
    argv = ["correct", str(source), str(out), "--method", "GW", "--preview", str(preview), "--no-progress"]
    assert cli.main(argv) == 2
    _one_line_error(capsys.readouterr(), "--preview", preview)
    assert source.read_bytes() == before and not out.exists()


def test_folder_outputs_never_collide_case_insensitively(setup, capsys):
    folder = setup / "d"
    folder.mkdir()
    _image(folder / "a.png", (0.5, 0.4, 0.3))
    _image(folder / "a.tif", (0.2, 0.3, 0.6))
    _image(folder / "A.PNG", (0.6, 0.6, 0.1))
    out = setup / "out"
    assert cli.main(["correct", str(folder), str(out), "--method", "GW", "--no-progress"]) == 0
    names = sorted(p.name for p in out.iterdir())
    assert len(names) == 6 and len({name.casefold() for name in names}) == 6, names
    assert {"A.png", "A_preview.png"} <= set(names)  # inputs in sorted order: the first keeps the plain names
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 3
    # Each input's own output: correcting it alone gives the same pixels.
    for line in lines:
        source = line.split(": ", 1)[0]
        written = [part.split(" (", 1)[0] for part in line.rsplit("-> ", 1)[1].split(", ")]  # "out (what it is)"
        single = setup / "single" / f"x{os.path.splitext(written[0])[1]}"
        single.parent.mkdir(exist_ok=True)
        argv = ["correct", source, str(single), "--method", "GW", "--no-progress", "--overwrite"]
        assert cli.main(argv) == 0
        capsys.readouterr()
        np.testing.assert_array_equal(io.read_image(written[0]).rgb, io.read_image(single).rgb)
        np.testing.assert_array_equal(io.read_png(written[1]), io.read_png(single.with_name("x_preview.png")))


def test_folder_outputs_helper_gives_distinct_names(tmp_path):
    paths = [Path("d") / name for name in ("a.png", "a.tif", "A.PNG", "a.TIF", "a_tif.tif", "b.nef")]
    outputs, previews = folders.folder_outputs(paths, tmp_path)
    keys = [path_key(p) for p in outputs + previews]
    assert len(set(keys)) == len(keys)
    assert outputs[0].name == "a.png" and previews[0].name == "a_preview.png"
    assert outputs[-1].name == "b.tiff"  # raw inputs are written as TIFF


def test_existing_output_needs_overwrite(setup, monkeypatch, capsys):
    source = _image(setup / "in.tif")
    out, preview = setup / "out.tif", setup / "out_tif_preview.png"
    out.write_bytes(b"old output")
    with monkeypatch.context() as patch:
        _no_reads(patch)
        assert cli.main(["correct", str(source), str(out), "--method", "GW", "--no-progress"]) == 2
        _one_line_error(capsys.readouterr(), out, "--overwrite")
    assert out.read_bytes() == b"old output" and not preview.exists()
    out.unlink()
    preview.write_bytes(b"old preview")
    with monkeypatch.context() as patch:
        _no_reads(patch)
        assert cli.main(["correct", str(source), str(out), "--method", "GW", "--no-progress"]) == 2
        _one_line_error(capsys.readouterr(), preview, "--overwrite")
    assert preview.read_bytes() == b"old preview" and not out.exists()
    out.write_bytes(b"old output")
    assert cli.main(["correct", str(source), str(out), "--method", "GW", "--no-progress", "--overwrite"]) == 0
    assert io.read_image(out).rgb.shape == (6, 6, 3) and io.read_png(preview).dtype == np.uint8


def test_existing_output_in_a_folder_needs_overwrite(setup, monkeypatch, capsys):
    folder, out = setup / "d", setup / "out"
    folder.mkdir()
    out.mkdir()
    _image(folder / "a.png")
    (out / "a_preview.png").write_bytes(b"old preview")
    _no_reads(monkeypatch)
    assert cli.main(["correct", str(folder), str(out), "--method", "GW", "--no-progress"]) == 2
    _one_line_error(capsys.readouterr(), out / "a_preview.png")
    assert _snapshot(out) == {"a_preview.png": b"old preview"}


# ---------------------------------------------------------------------------------------------
# Item 3: every written file is atomic


def _interrupt_replace(monkeypatch):
    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(os, "replace", interrupted)


@pytest.mark.parametrize("name", ["x.png", "x.tif", "x.tiff", "x_preview.png", "r.json"])
def test_interrupted_write_keeps_the_old_file_and_leaves_no_temporary(tmp_path, monkeypatch, name):
    path = tmp_path / name
    path.write_bytes(b"old contents")
    rgb = np.full((4, 5, 3), 0.25)
    write = {
        "x.png": lambda: writing.write_linear(path, rgb),
        "x.tif": lambda: writing.write_linear(path, rgb),
        "x.tiff": lambda: writing.write_linear(path, rgb),
        "x_preview.png": lambda: io.write_preview(path, rgb),
        "r.json": lambda: common.write(str(path), "{}", overwrite=True),
    }[name]
    with monkeypatch.context() as patch:
        _interrupt_replace(patch)
        with pytest.raises(KeyboardInterrupt):
            write()
    assert path.read_bytes() == b"old contents"
    assert [p.name for p in tmp_path.iterdir()] == [name]  # no temporary left behind
    write()
    assert path.read_bytes() != b"old contents" and [p.name for p in tmp_path.iterdir()] == [name]


def test_tiff_written_through_memory_reads_back_exactly(tmp_path):
    rgb = np.random.default_rng(0).uniform(0.0, 1.0, (7, 9, 3))
    writing.write_linear(tmp_path / "x.tif", rgb)
    writing.write_linear(tmp_path / "x.png", rgb)
    codes = writing.quantise(rgb)
    for name in ("x.tif", "x.png"):
        np.testing.assert_array_equal(np.round(io.read_image(tmp_path / name).rgb * 65535.0), codes)


def test_interrupted_correct_exits_130_and_keeps_old_outputs(setup, monkeypatch, capsys):
    source = _image(setup / "in.png")
    out, preview = setup / "out.tif", setup / "out_tif_preview.png"
    out.write_bytes(b"old output")
    preview.write_bytes(b"old preview")
    _interrupt_replace(monkeypatch)
    assert cli.main(["correct", str(source), str(out), "--method", "GW", "--no-progress", "--overwrite"]) == 130
    captured = capsys.readouterr()
    assert captured.err == "ccjax correct: interrupted\n"
    assert out.read_bytes() == b"old output" and preview.read_bytes() == b"old preview"
    assert sorted(p.name for p in setup.iterdir() if p.name != "cache") == ["in.png", "out.tif", "out_tif_preview.png"]


# ---------------------------------------------------------------------------------------------
# Item 7: checks before any work, one-line errors, every bad file reported, Ctrl-C


@pytest.mark.parametrize("command", ["estimate", "correct", "evaluate"])
def test_method_typo_is_reported_before_any_image_is_read(setup, monkeypatch, capsys, command):
    gt = io.write_dataset(setup / "set", np.full((1, 4, 4, 3), 0.5), [[1.0, 1.0, 1.0]])
    _no_reads(monkeypatch)
    argv = {
        "estimate": ["estimate", str(setup / "set"), "--method", "GWW"],
        "correct": ["correct", str(setup / "set"), str(setup / "out"), "--method", "GWW"],
        "evaluate": ["evaluate", str(setup / "set"), "--ground-truth", str(gt), "--methods", "GW,GWW"],
    }[command]
    assert cli.main(argv + ["--no-progress"]) == 2
    _one_line_error(capsys.readouterr(), "'GWW'")
    assert not (setup / "out").exists()


def test_output_that_is_a_folder_is_refused(setup, monkeypatch, capsys):
    source = _image(setup / "in.png")
    (setup / "out.png").mkdir()
    _no_reads(monkeypatch)
    for target in (setup / "out.png", setup):
        assert cli.main(["correct", str(source), str(target), "--method", "GW", "--no-progress"]) == 2
        _one_line_error(capsys.readouterr(), target, "is a folder")


@pytest.mark.parametrize("option", ["--json", "--csv"])
@pytest.mark.parametrize("problem", ["folder", "under-a-file"])
def test_evaluate_report_paths_are_checked_first(setup, monkeypatch, capsys, option, problem):
    gt = io.write_dataset(setup / "set", np.full((1, 4, 4, 3), 0.5), [[1.0, 1.0, 1.0]])
    (setup / "afile").write_text("x")
    name = "r." + option[2:]  # a report's name ends in .json / .csv
    (setup / name).mkdir()
    target = {"folder": setup / name, "under-a-file": setup / "afile" / name}
    _no_reads(monkeypatch)
    argv = ["evaluate", str(setup / "set"), "--ground-truth", str(gt), "--methods", "GW", option, str(target[problem])]
    assert cli.main(argv + ["--no-progress"]) == 2
    _one_line_error(capsys.readouterr(), option, target[problem])


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0, reason="root writes to read-only folders")
def test_read_only_folder_is_refused_before_work(setup, monkeypatch, capsys):
    source = _image(setup / "in.png")
    locked = setup / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        _no_reads(monkeypatch)
        assert cli.main(["correct", str(source), str(locked / "o.png"), "--method", "GW", "--no-progress"]) == 2
        _one_line_error(capsys.readouterr(), locked, "not writable")
    finally:
        locked.chmod(0o700)


def test_os_errors_during_work_are_one_line(setup, monkeypatch, capsys):
    source = _image(setup / "in.png")

    def refused(path, data, **options):
        raise PermissionError(13, "Permission denied", str(path))

    monkeypatch.setattr(writing, "write_file", refused)
    monkeypatch.setattr(folders, "atomic_write_files", lambda files, **options: refused(next(iter(files)), None))
    assert cli.main(["correct", str(source), str(setup / "o.tif"), "--method", "GW", "--no-progress"]) == 2
    captured = capsys.readouterr()
    errors = [line for line in captured.err.splitlines() if ": notice: " not in line]
    assert "Traceback" not in captured.err and len(errors) == 1
    assert "Permission denied" in captured.err and "o.tif" in captured.err


def test_every_bad_file_in_a_folder_is_reported(setup, capsys):
    folder = setup / "d"
    folder.mkdir()
    _image(folder / "a.png")
    bad = [(message, Path(str(path))) for message, path in bad_files(setup)[:2]]
    for _, path in bad:
        (folder / path.name).write_bytes(path.read_bytes())
    out = setup / "out"
    assert cli.main(["correct", str(folder), str(out), "--method", "GW", "--no-progress"]) == 2
    captured = capsys.readouterr()
    assert "2 of 3 images cannot be used" in captured.err and "Traceback" not in captured.err
    for message, path in bad:
        assert message in captured.err and path.name in captured.err
    # The run goes on past the bad files (the good one is corrected) and exits non-zero.
    assert captured.out.count("\n") == 1 and "a.png" in captured.out
    assert sorted(p.name for p in out.iterdir()) == ["a.png", "a_preview.png"]


def test_ctrl_c_exits_130_with_one_line(monkeypatch, capsys):
    def interrupted(args):
        raise KeyboardInterrupt

    monkeypatch.setattr(estimate_command, "run_estimate", interrupted)
    assert cli.main(["estimate", "x.png", "--method", "GW"]) == 130
    assert capsys.readouterr().err == "ccjax estimate: interrupted\n"


def test_ctrl_c_in_a_process_has_no_traceback(tmp_path):
    script = (
        "import sys, ccjax.cli, ccjax.cli.estimate as estimate\n"
        "def interrupted(args):\n    raise KeyboardInterrupt\n"
        "estimate.run_estimate = interrupted\n"
        "sys.exit(ccjax.cli.main(['estimate', 'x.png', '--method', 'GW']))\n"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert done.returncode == 130 and done.stderr == "ccjax estimate: interrupted\n" and done.stdout == ""


# ---------------------------------------------------------------------------------------------
# Atomic writes under signals: SIGINT and SIGKILL at random points while `ccjax correct` writes PNG and
# TIFF outputs. No file under a final name is ever partial (each is its old or its new contents,
# byte for byte); after SIGINT (exit 130) no temporary file is left. Each trial is a child of a
# fork server (tests/fork_server.py) that imported the command line once.

KILL_TRIALS = 50
"""Trials per signal in the manual test; the slow suite runs QUICK_KILL_TRIALS."""

QUICK_KILL_TRIALS = 4


def _kill_inputs(folder: Path) -> None:
    """Six 96x128 images, PNG and TIFF in turn: twelve outputs, each written in some milliseconds."""
    folder.mkdir()
    rng = np.random.default_rng(17)
    for index in range(6):
        rgb = rng.uniform(0.05, 0.9, (96, 128, 3)) * np.array([1.0, 0.8, 0.6])
        writing.write_linear(folder / f"im{index}.{'png' if index % 2 else 'tif'}", rgb)


def _old_outputs(out: Path, names) -> dict[str, bytes]:
    """Fill ``out`` with stand-ins for an earlier run's outputs (``--overwrite`` replaces them)."""
    old = {name: f"old contents of {name}".encode() for name in names}
    for name, blob in old.items():
        (out / name).write_bytes(blob)
    return old


def _without_run(blob: bytes) -> bytes:
    """A written file's bytes without its run identifier (each run writes its own: a PNG's
    ``tEXt`` "ccjax run" chunk dropped whole, CRC included; a TIFF's ImageDescription id zeroed),
    so two runs' complete files compare equal."""
    import re

    chunk = blob.find(b"tEXtccjax run\0")
    if blob.startswith(b"\x89PNG") and chunk >= 4:
        length = int.from_bytes(blob[chunk - 4 : chunk], "big")
        return blob[: chunk - 4] + blob[chunk + 8 + length :]
    return re.sub(rb"ccjax run [0-9a-f]{32}", b"ccjax run " + b"0" * 32, blob)


def _listing(folder: Path) -> frozenset:
    """(name, inode) of every entry: a new temporary file or a file renamed into place changes it."""
    try:
        return frozenset((entry.name, entry.inode()) for entry in os.scandir(folder))
    except FileNotFoundError:
        return frozenset()


def _wait_for_writing(folder: Path, before: frozenset, timeout: float) -> bool:
    """Poll ``folder`` until its listing differs from ``before`` (the command started writing)."""
    import time

    end = time.perf_counter() + timeout
    while time.perf_counter() < end:
        if _listing(folder) != before:
            return True
        time.sleep(0.0002)
    return False


def _run_kill_trials(tmp_path: Path, trials: int, seed: int = 0) -> dict[str, int]:
    """SIGINT and SIGKILL ``trials`` times each; returns the counts for the report."""
    import random
    import time

    folder, out = tmp_path / "in", tmp_path / "out"
    _kill_inputs(folder)
    argv = ["correct", str(folder), str(out), "--method", "GW", "--no-progress", "--overwrite"]
    logs = tmp_path / "logs"
    logs.mkdir()
    server = ForkServer(
        logs,
        CCJAX_CACHE=str(tmp_path / "cache"),
        JAX_COMPILATION_CACHE_DIR=str(tmp_path / "jax-cache"),
        JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS="0",
        JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES="0",
    )
    try:
        # Reference runs (uninterrupted): the first fills the caches (world, preview matrix, compiled
        # code); the second gives the new contents of every output and how long the writing lasts.
        for _ in range(2):
            for path in out.iterdir() if out.is_dir() else ():
                path.unlink()
            _, log = server.start(argv, tmp_path)
            assert _wait_for_writing(out, frozenset(), 600), Path(f"{log}.err").read_text()[-3000:]
            started = time.perf_counter()
            code = server.wait()
            assert code == 0, Path(f"{log}.err").read_text()[-3000:]
            writing_time = time.perf_counter() - started
        new = {path.name: path.read_bytes() for path in out.iterdir()}
        assert len(new) == 12 and not any(name.startswith(".") for name in new), sorted(new)
        counts = {"trials": 0, "partial": 0, "stray_after_sigint": 0, "temporary_after_sigkill": 0}
        counts.update({"mid_run": 0, "sigint_130": 0})
        rng = random.Random(seed)
        for trial in range(2 * trials):
            kill = signal.SIGINT if trial % 2 == 0 else signal.SIGKILL
            for path in out.iterdir():
                path.unlink()
            old = _old_outputs(out, new) if trial % 4 < 2 else {}
            # A random point of the writing: once the first file appears (or is replaced), wait
            # up to the time the reference run took to write everything.
            before = _listing(out)
            pid, log = server.start(argv, tmp_path)
            _wait_for_writing(out, before, 600)
            # The first SIGINT lands as the first file appears (surely mid-run, whatever the load
            # does to the reference's writing time); the others at random points.
            time.sleep(0.0 if trial == 0 else rng.uniform(0.0, writing_time))
            try:
                os.kill(pid, kill)
            except ProcessLookupError:
                pass
            code = server.wait()
            counts["trials"] += 1
            final = {p.name: p.read_bytes() for p in out.iterdir() if not p.name.startswith(".")}
            temporary = [p.name for p in out.iterdir() if p.name.startswith(".")]
            partial = [
                name
                for name, blob in final.items()
                if _without_run(blob) not in (_without_run(new[name]), old.get(name))
            ]
            counts["partial"] += len(partial)
            assert not partial, (trial, kill, partial)
            replaced = sum(final.get(name) == new[name] for name in new)
            counts["mid_run"] += 0 < replaced < len(new) or bool(temporary)
            if kill == signal.SIGINT:
                stderr = Path(f"{log}.err").read_text()
                assert code in (0, 130), (trial, code, stderr)
                if code == 130:
                    counts["sigint_130"] += 1
                    assert stderr.strip().splitlines()[-1:] == ["ccjax correct: interrupted"], stderr
                assert "Traceback" not in stderr, stderr
                counts["stray_after_sigint"] += len(temporary)
                assert not temporary, (trial, temporary)
            else:
                assert code in (0, -signal.SIGKILL), (trial, code)
                counts["temporary_after_sigkill"] += len(temporary)
        return counts
    finally:
        server.close()


@pytest.mark.slow  # over 30 s on 2 cores: the default run stays under 10 minutes
def test_kill_while_correct_writes_leaves_no_partial_file(tmp_path):
    counts = _run_kill_trials(tmp_path, QUICK_KILL_TRIALS)
    print(counts)
    assert counts["partial"] == 0 and counts["stray_after_sigint"] == 0
    assert counts["sigint_130"] >= 1  # some SIGINTs came while the command ran


@pytest.mark.manual  # about 180 s on 2 cores; the slow suite runs the same check with 4 trials
def test_kill_while_correct_writes_50_trials_each(tmp_path):
    counts = _run_kill_trials(tmp_path, KILL_TRIALS, seed=1)
    print(counts)
    assert counts["partial"] == 0 and counts["stray_after_sigint"] == 0
    assert counts["mid_run"] >= KILL_TRIALS // 2  # most signals came between the first and the last output
