"""Benchmark: how far a labelled folder's lights lie from a camera's Planckian and daylight loci.

A pool of other cameras' photographs trained for a target camera could keep only the training
lights near the target's loci (within 0.2 log-chroma, say). This prints, for each folder, the
distance of each ground-truth light from the nearest point of the camera's loci (blackbodies
1500-15000 K in 50 K steps and CIE daylights 4000-25000 K in 250 K steps through its curves),
in FFCC's log-chroma ``(log g/r, log g/b)``: quantiles and the fraction beyond 0.1 and 0.2, which
is the share of the folder such a filter would drop. The lights are the folder's own camera's, so
each folder is measured against its own camera's loci (the maps between cameras preserve the
whites of locus lights).

Usage: python benchmarks/locus_distance.py FOLDER=CAMERA [FOLDER=CAMERA ...]
       [--ground-truth-name groundtruth.csv]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from ccjax.camera import Camera
from ccjax.estimators.neural import log_chroma
from ccjax.io.ground_truth import read_ground_truth
from ccjax.transfer import locus_lights

QUANTILES = (0.5, 0.75, 0.9, 0.95, 0.99, 1.0)


def locus_distances(lights: np.ndarray, camera: Camera) -> np.ndarray:
    """Each light's log-chroma distance to the nearest point of ``camera``'s dense loci.

    Arguments:
        lights: ``(N, 3)`` camera RGB of the lights.
        camera: the camera whose loci are measured against.

    Returns:
        ``(N,)`` distances.
    """
    spectra = locus_lights(np.arange(1500.0, 15001.0, 50.0), np.arange(4000.0, 25001.0, 250.0))
    loci = np.asarray(log_chroma(jnp.asarray(spectra @ np.asarray(camera.sensors, np.float64), jnp.float32)))
    uv = np.asarray(log_chroma(jnp.asarray(lights, jnp.float32)))
    return np.min(np.linalg.norm(uv[:, None, :] - loci[None, :, :], axis=-1), axis=1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folders", nargs="+", metavar="FOLDER=CAMERA")
    parser.add_argument("--ground-truth-name", default="groundtruth.csv")
    args = parser.parse_args()
    header = " | ".join(f"q{q:g}" for q in QUANTILES)
    print(f"| folder (camera) | lights | {header} | beyond 0.1 | beyond 0.2 |")
    print("|---|---|" + "---|" * len(QUANTILES) + "---|---|")
    for item in args.folders:
        folder, _, name = item.partition("=")
        if not name:
            raise SystemExit(f"folders: expected FOLDER=CAMERA, got {item!r}")
        lights = np.stack(list(read_ground_truth(Path(folder) / args.ground_truth_name).values()))
        distance = locus_distances(lights, Camera.from_name(name))
        cells = " | ".join(f"{q:.3f}" for q in np.quantile(distance, QUANTILES))
        beyond = [f"{100 * np.mean(distance > limit):.1f} %" for limit in (0.1, 0.2)]
        print(f"| {Path(folder).name} ({name}) | {len(distance)} | {cells} | {beyond[0]} | {beyond[1]} |")


if __name__ == "__main__":
    main()
