"""The photographer's session of docs/photographer-session.md: a folder of photographs estimated,
FFCC trained on it, a new photograph corrected with the model to JPEG and to 16-bit PNG, and a
held-out folder evaluated, each command run as a user types it (``python -m ccjax ...`` in a fresh
process) and its output written down as printed.

The photographs are synthetic, rendered here from spectra with the embedded default world (so the
page needs no download): 16-bit PNG Mondrians with highlights and shot noise, under a warm cast,
each with one clipped patch, and their ``groundtruth.csv``.

Run::

    python docs/scripts/photographer.py [--out docs/photographer-session.md] [--workdir DIR]

Times are printed as measured; :func:`masked` replaces them with ``<t>``, so that a rerun can be
compared with the committed page (``tests/test_photographer_session.py``).
"""

from __future__ import annotations

import argparse
import os
import pathlib
import re
import subprocess
import sys
import tempfile

DOCS = pathlib.Path(__file__).resolve().parents[1]
PAGE = DOCS / "photographer-session.md"

COMMANDS = [
    (
        "Estimate the light of every photograph of a folder (grey world needs no camera curves):",
        "ccjax estimate photos/ --method shades-of-grey-p6 --no-progress",
    ),
    (
        "Train FFCC on the folder and its ground truth, and save the model:",
        "ccjax train photos/ --ground-truth photos/groundtruth.csv --method FFCC --out ffcc.eqx --no-progress",
    ),
    (
        "Estimate a new photograph with the model:",
        "ccjax estimate new-photos/IMG_0001.png --model ffcc.eqx --no-progress",
    ),
    (
        "Correct it with the model, as an 8-bit sRGB JPEG for viewing:",
        "ccjax correct new-photos/IMG_0001.png corrected/IMG_0001.jpg --model ffcc.eqx --srgb 8 --no-progress",
    ),
    (
        "and as linear 16-bit camera RGB under the canonical light, for further processing:",
        "ccjax correct new-photos/IMG_0001.png corrected/IMG_0001.png --model ffcc.eqx "
        "--preview corrected/IMG_0001_linear_preview.png --no-progress",
    ),
    (
        "Score methods on the held-out folder, whose ground truth is known:",
        "ccjax evaluate new-photos/ --ground-truth new-photos/groundtruth.csv "
        "--methods GW,shades-of-grey-p6,grey-edge-1-6-2 --no-progress",
    ),
]
"""The session: what the user wants, and the command."""

TIME = re.compile(r"\d+(?:\.\d+)?(?= ?(?:s|ms|s/image|ms/image|s/fold)\b)")
TIMING_ROW = re.compile(r"^(\S+\s+\S+\s+)[\d.]+(\s+)[\d.]+(\s+)[\d.]+")


def masked(text: str) -> str:
    """``text`` with every time as ``<t>``: a number followed by ``s``, ``ms``, ``s/image``, ...,
    and the seconds, ms/image and warm-up columns of ``ccjax evaluate``'s timing table.

    Arguments:
        text: a transcript.

    Returns:
        The text with its times masked.
    """
    lines, timing = [], False
    for line in text.splitlines():
        if timing and TIMING_ROW.match(line):
            line = TIMING_ROW.sub(r"\1<t>\2<t>\3<t>", line)
        else:
            timing = "ms/image" in line and "seconds" in line
        # A masked time's width is not kept: right-aligned columns shift with the digits.
        lines.append(re.sub(r" +<t>", " <t>", TIME.sub("<t>", line)))
    return "\n".join(lines) + "\n"


def make_photographs(folder: pathlib.Path) -> None:
    """``photos/`` (24 photographs with ground truth) and ``new-photos/`` (6 more, the first as
    ``IMG_0001.png``) in ``folder``: Mondrians of the default world's surfaces under its lights,
    with highlights and shot noise, each with a clipped patch (a highlight at the sensor's limit)."""
    import jax
    import numpy as np

    from ccjax import World, io
    from ccjax.scenes import sample_mondrians

    world = World.default()
    for name, key, count in (("photos", 0, 24), ("new-photos", 1, 6)):
        images = sample_mondrians(jax.random.key(key), world, count, height=64, width=64, specular=True, noise=True)
        pixels = np.array(images.image)
        pixels[:, 8:14, 40:50] = 1.0  # a clipped highlight in every photograph
        target = folder / name
        io.write_dataset(target, pixels, images.illuminant)
    (folder / "new-photos" / "image-0000.png").rename(folder / "new-photos" / "IMG_0001.png")
    truth = folder / "new-photos" / "groundtruth.csv"
    truth.write_text(truth.read_text().replace("image-0000.png", "IMG_0001.png"))


def run_session(folder: pathlib.Path) -> str:
    """Run :data:`COMMANDS` in ``folder`` (each ``python -m ccjax`` in a fresh process, stdout and
    stderr as a terminal shows them) and write them down as Markdown.

    Arguments:
        folder: the working folder (with the photographs).

    Returns:
        The session's Markdown, times as measured.
    """
    env = dict(os.environ, CCJAX_CACHE=str(folder / "cache"), COLUMNS="100")
    env.pop("CCJAX_DATA", None)
    parts = []
    for words, command in COMMANDS:
        run = subprocess.run(
            [sys.executable, "-m", *command.split()],
            cwd=folder,
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            timeout=1800,
        )
        if run.returncode != 0:
            raise SystemExit(f"{command} exited {run.returncode}:\n{run.stdout}")
        parts.append(f"{words}\n\n```console\n$ {command}\n{run.stdout.rstrip()}\n```\n")
    return "\n".join(parts)


HEADER = """# A photographer's session

A session as a photographer runs it: estimate the light of a folder of photographs, train FFCC
on them, correct a new photograph with the trained model (to JPEG for viewing and to 16-bit PNG
for further processing), and score methods on photographs whose lights are known. Each command
was run as shown, in a fresh process; the output is as it printed (progress bars off).

The photographs are synthetic so that the page can be rerun anywhere: 16-bit PNG Mondrians
rendered from spectra with the embedded default world (SFU surfaces, the Canon EOS 5D Mark II,
CIE and measured lights), with highlights, shot noise and a clipped patch in each, with their
`groundtruth.csv` (`docs/scripts/photographer.py` makes them and writes this page;
`tests/test_photographer_session.py` reruns it and compares, times aside). On your own
photographs give `--black-level` and `--saturation` as your files need (see
[Training on your photographs](photographs.md)).

"""


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default=str(PAGE), help="the page to write (default: %(default)s)")
    parser.add_argument("--workdir", default=None, help="folder to work in (default: a temporary one)")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as scratch:
        folder = pathlib.Path(args.workdir or scratch)
        folder.mkdir(parents=True, exist_ok=True)
        make_photographs(folder)
        text = HEADER + run_session(folder)
    pathlib.Path(args.out).write_text(text)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
