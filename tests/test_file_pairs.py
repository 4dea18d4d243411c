"""A model file and its record are one pair: on a full disk (or any failure) while either is
written, neither appears, so a rerun is not blocked by an orphan that cannot be loaded."""

from __future__ import annotations

import builtins
import errno
import json

import pytest

from ccjax import _cache
from ccjax.runs import store


class _FullDisk:
    """``open`` for the cache module whose files named ``.<name>.*`` fail to write (ENOSPC)."""

    def __init__(self, name: str):
        self.name = name

    def __call__(self, file, mode="r", *args, **kwargs):
        handle = builtins.open(file, mode, *args, **kwargs)
        if "w" in mode and str(file).rsplit("/", 1)[-1].startswith(f".{self.name}."):
            handle.close()
            raise OSError(errno.ENOSPC, "No space left on device")
        return handle


@pytest.fixture
def model(small_test_world):
    return store.fit("GW", small_test_world)


@pytest.mark.parametrize("failing", ["model.eqx", "model.json"])
def test_a_full_disk_leaves_neither_file_and_the_rerun_writes_the_pair(tmp_path, monkeypatch, model, failing):
    monkeypatch.setattr(_cache, "open", _FullDisk(failing), raising=False)
    with pytest.raises(OSError, match="No space left"):
        store.save_trained(tmp_path / "model.eqx", model, label="GW", camera="Canon EOS 600D", overwrite=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # no orphan, no temporary
    monkeypatch.undo()
    store.save_trained(tmp_path / "model.eqx", model, label="GW", camera="Canon EOS 600D", overwrite=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["model.eqx", "model.json"]
    assert json.loads((tmp_path / "model.json").read_text())["label"] == "GW"
    assert _cache.read_model_metadata(tmp_path / "model.eqx")["camera"] == "Canon EOS 600D"


def test_a_model_that_appears_meanwhile_takes_its_record_back(tmp_path, monkeypatch, model):
    real = _cache.put_in_place

    def appearing(temporary, path, *, overwrite):
        if str(path).endswith(".eqx"):
            (tmp_path / "model.eqx").write_bytes(b"someone else's")
        return real(temporary, path, overwrite=overwrite)

    monkeypatch.setattr(_cache, "put_in_place", appearing)
    with pytest.raises(FileExistsError):
        store.save_trained(tmp_path / "model.eqx", model, label="GW", camera="Canon EOS 600D", overwrite=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["model.eqx"]
    assert (tmp_path / "model.eqx").read_bytes() == b"someone else's"


def test_an_existing_half_of_the_pair_is_named_before_anything_is_written(tmp_path, model):
    (tmp_path / "model.json").write_text("{}")
    with pytest.raises(FileExistsError, match=r"model\.json"):
        store.save_trained(tmp_path / "model.eqx", model, label="GW", camera="Canon EOS 600D", overwrite=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["model.json"]
