"""White balance for a camera without labelled photographs: train on another camera's labelled
images mapped through the two cameras' spectral curves, score on the camera itself.

Two folders of synthetic labelled images are rendered by ccjax (:func:`ccjax.training.render_images`:
Mondrians of the embedded SFU reflectances under lights near each camera's Planckian locus,
highlights, shot noise, clipping, 16-bit PNGs with ``groundtruth.csv``), one through the Canon EOS
600D's curves and one through the Nikon D5300's. Then, as a user would on real folders:

1. ``ccjax evaluate A B --camera-for A=... --camera-for B=... --leave-one-camera-out --train METHOD``:
   each folder scored by a model trained only on the other folder, its images and ground truth
   mapped into the scored camera (:mod:`ccjax.transfer`), beside grey world and shades of grey
   (which need no training), then the geometric mean over the folders;
2. ``ccjax train A --camera-for A=... --target-camera "Nikon D5300" --out MODEL``: a model for the
   Nikon from the Canon's images alone, then ``ccjax evaluate B --methods MODEL`` scores it there.

Run: ``python examples/any_camera.py [--images 300] [--method FFCC] [--out DIR]``; ``--quick`` renders
40 images of 32 x 32 per camera and trains grey edge's Minkowski norm (a smoke test, seconds).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

from ccjax import cli, io, training

CAMERAS = {"canon": "Canon EOS 600D", "nikon": "Nikon D5300"}


def render(folder: Path, camera: str, images: int, size: int, seed: int) -> None:
    """Render ``images`` labelled images through ``camera``'s curves into ``folder``."""
    setting = training.Pretraining(camera, images=images, height=size, width=size, seed=seed)
    rgb, _, lights = training.render_images(setting)
    io.write_dataset(folder, np.asarray(rgb), np.asarray(lights))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--images", type=int, default=300, help="images per camera (default 300)")
    parser.add_argument("--method", default="FFCC", help="the trained method (default FFCC)")
    parser.add_argument("--out", default=None, help="keep the folders and the model here (default: a temp dir)")
    parser.add_argument("--quick", action="store_true", help="40 images of 32 x 32 per camera, grey edge trained")
    args = parser.parse_args(argv)
    images, size, method = (40, 32, "grey-edge-1-6-2") if args.quick else (args.images, 64, args.method)
    with tempfile.TemporaryDirectory() as temporary:
        root = Path(args.out or temporary)
        folders = {name: root / name for name in CAMERAS}
        for seed, (name, camera) in enumerate(CAMERAS.items()):
            render(folders[name], camera, images, size, seed)
        print(f"rendered {images} images of {size} x {size} through each camera's curves under {root}")
        camera_for = [f"--camera-for={folders[name]}={camera}" for name, camera in CAMERAS.items()]
        common = ["--ground-truth-name", "groundtruth.csv", "--no-progress"]
        status = cli.main(
            ["evaluate", *map(str, folders.values()), *camera_for, *common, "--leave-one-camera-out"]
            + ["--train", method, "--methods", "GW,shades-of-grey-p6"]
        )
        if status:
            return status
        model = root / "for-nikon.eqx"
        status = cli.main(
            ["train", str(folders["canon"]), camera_for[0], "--target-camera", CAMERAS["nikon"], "--method", method]
            + ["--out", str(model), "--overwrite", "--no-progress"]
        )
        if status:
            return status
        return cli.main(
            ["evaluate", str(folders["nikon"]), "--ground-truth-name", "groundtruth.csv", "--no-progress"]
            + ["--camera", CAMERAS["nikon"], "--methods", f"{model},shades-of-grey-p6"]
        )


if __name__ == "__main__":
    sys.exit(main())
