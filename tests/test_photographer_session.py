"""docs/photographer-session.md is what the session prints: docs/scripts/photographer.py reruns it
on freshly rendered photographs and the page matches, times aside."""

from __future__ import annotations

import importlib.util
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]


def _script():
    spec = importlib.util.spec_from_file_location("photographer", ROOT / "docs" / "scripts" / "photographer.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_masking_hides_times_and_only_times():
    script = _script()
    text = (
        "FFCC: trained on 24 images (2 L-BFGS passes, final loss 0.05643) in 252.6 s\n"
        "method                  input           seconds  ms/image  warm-up s  not ok (why)\n"
        "GW                      pixels             0.06     10.56       1.84  0 (0.0%)\n"
        "\n"
        "GW                         3.281   2.510    2.802\n"
    )
    assert script.masked(text) == (
        "FFCC: trained on 24 images (2 L-BFGS passes, final loss 0.05643) in <t> s\n"
        "method                  input           seconds  ms/image  warm-up s  not ok (why)\n"
        "GW                      pixels <t> <t> <t>  0 (0.0%)\n"
        "\n"
        "GW                         3.281   2.510    2.802\n"
    )


@pytest.mark.manual  # six commands in fresh processes, FFCC trained once: about 85 s on 2 cores
def test_the_committed_session_is_what_the_commands_print(tmp_path):
    script = _script()
    out = tmp_path / "session.md"
    assert script.main(["--out", str(out), "--workdir", str(tmp_path / "work")]) == 0
    committed = (ROOT / "docs" / "photographer-session.md").read_text()
    assert script.masked(out.read_text()) == script.masked(committed)
