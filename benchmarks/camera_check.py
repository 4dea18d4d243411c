"""How well does the camera check (``ccjax cameras --check``) tell cameras apart? Same-camera
failures and the share of pairs of different cameras it flags, on the 52 embedded cameras.

For every camera A, ground truths are rendered through A's own curves (the white of A under
each light) for three families of lights:

* ``world``: the default world's lights (training and test sets of ``World.default(A)``, seed 0:
  daylight, blackbody, CIE and LED lamps, fluorescents and random mixtures filling (r,g) cells);
* ``world-7``: the test set of the seed-7 world (other random mixtures);
* ``planckian``: 50 CIE daylights at 4000-12000 K and 50 blackbodies at 2500-7000 K, temperatures
  drawn at random (seed 0), the lights most photographs are taken under.

Each family's truths of A are checked (:func:`ccjax.experiments.curve_check`, its default
statistic and threshold) against every camera B's default world. A same-camera failure
(A = B, the check fails) is an error of the check; a flagged pair of different cameras (A != B,
the check fails) is what the check is for. The script prints, per family, the same-camera
failures, the largest same-camera statistic, the share of the 2,652 ordered pairs of different
cameras flagged and the statistic's quartiles over those pairs, then the share flagged in every
family and in any.

``--truth GT.csv=CAMERA`` (repeatable) also checks a ground-truth CSV (header image,r,g,b)
against its camera and a few others, and names the cameras whose curves it fits best.

It measures whichever ccjax is imported: run it on two checkouts (``PYTHONPATH=...``) to compare
two versions of the check.

Usage: ``python benchmarks/camera_check.py [--truth GT.csv=CAMERA ...] [--against CAMERA ...]``
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from ccjax import data, io
from ccjax.experiments import curve_check
from ccjax.spectra import blackbody, cie_daylight
from ccjax.world import World

DEFAULT_AGAINST = ("Canon EOS 600D", "Canon EOS-1Ds Mark III", "Nikon D5300", "Sony ILCE-7M3")


def planckian_lights(seed: int = 0) -> np.ndarray:
    """``(100, 101)`` 50 CIE daylights (4000-12000 K) and 50 blackbodies (2500-7000 K) at random temperatures."""
    rng = np.random.default_rng(seed)
    return np.concatenate([cie_daylight(rng.uniform(4000, 12000, 50)), blackbody(rng.uniform(2500, 7000, 50))])


def rendered_truths(names: list[str]) -> tuple[dict[str, dict[str, np.ndarray]], dict[str, World]]:
    """Each camera's truths per family, and its default world (the check's reference)."""
    planckian = planckian_lights()
    truths, worlds = {}, {}
    for name in names:
        world, other = World.default(name), World.default(name, seed=7)
        sensors = np.asarray(world.camera.sensors, np.float64)
        lights = np.concatenate([np.asarray(world.train_illuminants), np.asarray(world.test_illuminants)])
        truths[name] = {
            "world": lights.astype(np.float64) @ sensors,
            "world-7": np.asarray(other.test_illuminants, np.float64) @ sensors,
            "planckian": planckian @ sensors,
        }
        worlds[name] = world
    return truths, worlds


def pair_statistics(truths, worlds, family: str) -> tuple[np.ndarray, np.ndarray, float]:
    """``(A, B)`` the check's statistic and verdict for A's truths against B's world, and its threshold."""
    names = list(worlds)
    distance = np.zeros((len(names), len(names)))
    failed = np.zeros((len(names), len(names)), bool)
    threshold = float("nan")
    for i, a in enumerate(names):
        for j, b in enumerate(names):
            check = curve_check(truths[a][family], worlds[b])
            distance[i, j], failed[i, j], threshold = check.distance, not check.passed, check.threshold
    return distance, failed, threshold


def report_family(family: str, distance: np.ndarray, failed: np.ndarray, threshold: float) -> np.ndarray:
    """Print one family's figures; return the flags of the pairs of different cameras."""
    count = len(distance)
    other = ~np.eye(count, dtype=bool)
    same = np.diag(distance)
    quartiles = np.quantile(distance[other], [0.25, 0.5, 0.75])
    print(
        f"{family:<10} same-camera failures {int(np.diag(failed).sum())}/{count} "
        f"(largest statistic {same.max():.4f}, threshold {threshold:.4f}); "
        f"different cameras flagged {int(failed[other].sum())}/{int(other.sum())} = {100 * failed[other].mean():.1f} % "
        f"(statistic quartiles {quartiles[0]:.4f} / {quartiles[1]:.4f} / {quartiles[2]:.4f})"
    )
    return failed[other]


def check_truth(spec: str, against: list[str], worlds: dict[str, World]) -> None:
    """Check one ground-truth CSV against its camera, the ``against`` cameras and rank all cameras."""
    path, _, camera = spec.partition("=")
    if not camera:
        raise SystemExit(f"--truth: expected GT.csv=CAMERA, got {spec!r}")
    truth = np.stack(list(io.read_ground_truth(path).values()))
    checks = {name: curve_check(truth, world) for name, world in worlds.items()}
    for name in dict.fromkeys([camera, *against]):
        check = checks[name]
        role = "own" if name == camera else "other"
        verdict = "passes" if check.passed else "FLAGGED"
        print(f"  {path} ({len(truth)} images, {camera}) vs {name} [{role}]: {check.distance:.4f} {verdict}")
    best = ", ".join(f"{n} {checks[n].distance:.4f}" for n in sorted(checks, key=lambda n: checks[n].distance)[:5])
    passed = sum(check.passed for check in checks.values())
    print(f"    best fits: {best}; passes {passed}/{len(checks)} cameras")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--truth", action="append", default=[], metavar="GT.csv=CAMERA")
    parser.add_argument("--against", nargs="*", default=list(DEFAULT_AGAINST), metavar="CAMERA")
    args = parser.parse_args()
    start = time.perf_counter()
    names = sorted(data.rawtoaces_cameras())
    truths, worlds = rendered_truths(names)
    print(f"{len(names)} embedded cameras, {len(names) * (len(names) - 1)} ordered pairs of different cameras")
    flags = [report_family(family, *pair_statistics(truths, worlds, family)) for family in truths[names[0]]]
    every, some = np.logical_and.reduce(flags), np.logical_or.reduce(flags)
    print(f"flagged in every family {100 * every.mean():.1f} %, in at least one {100 * some.mean():.1f} %")
    for spec in args.truth:
        check_truth(spec, args.against, worlds)
    print(f"({time.perf_counter() - start:.0f} s)")


if __name__ == "__main__":
    main()
