"""docs/a-raw-file.md as pasted: its commands and its Python block run in order in one folder on a
stand-in raw photograph (``raw/IMG_0042.dng``, tests/dng_files.py) and a stand-in Cube+ folder,
then every file the page writes is opened and checked here: JPEGs upright at the sensor's full
size, tagged sRGB (ICC profile, EXIF ColorSpace 1), carrying the raw file's make and model with
Orientation 1, each with its preview (an sRGB PNG) of the same run; the grey card neutral in the
card-corrected image (its light was the card's)."""

from __future__ import annotations

import io as bytes_io
import os
import pathlib
import subprocess
import sys

import numpy as np
import page_blocks
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "a-raw-file.md"


@pytest.mark.slow  # about 40 s on 2 shared cores: three commands on a raw file and a training
def test_the_raw_file_page_runs_as_pasted_and_writes_what_it_says(tmp_path):
    pytest.importorskip("rawpy")
    from dng_files import GREY_CARD, photo_dng
    from PIL import Image, ImageCms

    from ccjax import io

    blocks = [block for block in page_blocks.page_blocks(PAGE.read_text()) if block.not_run is None]
    assert [block.kind for block in blocks] == ["shell", "shell", "shell", "python"]
    photo_dng(tmp_path / "raw" / "IMG_0042.dng")
    env = {k: v for k, v in os.environ.items() if k not in ("CCJAX_DATA", "CI")}
    env |= {"CCJAX_CACHE": str(tmp_path / "cache"), "MPLBACKEND": "Agg"}
    env["PATH"] = os.pathsep.join([str(pathlib.Path(sys.executable).parent), env.get("PATH", "")])
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), str(ROOT / "tests"), env.get("PYTHONPATH", "")])
    stand_ins = "from page_blocks import write_stand_in_sets; write_stand_in_sets(['cube_plus'])"
    subprocess.run([sys.executable, "-c", stand_ins], cwd=tmp_path, env=env, check=True)
    for block in blocks:
        command = ["bash", "-e", "-o", "pipefail", "-c", block.code] if block.kind == "shell" else None
        command = command or [sys.executable, "-c", block.code]
        run = subprocess.run(command, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
        assert run.returncode == 0, (block.line, run.stderr[-2000:])
    for name in ("IMG_0042-card", "IMG_0042-model"):
        jpeg_path, preview_path = tmp_path / "out" / f"{name}.jpg", tmp_path / "out" / f"{name}_jpg_preview.png"
        with Image.open(jpeg_path) as jpeg:
            assert jpeg.format == "JPEG" and jpeg.size == (128, 192)  # the 128 x 192 sensor, turned upright
            exif = jpeg.getexif()
            assert exif.get(0x0112) == 1 and exif.get(0x010F) == "Canon" and exif.get(0x0110) == "Canon EOS 5D Mark II"
            assert exif.get_ifd(0x8769).get(0xA001) == 1  # ColorSpace: sRGB
            profile = ImageCms.ImageCmsProfile(bytes_io.BytesIO(jpeg.info["icc_profile"]))
            assert "sRGB" in ImageCms.getProfileDescription(profile)
            pixels = np.asarray(jpeg, np.float64)
        blob = preview_path.read_bytes()
        assert blob[:8] == b"\x89PNG\r\n\x1a\n" and b"sRGB" in blob[: blob.index(b"IDAT")]
        assert io.file_run(jpeg_path) is not None and io.file_run(jpeg_path) == io.file_run(preview_path)
        if name == "IMG_0042-card":
            # The card at full size: the half-size rectangle doubled, 4 pixels in from its edges.
            x, y, width, height = (2 * value for value in GREY_CARD)
            card = pixels[y + 4 : y + height - 4, x + 4 : x + width - 4].reshape(-1, 3).mean(axis=0)
            assert np.ptp(card) <= 2, card
