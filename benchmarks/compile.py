"""Benchmark: what the gamut programs cost to build, beside what they cost to run, against a base.

Per gamut program (a label at a number of surface slots), each in a fresh process (no program
cache: every measurement traces and compiles from nothing), the program built the way the run
engine builds it: ``eqx.filter_jit`` of the engine's estimate program of one model
(:func:`ccjax.runs.engine.estimate_scenes`), or, on a base tree from before programs were keyed by
model, of its group program (``group_errors``) on that model alone:

* trace + lower: CPU seconds of ``.lower(...)`` (Python tracing and the StableHLO text);
* compile: CPU seconds of ``.compile()`` (XLA; its threads included);
* HLO: lines of the lowered StableHLO text (``.as_text()``);
* run: scenes per CPU-second of the warm program on a batch (``--scenes``), median of ``--repeats``.

With ``--speed-surfaces``, also the warm throughput of ``--speed-label`` at those surface counts
(the library's batched path, as ``benchmarks/gamut.py`` times it).

With ``--base COMMIT`` the base tree is checked out with ``git worktree add --detach`` in a
temporary folder (removed at the end) and every measurement runs once with it and once with this
tree, interleaved (base, head, base, ...), each a subprocess with ``PYTHONPATH`` at its tree, so
both see the same machine and load; the table gives medians over ``--rounds`` and head / base.
CPU seconds are this process's (``time.process_time``), so other load on the machine shows less
than in wall time; the load average is printed per round.

Usage: python benchmarks/compile.py [--base COMMIT] [--rounds 3]
       [--programs ND-ECRULE-MV:32,ND-ECRULE-MV:64,...] [--speed-surfaces 8,64,1024]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PROGRAMS = (
    "CRULE-MV:32",
    "ECRULE-MV:32",
    "ND-ECRULE-MV:32",
    "ND-ECRULE-MV:64",
    "ECRULE-SCWIA-12:32",
    "CRULE-AVE:64",
)


def child(program: str, kind: str, scenes_count: int, repeats: int, world_name: str) -> dict:
    """One measurement in this process (run with ``PYTHONPATH`` at the tree under test)."""
    import equinox as eqx
    import jax
    import numpy as np

    from ccjax import scenes
    from ccjax.estimators import registry
    from ccjax.estimators.base import estimate_batch
    from ccjax.world import World

    label, slots = program.rsplit(":", 1)
    if kind == "speed":  # as many scenes as at 8 surfaces take, at least 64
        scenes_count = max(64, scenes_count * 8 // int(slots))
    world = World.barnard1999() if world_name == "barnard1999" else World.default()
    model = registry.fit(label, world)
    batch = scenes.sample(jax.random.key(int(slots)), world, scenes_count, int(slots))
    if kind == "speed":
        run = eqx.filter_jit(lambda m, rgb, mask: estimate_batch(m, rgb, mask).illuminant)
        jax.block_until_ready(run(model, batch.rgb, batch.mask))
        cpus = []
        for _ in range(repeats):
            start = time.process_time()
            jax.block_until_ready(run(model, batch.rgb, batch.mask))
            cpus.append(time.process_time() - start)
        return {"run": scenes_count / float(np.median(cpus))}

    from ccjax.runs import engine

    white = jax.numpy.asarray(world.canonical_white, jax.numpy.float32)
    if hasattr(engine, "estimate_scenes"):
        program_fn = eqx.filter_jit(engine.estimate_scenes)
        arguments = (model, batch.rgb, batch.mask)
    else:  # a base tree whose engine compiles groups of models
        program_fn = eqx.filter_jit(engine.group_errors)  # pyright: ignore[reportAttributeAccessIssue]
        arguments = ((model,), batch, white)
    start = time.process_time()
    lowered = program_fn.lower(*arguments)
    lower = time.process_time() - start
    lines = lowered.as_text().count("\n")
    start = time.process_time()
    compiled = lowered.compile()
    compile_seconds = time.process_time() - start
    jax.block_until_ready(compiled(*arguments))
    cpus = []
    for _ in range(repeats):
        start = time.process_time()
        jax.block_until_ready(compiled(*arguments))
        cpus.append(time.process_time() - start)
    return {"lower": lower, "compile": compile_seconds, "hlo": lines, "run": scenes_count / float(np.median(cpus))}


def measure(tree: Path, program: str, kind: str, args) -> dict:
    """:func:`child` in a fresh process on ``tree``."""
    env = {**os.environ, "PYTHONPATH": str(tree), "JAX_ENABLE_COMPILATION_CACHE": "false"}
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    argv = [sys.executable, str(Path(__file__).resolve()), "--child", program, "--kind", kind]
    argv += ["--scenes", str(args.scenes), "--repeats", str(args.repeats), "--world", args.world]
    done = subprocess.run(argv, env=env, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise SystemExit(f"{program} ({kind}) on {tree} failed ({done.returncode}):\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def git(*args: str) -> str:
    return subprocess.run(["git", "-C", str(ROOT), *args], check=True, capture_output=True, text=True).stdout.strip()


def median(values: list[float]) -> float:
    ordered = sorted(values)
    middle = len(ordered) // 2
    return ordered[middle] if len(ordered) % 2 else 0.5 * (ordered[middle - 1] + ordered[middle])


def report(trees: dict[str, Path], jobs: list[tuple[str, str]], args) -> None:
    results: dict[tuple[str, str, str], list[dict]] = {}
    for round_ in range(args.rounds):
        print(f"-- round {round_ + 1} of {args.rounds}, load {os.getloadavg()}", flush=True)
        for program, kind in jobs:
            for name, tree in trees.items():
                r = measure(tree, program, kind, args)
                results.setdefault((name, program, kind), []).append(r)
                shown = ", ".join(f"{key} {value:.4g}" for key, value in r.items())
                print(f"  {name:<14} {program:<22} {kind:<7} {shown}", flush=True)
    print(f"\nmedians of {args.rounds} rounds (CPU seconds; run: scenes per CPU-second, {args.scenes} scenes):")
    names = list(trees)
    for program, kind in jobs:
        for name in names:
            rows = results[name, program, kind]
            cells = {key: median([row[key] for row in rows]) for key in rows[0]}
            line = f"  {name:<14} {program:<22}"
            if kind == "compile":
                total = cells["lower"] + cells["compile"]
                line += (
                    f" trace+lower {cells['lower']:6.2f} s, compile {cells['compile']:6.2f} s, "
                    f"together {total:6.2f} s, HLO {cells['hlo']:6.0f} lines, run {cells['run']:8.0f} scenes/s"
                )
            else:
                line += f" run {cells['run']:8.0f} scenes/s"
            print(line)
        if len(names) == 2:
            base, head = (results[name, program, kind] for name in names)
            parts = []
            if kind == "compile":
                pairs = list(zip(base, head, strict=True))
                both = [(h["lower"] + h["compile"]) / (b["lower"] + b["compile"]) for b, h in pairs]
                parts.append(f"trace+lower+compile {median(both):.2f}x")
                parts.append(f"HLO {median([h['hlo'] / b['hlo'] for b, h in zip(base, head, strict=True)]):.2f}x")
            parts.append(f"run speed {median([h['run'] / b['run'] for b, h in zip(base, head, strict=True)]):.2f}x")
            print(f"  {'head / base':<14} {program:<22} " + ", ".join(parts) + " (median of per-round ratios)")


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--base", help="a commit to compare with, run interleaved with this tree")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--programs", default=",".join(PROGRAMS), help="LABEL:SLOTS, comma-separated")
    parser.add_argument("--scenes", type=int, default=512, help="scenes per timed batch")
    parser.add_argument("--repeats", type=int, default=3, help="warm runs per measurement (median)")
    parser.add_argument("--speed-label", default="ND-ECRULE-MV")
    parser.add_argument("--speed-surfaces", default="", help="surface counts of the run-speed table, e.g. 8,64,1024")
    parser.add_argument("--world", default="default", choices=("default", "barnard1999"))
    parser.add_argument("--child", help=argparse.SUPPRESS)
    parser.add_argument("--kind", default="compile", choices=("compile", "speed"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.rounds < 1 or args.scenes < 1 or args.repeats < 1:
        raise ValueError("--rounds, --scenes and --repeats must be positive")
    if args.child:
        print(json.dumps(child(args.child, args.kind, args.scenes, args.repeats, args.world)))
        return
    jobs = [(program, "compile") for program in args.programs.split(",") if program]
    jobs += [(f"{args.speed_label}:{n}", "speed") for n in args.speed_surfaces.split(",") if n]
    head = f"head {git('rev-parse', '--short=8', 'HEAD')}" + ("+" if git("status", "--porcelain", "ccjax") else "")
    print(f"cpus {os.cpu_count()}, world {args.world}, {len(jobs)} measurements per tree per round", flush=True)
    if not args.base:
        report({head: ROOT}, jobs, args)
        return
    with tempfile.TemporaryDirectory(prefix="ccjax-compile-") as scratch:
        base_tree = Path(scratch) / "base"
        git("worktree", "add", "--detach", str(base_tree), args.base)
        try:
            report({f"base {args.base[:8]}": base_tree, head: ROOT}, jobs, args)
        finally:
            git("worktree", "remove", "--force", str(base_tree))


if __name__ == "__main__":
    main()
