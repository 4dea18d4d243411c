"""Peak memory per item of every count the limits table bounds (``docs/limits.md``), measured.

Each bounded count is run at two sizes, each in a fresh Python process that does the work and
then prints its own peak resident memory (``VmHWM`` of ``/proc/self/status``; Linux). The sizes
are small, so the benchmark runs on a shared machine; the table extrapolates linearly:

- bytes per item: ``(peak(large) - peak(small)) / (large - small)``;
- projected peak at the limit: ``peak(small) + bytes per item * (limit - small)``.

The rows (``ccjax.limits`` names the limits):

- ``indexing objects``: :func:`ccjax.experiments.indexing.run_indexing` with ``ACTUAL`` and
  ``GW``, 20 lights, 64 x 64 images (both sizes fill whole blocks of database and query images:
  at least 128 objects; between smaller sizes the peak grows faster, then levels off); item: an object
  (:data:`~ccjax.limits.OBJECTS`). A surface-list method adds a compiled program per size class
  of its lists, a bounded cost that a two-point line would take for a per-object one.
- ``indexing size``: ``ACTUAL``, ``GW`` and ``CRULE-MV`` (a surface-list method: its working
  memory grows with the surfaces of an image) on 4 objects x 2 lights at two image sides; item:
  a pixel of one image (:data:`~ccjax.limits.INDEXING_SIZE` squared). The images go in blocks of
  ``BLOCK_PIXELS``, so the images held at once do not grow with the side; one image's working
  copies do.
- ``sample 64``, ``sample 64 all``, ``sample max all``: :func:`ccjax.sample` of 64-surface scenes
  without options and with every option (specular, noise, clip, metallic, fluorescent), and of
  scenes of every reflectance with every option; item: a surface held
  (:data:`~ccjax.limits.SAMPLE_SURFACES`).
- ``compare``: :func:`ccjax.experiments.sweep` of ``NOTHING`` and ``GW`` at 4 and 8 surfaces (no
  disk cache); item: one scene's results of one (method, surface count) cell
  (:data:`~ccjax.limits.SCENE_RESULTS`).
- ``rendered images``: :func:`ccjax.training.render_images` of 64 x 64 images for the Canon EOS
  600D; item: an image (:data:`~ccjax.limits.RENDERED_IMAGES`).

The fits and worlds come from the disk cache (``$CCJAX_CACHE``); a first run fills it, so run
twice when it is cold (its first peaks include the fitting).

Run: ``python benchmarks/limits.py [--rows indexing-objects,sample-64,...]``
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import textwrap
from dataclasses import dataclass

from ccjax import limits

PEAK = """
import re
print("peak", re.search(r"VmHWM:\\s*(\\d+) kB", open("/proc/self/status").read()).group(1))
"""
"""Appended to every child's code: its peak resident memory, in kB."""

INDEXING = """
import jax, ccjax
from ccjax.experiments import indexing
world = ccjax.World.default()
indexing.run_indexing(world, {methods}, jax.random.key(0), n_objects={objects},
                      n_lights={lights}, size={size})
"""

SAMPLE = """
import jax, ccjax
world = ccjax.World.default()
surfaces = {surfaces} or int(world.reflectances.shape[0])
options = dict(specular=True, noise=True, clip=0.9, metallic=True, fluorescent=True) if {options} else dict()
jax.block_until_ready(ccjax.sample(jax.random.key(0), world, {n} // surfaces, surfaces, **options))
"""

COMPARE = """
import jax, ccjax
from ccjax.experiments import sweep
sweep(ccjax.World.default(), ["NOTHING", "GW"], [4, 8], {n} // 4, jax.random.key(0), progress=False, cache=False)
"""

RENDERED = """
import jax
from ccjax.training import Pretraining, render_images
jax.block_until_ready(render_images(Pretraining("Canon EOS 600D", images={n})))
"""


@dataclass(frozen=True)
class Row:
    """One bounded count: the child's code for ``n`` items, the two sizes and the limit in items."""

    name: str
    item: str
    code: str
    sizes: tuple[int, int]
    limit: int


def rows() -> list[Row]:
    """The measured counts, in the order of the docs' table."""
    max_surfaces = 1993  # the default world's reflectances
    at_max = int(limits.SAMPLE_SURFACES.value) // max_surfaces * max_surfaces
    return [
        Row(
            "indexing-objects",
            "object",
            INDEXING.format(methods=["ACTUAL", "GW"], objects="{n}", lights=20, size=64),
            (520, 1040),
            int(limits.OBJECTS.value),
        ),
        Row(
            "indexing-size",
            "pixel of an image",
            INDEXING.format(methods=["ACTUAL", "GW", "CRULE-MV"], objects=4, lights=2, size="int({n} ** 0.5)"),
            (128**2, 512**2),
            int(limits.INDEXING_SIZE.value) ** 2,
        ),
        # ccjax.sample: 64 surfaces a scene, plain and with every scene option; every surface.
        *(
            Row(name, "surface", SAMPLE.format(n="{n}", surfaces=surfaces, options=options), sizes, at_limit)
            for name, surfaces, options, sizes, at_limit in (
                ("sample-64", 64, False, (64 * 20_000, 64 * 60_000), int(limits.SAMPLE_SURFACES.value)),
                ("sample-64-all", 64, True, (64 * 5_000, 64 * 15_000), int(limits.SAMPLE_SURFACES.value)),
                ("sample-max-all", 0, True, (max_surfaces * 200, max_surfaces * 600), at_max),
            )
        ),
        Row("compare", "scene result", COMPARE, (4 * 50_000, 4 * 1_000_000), int(limits.SCENE_RESULTS.value)),
        Row("rendered-images", "image", RENDERED, (200, 2000), int(limits.RENDERED_IMAGES.value)),
    ]


def peak_bytes(code: str) -> int:
    """Run ``code`` in a fresh Python process; its peak resident memory, in bytes."""
    child = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code) + PEAK],
        capture_output=True,
        text=True,
        env={**os.environ, "TQDM_DISABLE": "1"},
    )
    lines = [line for line in child.stdout.splitlines() if line.startswith("peak ")]
    if child.returncode or not lines:
        raise RuntimeError(f"child failed ({child.returncode}):\n{child.stderr[-3000:]}")
    return int(lines[-1].split()[1]) * 1024


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rows", default=None, help="comma-separated row names (default: every row)")
    args = parser.parse_args()
    chosen = [row for row in rows() if args.rows is None or row.name in args.rows.split(",")]
    print(
        f"{'count':<18}{'item':<19}{'small':>10}{'large':>10}{'peak small':>12}{'peak large':>12}"
        f"{'B/item':>10}{'limit':>12}{'at limit':>10}"
    )
    for row in chosen:
        small, large = row.sizes
        low, high = (peak_bytes(row.code.format(n=n)) for n in row.sizes)
        per_item = (high - low) / (large - small)
        projected = low + per_item * (row.limit - small)
        print(
            f"{row.name:<18}{row.item:<19}{small:>10,}{large:>10,}{low / 2**20:>10.0f}MB{high / 2**20:>10.0f}MB"
            f"{per_item:>10.1f}{row.limit:>12,}{projected / 2**30:>8.2f}GB",
            flush=True,
        )


if __name__ == "__main__":
    main()
