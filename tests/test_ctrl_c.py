"""Ctrl-C at any time after ``ccjax`` starts, also while JAX is being imported,
exits 130 with one line and no traceback.

A real process gets a real SIGINT at several delays. ``-X importtime`` (Python's own import report,
no hook in ccjax) tells the test when :func:`ccjax.cli.main` is running (the first command module
has been imported) and when the import of JAX finished, so the delays are measured from the start
of ``main`` and the test checks that some signals really arrived during the import of JAX."""

from __future__ import annotations

import builtins
import concurrent.futures
import os
import signal
import subprocess
import sys
import sysconfig
import threading
import time
import types
from pathlib import Path

import pytest

from ccjax import cli

DELAYS = (0.0, 0.01, 0.03, 0.06, 0.1, 0.2, 0.35, 0.5, 0.8, 1.2)
"""Seconds from the start of ``main`` to SIGINT: the first ones land in the import of numpy and JAX
(about 0.5-1.5 s on the CI machine), the last ones in the command's work (``ccjax compare`` with
an empty cache fits and compiles for many seconds)."""

QUICK_DELAYS = {"python -m ccjax": (0.0, 0.03, 0.1, 0.4), "console script": (0.05, 1.2)}
"""The default suite's share of :data:`DELAYS`, run concurrently (each trial costs a process start)."""

WORK = ("compare", "--no-progress")
"""The command interrupted: each trial has its own empty cache, so it is still fitting or compiling
at the last delay."""


def _module(line: str) -> str:
    return line.rsplit("|", 1)[-1].strip()


def _interrupt(
    command: list[str], delay: float, tmp_path: Path, exit_seconds: list[float] | None = None
) -> tuple[int, list[str], str, bool]:
    """Run ``command`` (after ``python -X importtime``), SIGINT it ``delay`` s after ``main`` started.

    Returns:
        The exit code, the stderr lines that are not import times, the whole stderr, and whether
        the signal was sent before the import of JAX had finished; the seconds from the signal
        to the exit are appended to ``exit_seconds``.
    """
    tmp_path.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, CCJAX_CACHE=str(tmp_path / "cache"))
    process = subprocess.Popen(
        [sys.executable, "-X", "importtime", *command],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        cwd=tmp_path,
        env=env,
    )
    assert process.stderr is not None
    lines: list[str] = []
    main_started, jax_imported = threading.Event(), threading.Event()

    def read() -> None:
        assert process.stderr is not None
        for line in process.stderr:
            lines.append(line)
            name = _module(line) if line.startswith("import time:") else ""
            if name == "ccjax.cli.common":  # imported by build_parser, inside main's try
                main_started.set()
            elif name == "jax":
                jax_imported.set()
        main_started.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        assert main_started.wait(120), "main never started"
        time.sleep(delay)
        during_import = not jax_imported.is_set()
        process.send_signal(signal.SIGINT)
        sent = time.monotonic()
        process.wait(120)
        if exit_seconds is not None:
            exit_seconds.append(time.monotonic() - sent)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    reader.join(10)
    process.stderr.close()
    text = "".join(lines)
    messages = [line for line in text.splitlines() if not line.startswith("import time:")]
    return process.returncode, messages, text, during_import


def _console_script() -> Path | None:
    script = Path(sysconfig.get_path("scripts")) / "ccjax"
    return script if script.is_file() else None


def _command(entry: str) -> list[str]:
    if entry == "console script":
        script = _console_script()
        if script is None:
            pytest.skip("the ccjax console script is not installed")
        return [str(script), *WORK]
    return ["-m", "ccjax", *WORK]


def _check(trials: list[tuple[float, tuple[int, list[str], str, bool]]]) -> None:
    for delay, (code, messages, text, _) in trials:
        assert "Traceback" not in text and "Exception ignored" not in text, (delay, text[-3000:])
        assert code == 130, (delay, code, messages)
        assert len(messages) == 1 and messages[0] in ("ccjax: interrupted", "ccjax compare: interrupted"), messages
    during_import = sum(result[3] for _, result in trials)
    assert during_import >= 1, f"none of {len(trials)} signals came during the import of JAX"


def test_ctrl_c_at_any_time_exits_130_with_one_line(tmp_path):
    runs = [(entry, delay) for entry, delays in QUICK_DELAYS.items() for delay in delays]
    commands = {entry: _command(entry) for entry in QUICK_DELAYS}
    with concurrent.futures.ThreadPoolExecutor(len(runs)) as pool:
        futures = [
            pool.submit(_interrupt, commands[entry], delay, tmp_path / str(index))
            for index, (entry, delay) in enumerate(runs)
        ]
        _check([(delay, future.result()) for (_, delay), future in zip(runs, futures, strict=True)])


