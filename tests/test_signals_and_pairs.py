"""A command stopped by Ctrl-C or SIGTERM exits with one line and 130 / 143, without a crash at
shutdown (``ccjax train`` stopped while XLA compiles ended in a segmentation fault), and a
corrected image and its preview are one pair: written whole before either replaces anything, put
in place together, and carrying the same run identifier, so no interruption leaves a pair half old
and half new or loses the previous one."""

from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from ccjax import cli, io


def _folder(path, count=60, seed=1):
    import jax

    from ccjax.scenes import sample_mondrians
    from ccjax.world import World

    images = sample_mondrians(jax.random.key(seed), World.default(), count, height=32, width=32)
    io.write_dataset(path, np.asarray(images.image), np.asarray(images.illuminant))
    return path


@pytest.mark.slow  # about 25 s on 2 shared cores: two trainings stopped while compiling
def test_train_stopped_while_compiling_exits_130_or_143_without_a_crash(tmp_path):
    """One training stopped by SIGINT and one by SIGTERM 6-8 s in, while XLA compiles;
    ``CCJAX_TRAIN_TRIALS=N`` stops N trainings by SIGINT instead (20 for the full check)."""
    folder = _folder(tmp_path / "set")
    rng = random.Random(0)
    trials = os.environ.get("CCJAX_TRAIN_TRIALS")
    numbers = [signal.SIGINT] * int(trials) if trials else [signal.SIGINT, signal.SIGTERM]
    for trial, number in enumerate(numbers):
        env = dict(os.environ, CCJAX_CACHE=str(tmp_path / f"cache{trial}"))
        out = tmp_path / f"m{trial}.eqx"
        command = [sys.executable, "-m", "ccjax", "train", str(folder), "--method", "FFCC", "--out", str(out)]
        process = subprocess.Popen(
            [*command, "--no-progress"], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
        )
        time.sleep(rng.uniform(6.0, 8.0))
        process.send_signal(number)
        _, err = process.communicate(timeout=120)
        want = 130 if number == signal.SIGINT else 143
        assert process.returncode == want, (process.returncode, err[-2000:])
        assert err.strip().splitlines()[-1] == f"ccjax train: {'interrupted' if want == 130 else 'terminated'}"
        assert not out.exists() and not [p for p in tmp_path.iterdir() if p.name.startswith(f".m{trial}.")]


def _photo(path, seed):
    rng = np.random.default_rng(seed)
    io.write_png(path, np.round(rng.uniform(0.05, 0.6, (30, 40, 3)) * [1.0, 0.7, 0.4] * 65535).astype(np.uint16))


def test_an_image_and_its_preview_carry_one_run_identifier(tmp_path):
    _photo(tmp_path / "a.png", 0)
    for name in ("out.png", "out.tif", "out.jpg"):
        argv = ["correct", str(tmp_path / "a.png"), str(tmp_path / name), "--method", "GW", "--no-progress"]
        assert cli.main([*argv, *(["--srgb", "8"] if name.endswith(".jpg") else [])]) == 0
    pairs = [("out.png", "out_preview.png"), ("out.tif", "out_tif_preview.png"), ("out.jpg", "out_jpg_preview.png")]
    identifiers = [(io.file_run(tmp_path / a), io.file_run(tmp_path / b)) for a, b in pairs]
    for output, preview in identifiers:
        assert output is not None and len(output) == 32 and output == preview
    assert len({output for output, _ in identifiers}) == 3  # one per pair


