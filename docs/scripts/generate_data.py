"""Regenerate the documentation's data, ``docs/data/*.json``, from ccjax's own commands.

The documentation site never types a number by hand: every table, figure and catalogue cell is
built (by ``docs/hooks.py`` at ``mkdocs build``) from the JSON files this script writes, which are
committed so that CI builds the site without running an experiment. Run from the repository root:

    CCJAX_DATA=/path/to/shared/data python docs/scripts/generate_data.py

Parts (``--only`` selects some; each writes its own files):

* ``reproduce``: ``ccjax reproduce T --json --no-progress`` for each thesis table
  (``--tables``, default 4.2 4.3 4.4 5.1 6.1 10.1 10.2) -> ``reproduce-T.json``;
* ``compare``: ``ccjax compare --world barnard1999 --json`` with Fig. 10.1's methods and the simple
  ones at 4..64 surfaces -> ``compare-barnard1999.json`` (the error-versus-surfaces figures);
* ``world``: the thesis world's (r,g) chromaticities (lights, canonical, reflectances) ->
  ``world-barnard1999.json`` (the Fig. 4.1-style plot);
* ``catalogue``: per registry family, its example label's rg RMS on the thesis world at 8 and 64
  surfaces (``ccjax.experiments.sweep``) and its speed (scenes/s of the compiled, batched
  estimator, median of warm runs) -> ``catalogue.json``.

The parts run one after another (``ccjax`` commands are not run in parallel: they share the cores).
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import platform
import subprocess
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[2]
DATA = ROOT / "docs" / "data"
TABLES = ("4.2", "4.3", "4.4", "5.1", "6.1", "10.1", "10.2")
# Fig. 10.1's methods (thesis §10.3: 3-D and 2-D Colour by Correlation, CRULE-MV, ND-ECRULE-SCWIA-12)
# and the simple methods of ch. 4 for the error-versus-surfaces figure.
COMPARE_METHODS = (
    "GW",
    "DB-GW",
    "RETINEX",
    "CRULE-MV",
    "ND-ECRULE-SCWIA-12",
    "C-by-C-MAP",
    "C-by-C-MMSE",
    "RGB-C-by-C-MAP",
    "RGB-C-by-C-MMSE",
)
COMPARE_SURFACES = "4,8,16,32,64"
CATALOGUE_SURFACES = (8, 64)
SPEED_BATCH = {8: 2048, 64: 512}


FAILED: list[str] = []


def _run(command: list[str], output: pathlib.Path | None = None) -> None:
    # A failing command is reported (with its stderr) and the next one runs; main() exits 1.
    print("$", " ".join(command), flush=True)
    start = time.perf_counter()
    completed = subprocess.run(command, capture_output=True, text=True)
    if completed.returncode != 0:
        print(completed.stderr[-4000:], flush=True)
        FAILED.append(" ".join(command))
        return
    if output is not None:
        json.loads(completed.stdout)  # a command that printed anything but JSON fails here
        output.write_text(completed.stdout)
    print(f"  {time.perf_counter() - start:.0f} s", flush=True)


def reproduce(args) -> None:
    for table in args.tables:
        command = ["ccjax", "reproduce", table, "--json", "--no-progress", "--scenes", str(args.scenes)]
        if args.data_dir:
            command += ["--data-dir", args.data_dir]
        _run(command, DATA / f"reproduce-{table}.json")


def compare(args) -> None:
    command = ["ccjax", "compare", "--world", "barnard1999", "--methods", ",".join(COMPARE_METHODS)]
    command += ["--surfaces", COMPARE_SURFACES, "--scenes", str(args.scenes), "--no-progress"]
    command += ["--json", str(DATA / "compare-barnard1999.json")]
    if args.data_dir:
        command += ["--data-dir", args.data_dir]
    _run(command)


def world(args) -> None:
    import numpy as np

    from ccjax._colour import rg_numpy
    from ccjax.world import World

    w = World.barnard1999(args.data_dir)

    def rg(rgb) -> list:
        return np.round(rg_numpy(np.asarray(rgb, np.float64)), 5).tolist()

    payload = {
        "world": w.name,
        "camera": w.camera.name,
        "train": rg(w.train_whites),
        "test": rg(w.test_whites),
        "canonical": rg(w.canonical_white),
        "reflectances": rg(w.canonical_rgb),
    }
    (DATA / "world-barnard1999.json").write_text(json.dumps(payload))
    print(f"wrote {DATA / 'world-barnard1999.json'}")


def catalogue(args) -> None:
    import equinox as eqx
    import jax
    import numpy as np

    from ccjax import experiments, scenes
    from ccjax.estimators import registry
    from ccjax.estimators.base import estimate_batch
    from ccjax.world import World

    @eqx.filter_jit
    def estimate(model, rgb, mask):
        return estimate_batch(model, rgb, mask).illuminant

    w = World.barnard1999(args.data_dir)
    batches = {n: scenes.sample(jax.random.key(n), w, SPEED_BATCH[n], n) for n in CATALOGUE_SURFACES}
    path = DATA / "catalogue.json"
    done = {}
    if args.resume and path.is_file():
        # Keep the families already measured (same scenes and machine description), measure the rest.
        done = {family["grammar"]: family for family in json.loads(path.read_text())["families"]}
    families = []

    def write() -> None:
        payload = {
            "world": w.name,
            "n_scenes": args.scenes,
            "surfaces": list(CATALOGUE_SURFACES),
            "speed_batch": {str(k): v for k, v in SPEED_BATCH.items()},
            "machine": f"{platform.machine()}, {os.cpu_count()} cores (shared), jax {jax.__version__} "
            f"on {jax.default_backend()}",
            "families": families,
        }
        path.write_text(json.dumps(payload, indent=1))

    for entry in registry.available():
        if entry.grammar in done and "note" not in done[entry.grammar]:
            families.append(done[entry.grammar])
            continue
        record: dict = {"grammar": entry.grammar, "example": entry.example}
        print(f"- {entry.example}", flush=True)
        record |= image_input(entry.example)
        if entry.input_kind != "surfaces":
            record["note"] = "image estimator: runs on images (ccjax evaluate), not on surface lists"
        elif not experiments.weights_ready(entry.example, w):
            record["note"] = "learned: needs `ccjax train-net` for the thesis world first"
        else:
            try:
                start = time.perf_counter()
                model = registry.fit(entry.example, w)
                record["fit_seconds"] = time.perf_counter() - start
                result = experiments.sweep(
                    w, [(entry.example, model)], CATALOGUE_SURFACES, args.scenes, jax.random.key(0), progress=False
                )
                record["rg_rms"] = {str(n): result.value(entry.example, n, "rg") for n in CATALOGUE_SURFACES}
                record["rg_rms_se"] = {
                    str(n): result.standard_error(entry.example, n, "rg") for n in CATALOGUE_SURFACES
                }
                record["angular_rms"] = {str(n): result.value(entry.example, n, "angular") for n in CATALOGUE_SURFACES}
                record["ok_fraction"] = {str(n): result.ok_fraction(entry.example, n) for n in CATALOGUE_SURFACES}
                speed = {}
                for n, batch in batches.items():
                    jax.block_until_ready(estimate(model, batch.rgb, batch.mask))  # compile
                    walls = []
                    for _ in range(3):
                        start = time.perf_counter()
                        jax.block_until_ready(estimate(model, batch.rgb, batch.mask))
                        walls.append(time.perf_counter() - start)
                    speed[str(n)] = SPEED_BATCH[n] / float(np.median(walls))
                record["scenes_per_second"] = speed
                record["load_average"] = os.getloadavg()[0]  # other load divides the wall-clock speed
            except Exception as error:  # a family that cannot run is reported as such, never hidden
                record["note"] = f"failed: {type(error).__name__}: {error}"
        families.append(record)
        print(f"  {record}", flush=True)
        write()  # after every family: an interrupted run keeps what it measured
    print(f"wrote {path}")


def image_input(label: str) -> dict:
    """What the image commands give ``label``'s model, from the model fitted to the default world:
    ``world_based`` (needs ``--camera``) and ``default_preprocessing``; empty when it cannot be
    fitted here (the nets before ``ccjax train-net``)."""
    from ccjax.runs import store

    try:
        model = store.fit(label, store.world())
    except Exception:  # a family that cannot be fitted here says nothing about its input
        return {}
    return {"world_based": bool(model.world_based), "default_preprocessing": str(model.default_preprocessing)}


PARTS = {"world": world, "reproduce": reproduce, "compare": compare, "catalogue": catalogue}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", default=",".join(PARTS), help=f"comma-separated parts of {list(PARTS)}")
    parser.add_argument("--tables", default=",".join(TABLES), type=lambda s: s.split(","))
    parser.add_argument("--scenes", type=int, default=1000, help="scenes per condition (the thesis: 1000)")
    parser.add_argument("--data-dir", default=os.environ.get("CCJAX_DATA"), help="external data (else $CCJAX_DATA)")
    parser.add_argument("--resume", action="store_true", help="catalogue: keep the families catalogue.json has")
    args = parser.parse_args()
    DATA.mkdir(parents=True, exist_ok=True)
    for part in args.only.split(","):
        if part not in PARTS:
            parser.error(f"--only: unknown part {part!r}")
        PARTS[part](args)
    for command in FAILED:
        print(f"FAILED: {command}", file=sys.stderr)
    return 1 if FAILED else 0


if __name__ == "__main__":
    sys.exit(main())
