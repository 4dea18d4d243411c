"""A newcomer's first runs: the main job, ``evaluate`` and ``estimate``, cold and warm, against a base.

Each command runs in a fresh process, first with an empty ``CCJAX_CACHE`` (every program
compiled) and again with that cache warm (programs and fits read back), once with this tree and
once with a base commit's, interleaved (base, this tree, base, ...) so that both see the same
machine load; the load average is printed before every run. The commands:

- ``ccjax compare --plot compare.png`` (the README's main job; it prints its own breakdown line:
  import, fit, compile, run, programs built), cold, warm and then ``--recompute`` (every program
  in the persistent compilation cache, every cell computed again);
- ``ccjax evaluate FOLDER --methods GW`` on a small folder of synthetic Mondrians with their
  ground truth (written by this tree's ``ccjax.io.write_dataset``);
- ``ccjax estimate IMAGE --method GW`` on one of those images;
- ``sweep``: a researcher's sweep in a fresh Python process, the documented
  ``ccjax.experiments.sweep`` of GW, shades of grey and ND-ECRULE-MV at 4, 8, 16, 32 surfaces and
  10,000 scenes each, printing its (r,g) and angular tables (it prints the same breakdown line,
  from :class:`ccjax.runs.CompileLog`; the library enables no persistent compilation cache, so
  its warm run reads only the fits back).

Every run's printed tables (stdout, with the cache folder's name replaced) are compared between
base and head for the same state: ``tables identical`` or the first differing lines.

The base is checked out with ``git worktree add --detach`` into a temporary folder (removed at the
end) and run with ``PYTHONPATH`` at it; this tree is run with ``PYTHONPATH`` at the repository.

Run: ``python benchmarks/startup.py [--base COMMIT] [--rounds 1] [--jobs compare,evaluate,estimate,sweep]``
(default base: ``git merge-base HEAD main``).
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

SWEEP = """
import sys, time
start = time.perf_counter()
import jax
import ccjax
from ccjax.experiments import sweep
from ccjax.runs import CompileLog

imported = time.perf_counter()
world = ccjax.World.default()
with CompileLog() as log:
    result = sweep(world, ["GW", "shades-of-grey-p6", "ND-ECRULE-MV"], n_surfaces=[4, 8, 16, 32],
                   n_scenes=10_000, key=jax.random.key(0), progress=False)
print(result.table("rg"))
print(result.table("angular"))
print(result.status_table())
print(f"done in {time.perf_counter() - start:.1f} s (import {imported - start:.1f} s, compile "
      f"{log.seconds():.1f} s, {log.programs} programs built)", file=sys.stderr)
"""
"""A researcher's sweep (a script, not a command): the printed tables and a breakdown line."""


STATES = {
    "compare": ("cold", "warm", "recompute"),
    "evaluate": ("cold", "warm"),
    "estimate": ("cold", "warm"),
    "sweep": ("cold", "warm"),
}
"""The states each job is run in, in order on one cache; ``recompute``: ``compare --recompute``
with the fits and programs of the runs before it cached."""


def git(*args: str) -> str:
    return subprocess.run(["git", "-C", str(ROOT), *args], check=True, capture_output=True, text=True).stdout.strip()


def write_folder(folder: Path, n_images: int) -> tuple[Path, Path]:
    """``n_images`` 64 x 64 Mondrians under the default world's lights, and their ground truth."""
    sys.path.insert(0, str(ROOT))
    import jax
    import numpy as np

    from ccjax import io, scenes
    from ccjax.world import World

    batch = scenes.sample_mondrians(jax.random.key(0), World.default(), n_images, height=64, width=64)
    truth = io.write_dataset(folder, np.asarray(batch.image), np.asarray(batch.illuminant))
    return truth, folder / "image-0000.png"