@pytest.mark.slow
@pytest.mark.parametrize("entry", ["python -m ccjax", "console script"])
def test_ctrl_c_at_every_delay_exits_130_with_one_line(tmp_path, entry):
    command = _command(entry)
    # Each trial with its own empty cache: a fit a trial stored would shorten the next one's work.
    _check([(delay, _interrupt(command, delay, tmp_path / str(index))) for index, delay in enumerate(DELAYS)])


@pytest.mark.slow
def test_ctrl_c_while_a_sweep_compiles_ahead_exits_at_once(tmp_path):
    # A cold `ccjax compare` compiles its programs on worker threads for about 20 s from ~4 s after
    # main starts; the exit must not wait for the compilation in progress (it took 18-26 s).
    seconds: list[float] = []
    code, messages, text, _ = _interrupt(["-m", "ccjax", "compare", "--no-progress"], 7.0, tmp_path, seconds)
    assert "Traceback" not in text, text[-3000:]
    assert code == 130 and messages == ["ccjax compare: interrupted"], (code, messages)
    assert seconds[0] < 3.0, seconds


def test_interrupt_raised_inside_an_import_error_counts_as_ctrl_c():
    # What an extension module's initialisation makes of Ctrl-C (pybind11, nanobind): an ImportError
    # whose cause is the KeyboardInterrupt.
    try:
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as interrupt:
            raise ImportError("Encountered an error while initializing the extension.") from interrupt
    except ImportError as error:
        assert cli.interrupted(error)
    assert not cli.interrupted(ImportError("no module named x"))
    assert not cli.interrupted(ValueError("bad"))


needs_default_handler = pytest.mark.skipif(
    signal.getsignal(signal.SIGINT) is not signal.default_int_handler, reason="SIGINT is not Python's default here"
)


@needs_default_handler
def test_held_interrupt_is_raised_after_the_import(monkeypatch):
    # Ctrl-C during the held import is raised once the module is loaded, not inside it.
    name = "ccjax_test_ctrl_c_module"
    loaded = []
    original = builtins.__import__

    def fake_import(module, *args, **kwargs):
        if module == name:
            signal.raise_signal(signal.SIGINT)  # delivered while "importing": must be held
            loaded.append(module)
            return None
        return original(module, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", fake_import)
    with pytest.raises(KeyboardInterrupt):
        cli.import_holding_interrupts(name)
    assert loaded == [name]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


@needs_default_handler
def test_swallowed_interrupt_is_delivered_again():
    # A KeyboardInterrupt that Python could only report as unraisable (raised in a gc callback)
    # comes back to ordinary code a moment later.
    start = time.perf_counter()
    with pytest.raises(KeyboardInterrupt):
        cli.redeliver_interrupts(types.SimpleNamespace(exc_value=KeyboardInterrupt()))
        while time.perf_counter() - start < 10:
            time.sleep(0.001)
    assert time.perf_counter() - start < 5


@needs_default_handler
def test_one_interrupt_reported_twice_is_delivered_once():
    # Several callbacks can report the same Ctrl-C; a second redelivery would reach the process
    # after the command stopped (and kill it by SIGINT instead of exit 130).
    interrupts = 0
    start = time.perf_counter()
    try:
        cli.redeliver_interrupts(types.SimpleNamespace(exc_value=KeyboardInterrupt()))
        cli.redeliver_interrupts(types.SimpleNamespace(exc_value=KeyboardInterrupt()))
        while time.perf_counter() - start < 5:
            time.sleep(0.001)
    except KeyboardInterrupt:
        interrupts += 1
    try:
        deadline = time.perf_counter() + 0.3
        while time.perf_counter() < deadline:
            time.sleep(0.001)
    except KeyboardInterrupt:
        interrupts += 1
    assert interrupts == 1


def test_other_unraisable_errors_go_to_the_default_hook(capsys, monkeypatch):
    class Broken:
        def __del__(self):
            raise ValueError("from a __del__")

    monkeypatch.setattr(sys, "unraisablehook", cli.redeliver_interrupts)
    Broken()  # collected at once; its error can only be reported
    assert "from a __del__" in capsys.readouterr().err


def test_a_late_copy_of_the_interrupt_while_stopping_still_gives_130(monkeypatch, capsys):
    # A redelivered Ctrl-C can land while main is already stopping on the first one (before it has
    # printed its line): main still prints one line and gives 130, it does not raise.
    def interrupted_import(*names):
        raise KeyboardInterrupt

    calls = []
    real_prefix = cli.prefix

    def prefix_interrupted_once(command):
        calls.append(command)
        if len(calls) == 1:
            raise KeyboardInterrupt  # the late copy, landing in the stopping code
        return real_prefix(command)

    monkeypatch.setattr(cli, "import_holding_interrupts", interrupted_import)
    monkeypatch.setattr(cli, "prefix", prefix_interrupted_once)
    try:
        code = cli.main(["methods"])
    except KeyboardInterrupt:
        pytest.fail("main let the late copy of the interrupt escape")
    assert code == 130 and len(calls) == 2
    assert capsys.readouterr().err.splitlines() == ["ccjax methods: interrupted"]
