"""A plot drawn from the same values is written from the disk cache (no second drawing), any
change of what it is drawn from draws it again, and a damaged stored PNG is drawn again."""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest

from ccjax._entries import CacheEntryRejected
from ccjax.cli.common import write_plot


class Drawing:
    """A stand-in for a figure's ``savefig``: counts its calls and writes distinct bytes each time."""

    def __init__(self):
        self.calls = 0

    def __call__(self, file):
        self.calls += 1
        file.write(b"\x89PNG fake " + bytes([self.calls]) * 64)


@pytest.fixture
def cache(tmp_path, monkeypatch) -> Path:
    monkeypatch.setenv("CCJAX_CACHE", str(tmp_path / "cache"))
    return tmp_path / "cache"


def test_the_same_values_write_the_stored_png_without_drawing(tmp_path, cache):
    draw = Drawing()
    parts = ("compare", "title", ["GW"], [4, 8], [[[0.1, 0.2]]])
    write_plot(tmp_path / "a.png", draw, overwrite=False, drawn_from=parts)
    write_plot(tmp_path / "b.png", draw, overwrite=False, drawn_from=parts)
    assert draw.calls == 1
    assert (tmp_path / "a.png").read_bytes() == (tmp_path / "b.png").read_bytes()
    # One value in the last place, a label or the title: another figure.
    for changed in (
        ("compare", "title", ["GW"], [4, 8], [[[0.1, 0.2000001]]]),
        ("compare", "title", ["DB-GW"], [4, 8], [[[0.1, 0.2]]]),
        ("compare", "other title", ["GW"], [4, 8], [[[0.1, 0.2]]]),
    ):
        calls = draw.calls
        write_plot(tmp_path / "c.png", draw, overwrite=True, drawn_from=changed)
        assert draw.calls == calls + 1
        assert (tmp_path / "c.png").read_bytes() != (tmp_path / "a.png").read_bytes()


def test_without_parts_every_plot_is_drawn(tmp_path, cache):
    draw = Drawing()
    write_plot(tmp_path / "a.png", draw, overwrite=False)
    write_plot(tmp_path / "a.png", draw, overwrite=True)
    assert draw.calls == 2
    assert not (cache / "plots").exists()


def test_a_damaged_stored_png_is_drawn_again(tmp_path, cache):
    draw = Drawing()
    parts = ("compare", "title", ["GW"], [4], [[[0.1]]])
    write_plot(tmp_path / "a.png", draw, overwrite=False, drawn_from=parts)
    entries = [path for path in (cache / "plots").rglob("*") if path.is_file()]
    assert entries
    for entry in entries:
        data = bytearray(entry.read_bytes())
        data[len(data) // 2] ^= 0xFF
        entry.write_bytes(bytes(data))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        write_plot(tmp_path / "b.png", draw, overwrite=False, drawn_from=parts)
    assert draw.calls == 2
    assert (tmp_path / "b.png").read_bytes() != (tmp_path / "a.png").read_bytes()
    assert any(issubclass(w.category, CacheEntryRejected) for w in caught)