def run(tree: Path, argv: list[str], cache: str, workdir: Path) -> dict:
    """One fresh process of ``python -m ccjax ARGV`` (``python -c`` for an ARGV ``["-c", code]``) on
    ``tree``: wall seconds, load, breakdown, printed tables."""
    env = {**os.environ, "PYTHONPATH": str(tree), "CCJAX_CACHE": cache}
    load = os.getloadavg()
    start = time.perf_counter()
    command = [sys.executable, *argv] if argv[0] == "-c" else [sys.executable, "-m", "ccjax", *argv]
    done = subprocess.run(command, env=env, cwd=workdir, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(argv)} on {tree} failed ({done.returncode}):\n{done.stderr[-2000:]}")
    lines = [line for line in done.stderr.splitlines() if line.startswith("done in")]
    compile_match = re.search(r"compile ([0-9.]+) s", lines[-1]) if lines else None
    programs = re.search(r"(\d+) programs built", lines[-1]) if lines else None
    return {
        "wall": wall,
        "load": load,
        "line": lines[-1] if lines else "",
        "compile": float(compile_match.group(1)) if compile_match else None,
        "programs": int(programs.group(1)) if programs else None,
        "tables": done.stdout.replace(cache, "<cache>"),
    }


def same_tables(head: str, base: str) -> str:
    """``tables identical``, or the first lines where the printed tables differ."""
    if head == base:
        return "tables identical"
    pairs = [(h, b) for h, b in zip(head.splitlines(), base.splitlines(), strict=False) if h != b]
    first = pairs[0] if pairs else ("(lengths differ)", "")
    return f"TABLES DIFFER ({len(pairs)} lines), first: base {first[1]!r} head {first[0]!r}"


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--base", help="the commit to compare with (default: git merge-base HEAD main)")
    parser.add_argument("--rounds", type=int, default=1, help="interleaved rounds per command")
    parser.add_argument("--jobs", default="compare,evaluate,estimate,sweep", help="comma-separated commands to run")
    parser.add_argument("--images", type=int, default=8, help="images in the evaluate folder")
    args = parser.parse_args()
    base = args.base or git("merge-base", "HEAD", "main")
    jobs = args.jobs.split(",")
    with tempfile.TemporaryDirectory(prefix="ccjax-startup-") as scratch:
        work = Path(scratch)
        base_tree = work / "base"
        git("worktree", "add", "--detach", str(base_tree), base)
        try:
            truth, image = write_folder(work / "folder", args.images)
            argvs = {
                "compare": ["compare", "--plot", "compare.png", "--overwrite", "--no-progress"],
                "evaluate": ["evaluate", str(truth.parent), "--ground-truth", str(truth), "--methods", "GW"]
                + ["--no-progress"],
                "estimate": ["estimate", str(image), "--method", "GW", "--no-progress"],
                "sweep": ["-c", SWEEP],
            }
            trees = {f"base {base[:8]}": base_tree, f"head {git('rev-parse', '--short=8', 'HEAD')}": ROOT}
            print(f"cpus {os.cpu_count()}, load before {os.getloadavg()}", flush=True)
            results: dict[tuple[str, str], list[dict]] = {}
            for job in jobs:
                for round_ in range(args.rounds):
                    for name, tree in trees.items():
                        cache = tempfile.mkdtemp(dir=work, prefix="cache-")
                        for state in STATES[job]:
                            argv = argvs[job] + (["--recompute"] if state == "recompute" else [])
                            r = run(tree, argv, cache, work)
                            results.setdefault((job, f"{name} {state}"), []).append(r)
                            print(
                                f"{job:<9} {name:<14} {state:<5} round {round_}: wall {r['wall']:6.1f} s, "
                                f"load {r['load'][0]:.2f} {r['load'][1]:.2f} | {r['line']}",
                                flush=True,
                            )
            print("\nratios head / base (per round, interleaved):")
            base_name, head = list(trees)
            for job in jobs:
                for state in STATES[job]:
                    for h, b in zip(results[job, f"{head} {state}"], results[job, f"{base_name} {state}"], strict=True):
                        parts = [f"wall {h['wall'] / b['wall']:.2f}x ({b['wall']:.1f} -> {h['wall']:.1f} s)"]
                        if h["compile"] is not None and b["compile"]:
                            parts.append(
                                f"compile {h['compile'] / b['compile']:.2f}x ({b['compile']} -> {h['compile']} s)"
                            )
                        if h["programs"] is not None:
                            parts.append(f"programs {b['programs']} -> {h['programs']}")
                        parts.append(same_tables(h["tables"], b["tables"]))
                        print(f"  {job:<9} {state:<5} " + ", ".join(parts))
        finally:
            git("worktree", "remove", "--force", str(base_tree))


if __name__ == "__main__":
    main()
