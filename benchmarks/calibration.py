"""Benchmark: chapter-3 sensor fitting (ccjax.calibration) against the SciPy reference.

Prints, with compiled (warm) functions on this machine:
* one camera — 3 x 101 sensor unknowns plus F's a0, a1, about 612 measurements (the thesis'
  experiment) — with ccjax.calibration.fit_sensors (jaxopt ProjectedGradient + polish, vmapped over channels)
  and with the SciPy oracle (lsq_linear, two passes per channel, as in tests/calibration_oracle.py);
* 100 cameras (synthetic experiments for the embedded/external cameras, cycled, each with its own
  noise) as ONE vmapped batch with ccjax.calibration.fit_sensors_batch;
* peak resident memory.

Usage: python benchmarks/calibration.py [--cameras 100] [--repeats 5]
"""

from __future__ import annotations

import argparse
import pathlib
import resource
import sys
import time

import jax
import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests"))

import calibration_oracle as oracle

from ccjax import calibration as cal
from ccjax.camera import cameras

F = dict(black=10.0, exp_rate=0.15)


def _timed(fn, repeats):
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        out = fn()
        jax.block_until_ready(out)
        times.append(time.perf_counter() - start)
    return out, float(np.median(times)), float(np.min(times))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cameras", type=int, default=100)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()

    names = list(cameras())
    first = "Sony DXC-930" if "Sony DXC-930" in names else names[0]
    data = cal.synthetic_calibration(first)
    print(f"jax {jax.__version__}, backend {jax.default_backend()}, devices {jax.device_count()}")
    print(f"one camera: {first}, {data.n_usable} measurements, 3 x 101 sensor unknowns + a0, a1 per channel")

    def one():
        return cal.fit_sensors(data.spectra, data.raw, linearisation="exp", mask=data.usable, **F).sensors

    start = time.perf_counter()
    jax.block_until_ready(one())
    print(f"  first call (compile + fit): {time.perf_counter() - start:.2f} s")
    sensors, median, best = _timed(one, args.repeats)
    print(f"  ccjax fit_sensors after compilation: median {median:.3f} s, best {best:.3f} s over {args.repeats} runs")
    print(f"  curve error vs truth (% of peak): {np.round(100 * cal.curve_error(sensors, data.sensors), 2).tolist()}")

    L, raw = data.usable_data()
    start = time.perf_counter()
    for k in range(3):
        oracle.fit_channel(L, raw[:, k], smoothness=cal.DEFAULT_SMOOTHNESS, **F)
    scipy_time = time.perf_counter() - start
    print(
        f"  SciPy reference (lsq_linear bvls, 2 passes x 3 channels): {scipy_time:.3f} s  "
        f"-> ratio scipy/ccjax {scipy_time / median:.1f}"
    )

    chosen = [names[i % len(names)] for i in range(args.cameras)]
    sets = [cal.synthetic_calibration(name, seed=i) for i, name in enumerate(chosen)]
    spectra = np.stack([s.spectra for s in sets])
    responses = np.stack([s.raw for s in sets])
    masks = np.stack([s.usable for s in sets])
    truth = np.stack([s.sensors for s in sets])
    print(
        f"{args.cameras} cameras ({len(set(chosen))} distinct curve sets, each with its own noise draw), "
        "one vmapped batch:"
    )

    def many():
        return cal.fit_sensors_batch(spectra, responses, mask=masks, chunk_size=args.cameras, linearisation="exp", **F)

    start = time.perf_counter()
    jax.block_until_ready(many())
    print(f"  first call (compile + fit): {time.perf_counter() - start:.2f} s")
    fits, median, best = _timed(many, max(1, args.repeats // 2))
    print(
        f"  ccjax fit_sensors_batch after compilation: median {median:.2f} s "
        f"({median / args.cameras * 1e3:.1f} ms per camera)"
    )
    errors = np.stack([cal.curve_error(fits.sensors[b], truth[b]) for b in range(args.cameras)])
    print(
        f"  curve error vs truth over the batch: median {100 * np.median(errors):.2f} %, "
        f"max {100 * errors.max():.2f} % of peak; "
        f"converged {100 * float(np.mean(np.asarray(fits.converged))):.0f} % of channels"
    )
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak resident memory: {peak:.0f} MB")


if __name__ == "__main__":
    main()
