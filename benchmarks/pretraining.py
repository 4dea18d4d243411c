"""The pretraining curve on a photo set: FFCC (or another trainable label) trained on 10, 25, 50
and 100 % of each training fold (3 random subsets at 10 and 25 %), from scratch and fine-tuned
from its pretraining on images rendered with a camera's spectral curves
(:func:`ccjax.experiments.pretraining.pretraining_curve`), 3-fold, mean and median angular error.

Run::

    python benchmarks/pretraining.py /work/photosets/nus8-Canon600D --camera "Canon EOS 600D" --saturation 64224
    python benchmarks/pretraining.py /work/photosets/cube_plus --camera "Canon EOS 600D" --saturation 64224

(Cube+ was taken with a Canon 550D; the 600D's curves stand in for it.) The rendered set is
cached (``$CCJAX_CACHE/pretraining``).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from ccjax.experiments.pretraining import pretraining_curve
from ccjax.training import Pretraining


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("directory", help="photo folder with groundtruth.csv")
    parser.add_argument("--camera", required=True, help="embedded camera whose curves render the pretraining set")
    parser.add_argument("--method", default="FFCC", help="trainable label (default FFCC)")
    parser.add_argument("--saturation", type=float, default=None, help="saturation level in file units")
    parser.add_argument("--images", type=int, default=2000, help="rendered pretraining images (default 2000)")
    parser.add_argument("--fractions", default="0.1,0.25,0.5,1", help="shares of each training fold")
    parser.add_argument("--subsets", type=int, default=3, help="random subsets per share below 1 (default 3)")
    parser.add_argument("--folds", type=int, default=3)
    parser.add_argument("--json", default=None, help="write the summary rows as JSON")
    args = parser.parse_args()
    directory = Path(args.directory)
    options = {} if args.saturation is None else {"saturation": args.saturation}
    curve = pretraining_curve(
        directory,
        directory / "groundtruth.csv",
        Pretraining(args.camera, images=args.images),
        method=args.method,
        fractions=[float(f) for f in args.fractions.split(",")],
        subsets=args.subsets,
        folds=args.folds,
        read_options=options,
        log=lambda line: print(time.strftime("%H:%M:%S"), line, flush=True),
    )
    print(curve.table())
    if args.json:
        Path(args.json).write_text(json.dumps(curve.summary(), indent=1))


if __name__ == "__main__":
    main()