def test_a_full_disk_while_writing_the_pair_keeps_the_previous_pair(tmp_path, monkeypatch, capsys):
    """The preview's temporary does not fit: nothing is replaced, the previous pair is intact and
    no temporary is left."""
    import builtins

    _photo(tmp_path / "a.png", 0)
    argv = ["correct", str(tmp_path / "a.png"), str(tmp_path / "out.png"), "--method", "GW", "--no-progress"]
    assert cli.main(argv) == 0
    before = {name: (tmp_path / name).read_bytes() for name in ("out.png", "out_preview.png")}
    _photo(tmp_path / "a.png", 1)  # another photograph: another pair would be written
    real_open = builtins.open

    def full_disk(file, mode="r", *args, **kwargs):
        handle = real_open(file, mode, *args, **kwargs)
        if "w" in mode and os.path.basename(str(file)).startswith(".out_preview.png."):
            handle.close()
            raise OSError(28, "No space left on device")
        return handle

    monkeypatch.setattr(builtins, "open", full_disk)
    assert cli.main([*argv, "--overwrite"]) == 2
    assert "No space left on device" in capsys.readouterr().err
    monkeypatch.undo()
    assert {name: (tmp_path / name).read_bytes() for name in before} == before
    assert not [p.name for p in tmp_path.iterdir() if p.name.startswith(".")]


@pytest.mark.slow  # about 30 s on 2 shared cores: 20 corrections of a small photograph
def test_a_disk_full_at_any_byte_keeps_the_previous_pair_or_writes_the_new_one(tmp_path, monkeypatch, capsys):
    """``correct --overwrite`` with the disk full after a random number of bytes (20 trials, from
    none to more than the new pair needs; ``CCJAX_DISK_TRIALS`` for more): every time the output
    and its preview are the previous pair (exit 2, the error names a file) or the new one (exit 0),
    one run identifier for both, and no temporary is left."""
    import builtins
    import io as python_io

    _photo(tmp_path / "a.png", 0)
    argv = ["correct", str(tmp_path / "a.png"), str(tmp_path / "out.tif"), "--method", "GW", "--no-progress"]
    assert cli.main(argv) == 0
    pair = (tmp_path / "out.tif", tmp_path / "out_tif_preview.png")
    size = sum(path.stat().st_size for path in pair)
    real_open = builtins.open
    budget = [0]

    class FullDisk(python_io.FileIO):
        def write(self, data):  # the device fills up after budget[0] more bytes
            count = min(len(data), budget[0])
            if count == 0 and len(data):
                raise OSError(28, "No space left on device")
            budget[0] -= count
            return super().write(memoryview(data)[:count])

    def opened(file, mode="r", *args, **kwargs):
        if "w" in mode and "b" in mode and os.path.basename(str(file)).startswith(".out"):
            return python_io.BufferedWriter(FullDisk(file, "w"))
        return real_open(file, mode, *args, **kwargs)

    monkeypatch.setattr(builtins, "open", opened)
    rng = random.Random(4)
    outcomes = []
    for trial in range(int(os.environ.get("CCJAX_DISK_TRIALS", "20"))):
        previous = io.file_run(pair[0])
        assert previous is not None and io.file_run(pair[1]) == previous
        _photo(tmp_path / "a.png", 10 + trial)  # another photograph: another pair
        budget[0] = rng.randrange(0, int(size * 1.3))
        status = cli.main([*argv, "--overwrite"])
        err = capsys.readouterr().err
        now = io.file_run(pair[0])
        assert now is not None and io.file_run(pair[1]) == now, (trial, budget, err)
        if status == 0:
            assert now != previous, trial
        else:
            assert status == 2 and now == previous and "No space left on device" in err, (trial, status, err)
        assert not [p.name for p in tmp_path.iterdir() if p.name.startswith(".")], trial
        outcomes.append(status)
    assert 0 in outcomes and 2 in outcomes  # the budgets reached both ends


