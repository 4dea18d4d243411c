"""How right is ``ccjax evaluate``'s progress-bar ETA?

Writes 500 synthetic 48x64 16-bit Mondrians of the Canon EOS 5D Mark II (shot noise, highlights on
half the patches) with their ground truth, runs ``ccjax evaluate`` on them with its progress bar,
timestamps every bar update and prints the ETA the bar showed after 5, 10, 20 and 50 % of the
images against the real remaining time of the bar.

Usage: ``python benchmarks/evaluate_eta.py [FOLDER] [METHODS]`` (default: a temporary folder;
GW, shades-of-grey-p6, grey-edge-1-6-2, DB-GW, ECRULE-MV). Takes several minutes.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import jax

from ccjax import io, scenes
from ccjax.world import World

IMAGES = 500
BAR = re.compile(rb"images:\s+\d+%\|.*\|\s*(\d+)/(\d+) \[([\d:]+)<([\d:?]+)")


def write_images(folder: Path) -> Path:
    """The 500 images and their ground truth in ``folder``; returns the CSV."""
    world = World.default("Canon EOS 5D Mark II")
    batch = scenes.sample_mondrians(
        jax.random.key(5),
        world,
        IMAGES,
        height=48,
        width=64,
        n_patches=10,
        noise=scenes.ShotNoise(a=1e-4, b=0.0),
        specular=scenes.Specular(probability=0.5, max_amount=1.5),
    )
    return io.write_dataset(folder, batch.image, batch.illuminant)


def seconds(text: str) -> float:
    """``"1:02:03"`` or ``"02:03"`` -> seconds (``nan`` for tqdm's ``"?"``)."""
    if "?" in text:
        return float("nan")
    return float(sum(int(part) * 60**index for index, part in enumerate(reversed(text.split(":")))))


def main(argv: list[str]) -> int:
    """Write the images, run the command, print the ETA table.

    Arguments:
        argv: ``[FOLDER] [METHODS]``.

    Returns:
        The exit status (the command's).
    """
    folder = Path(argv[0]) if argv else Path(tempfile.mkdtemp(prefix="ccjax-eta-"))
    methods = argv[1] if len(argv) > 1 else "GW,shades-of-grey-p6,grey-edge-1-6-2,DB-GW,ECRULE-MV"
    ground_truth = folder / "groundtruth.csv"
    if not ground_truth.is_file():
        write_images(folder)
    command = ["ccjax", "evaluate", str(folder), "--ground-truth", str(ground_truth), "--methods", methods]
    command += ["--camera", "Canon EOS 5D Mark II"]
    started = time.time()
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=dict(os.environ))
    assert process.stderr is not None and process.stdout is not None
    updates, pending = [], b""
    while chunk := os.read(process.stderr.fileno(), 4096):
        *lines, pending = re.split(rb"[\r\n]", pending + chunk)
        now = time.time()
        updates += [(now, int(m[1]), m[4].decode()) for m in map(BAR.search, lines) if m]
    print(process.stdout.read().decode())
    code = process.wait()
    end = max(moment for moment, count, _ in updates if count == IMAGES)
    print(f"command {time.time() - started:.1f} s; bar {end - updates[0][0]:.1f} s")
    for share in (0.05, 0.10, 0.20, 0.50):
        moment, count, eta = next(update for update in updates if update[1] >= share * IMAGES)
        real = end - moment
        print(
            f"after {count}/{IMAGES}: ETA shown {seconds(eta):.0f} s, real remaining {real:.1f} s, "
            f"ratio {seconds(eta) / real:.2f}"
        )
    return code


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