@pytest.mark.slow  # about 45 s on 2 shared cores: interrupted corrections of a 6 MP image
def test_interrupted_overwrites_leave_a_whole_pair_old_or_new(tmp_path):
    """``correct --overwrite`` of a 6 MP image stopped by SIGINT or SIGTERM at random times across
    the whole run: every time, the output and its preview are the previous pair or the new one
    (the same run identifier), never one of each or one missing, and no temporary is left."""
    rng = np.random.default_rng(5)
    codes = np.round(rng.uniform(0.05, 0.6, (2000, 3000, 3)) * [1.0, 0.7, 0.4] * 65535).astype(np.uint16)
    io.write_png(tmp_path / "big.png", codes)
    del codes
    out, preview = tmp_path / "out.tif", tmp_path / "out_tif_preview.png"
    command = [sys.executable, "-m", "ccjax", "correct", str(tmp_path / "big.png"), str(out), "--method", "GW"]
    env = dict(os.environ, CCJAX_CACHE=str(tmp_path / "cache"))
    started = time.perf_counter()
    assert subprocess.run([*command, "--no-progress"], env=env, capture_output=True).returncode == 0
    whole = time.perf_counter() - started
    timing = random.Random(2)
    for trial in range(int(os.environ.get("CCJAX_PAIR_TRIALS", "3"))):  # 100 for the full check
        previous = io.file_run(out)
        assert previous is not None and io.file_run(preview) == previous
        process = subprocess.Popen(
            [*command, "--no-progress", "--overwrite"], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE
        )
        time.sleep(timing.uniform(0.2, 1.2) * whole)
        process.send_signal(signal.SIGINT if trial % 2 == 0 else signal.SIGTERM)
        process.communicate(timeout=300)
        assert process.returncode in (0, 130, 143), process.returncode
        now = io.file_run(out)
        assert now is not None and io.file_run(preview) == now, (trial, previous, now)
        assert not [p.name for p in tmp_path.iterdir() if p.name.startswith(".")], trial


def test_two_writers_of_one_pair_put_their_files_in_place_one_after_the_other(tmp_path, monkeypatch):
    """Two ``correct --overwrite`` runs of one output interleaved their renames (the image of one
    beside the preview of the other in 2 of 3 trials). Here writer A puts its first file in place
    and then waits up to 0.3 s for writer B to put both of its files in place: unlocked, B would
    finish inside that wait and A's second file would land beside B's first; the pair's folder is
    locked while a pair is put in place, so B waits for A and the pair is B's whole."""
    import threading

    from ccjax import _cache

    pair = [tmp_path / "out.tif", tmp_path / "out_tif_preview.png"]
    first_in_place, second_done = threading.Event(), threading.Event()
    real = _cache.put_in_place

    def put_in_place(temporary, path, *, overwrite):
        real(temporary, path, overwrite=overwrite)
        writer = threading.current_thread().name
        if writer == "A" and path == pair[0]:
            first_in_place.set()
            second_done.wait(0.3)
        if writer == "B" and path == pair[1]:
            second_done.set()

    monkeypatch.setattr(_cache, "put_in_place", put_in_place)

    def write(name):
        if name == "B":
            first_in_place.wait(5)
        _cache.atomic_write_files({path: name.encode() for path in pair})

    threads = [threading.Thread(target=write, args=(name,), name=name) for name in "AB"]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(10)
    assert [path.read_bytes() for path in pair] == [b"B", b"B"]
    assert not [p.name for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_a_model_beside_another_runs_record_is_refused(tmp_path):
    """Two trainings write ``m.eqx`` and its record; the record of one beside the model of the
    other (a concurrent writer, or files copied apart) is refused when read, naming both files, as
    is an edited model file; each whole pair loads."""
    import equinox as eqx
    import jax.numpy as jnp

    from ccjax.runs import store

    world = store.world()
    first = store.fit("grey-edge-1-6-2", world)
    second = eqx.tree_at(lambda m: m.p, first, jnp.asarray(2.0, first.p.dtype))
    store.save_trained(tmp_path / "a.eqx", first, label="grey-edge-1-6-2", camera=None)
    store.save_trained(tmp_path / "b.eqx", second, label="grey-edge-1-6-2", camera=None)
    assert float(store.load_model(tmp_path / "b.eqx").p) == 2.0
    (tmp_path / "b.eqx").write_bytes((tmp_path / "a.eqx").read_bytes())  # the other run's model
    with pytest.raises(ValueError, match=r"b\.eqx is not the model its record .*b\.json describes"):
        store.load_model(tmp_path / "b.eqx")
    blob = bytearray((tmp_path / "a.eqx").read_bytes())
    blob[-1] ^= 1
    (tmp_path / "a.eqx").write_bytes(bytes(blob))
    with pytest.raises(ValueError, match="is not the model its record"):
        store.load_model(tmp_path / "a.eqx")
