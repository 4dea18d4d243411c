"""The development-set table of docs/photographs.md: the field's protocol on folders of
photographs with ground truth (each set 3-fold cross-validated, the learned methods trained
within the folds; over the NUS-8 cameras, the geometric mean of each statistic, as the field
reports it), with training seconds per fold and inference milliseconds per image.

Run::

    python docs/scripts/photographs.py ROOT --saturation 64224 [--sets cube_plus,nus8-C1,...]
        [--train FFCC] [--methods GW,shades-of-grey-p6,grey-edge-1-6-2] [--models DIR] [--quick]

``ROOT`` holds one folder per set (``cube_plus/``, ``nus8-<camera>/``) with ``groundtruth.csv``.
It prints the per-set rows and the NUS-8 geometric means, writes ``docs/data/photographs.json``
and rewrites the table between the markers of ``docs/photographs.md``. ``--models DIR`` writes
each fold's trained model (``DIR/<set>/<label>-fold<k>.eqx``, :func:`ccjax.runs.store.save_trained`).
``--quick``: the first 60 images of each set, for a smoke run.
"""

from __future__ import annotations

import argparse
import json
import math
import pathlib
import shutil
import sys
import tempfile

import numpy as np

DOCS = pathlib.Path(__file__).resolve().parents[1]
START, END = "<!-- photographs-table:start -->", "<!-- photographs-table:end -->"

# The camera whose curves fit each set's world-based methods; None: ccjax has no curves for it.
CAMERAS = {
    "cube_plus": "Canon EOS 600D",  # a stand-in for Cube+'s Canon 550D
    "nus8-C1": "Canon EOS-1Ds Mark III",
    "nus8-Canon600D": "Canon EOS 600D",
}
NUS8 = tuple(
    f"nus8-{name}" for name in ("C1", "Canon600D", "Fuji", "NikonD5200", "Olympus", "Panasonic", "Samsung", "Sony")
)


def _subset(directory: pathlib.Path, count: int, scratch: pathlib.Path) -> pathlib.Path:
    """A folder of copies of the first ``count`` images of ``directory`` and their ground truth."""
    lines = (directory / "groundtruth.csv").read_text().splitlines()
    target = scratch / directory.name
    target.mkdir()
    (target / "groundtruth.csv").write_text("\n".join(lines[: count + 1]) + "\n")
    for line in lines[1 : count + 1]:
        name = line.split(",")[0]
        shutil.copyfile(directory / name, target / name)
    return target


def evaluate_set(directory: pathlib.Path, methods, train, saturation: float, models: pathlib.Path | None) -> dict:
    """One set's 3-fold run: ``{label: {mean, median, ..., ms_per_image, train_seconds}}``."""
    from ccjax.experiments.folders import evaluate_folder
    from ccjax.runs import store
    from ccjax.runs.store import save_trained

    camera = CAMERAS.get(directory.name)
    # World-based labels need the camera's curves: left out of sets without them.
    usable = [label for label in train if camera is not None or not store.fit(label, store.world()).world_based]
    scored = [label for label in methods if camera is not None or not store.fit(label, store.world()).world_based]
    evaluation = evaluate_folder(
        directory,
        directory / "groundtruth.csv",
        scored,
        world=store.world("default", camera),
        folds=3,
        train=usable,
        read_options={"saturation": saturation},
        log=lambda line: print(line, file=sys.stderr),
    )
    results, rows = evaluation.results, {}
    for label in results.estimates:
        summary = results.summary(label)
        row = {key: summary[key] for key in ("mean", "median", "trimean", "best25", "worst25") if key in summary}
        row["ms_per_image"] = 1e3 * results.seconds.get(label, math.nan) / max(1, len(results.paths))
        rows[label] = row
    for label, validation in evaluation.validations.items():
        rows[label + " trained"]["train_seconds"] = float(np.mean([fold.log.seconds for fold in validation.folds]))
        if models is not None:
            for fold, model in enumerate(evaluation.trained_models[label + " trained"]):
                path = models / directory.name / f"{label}-fold{fold}.eqx"
                path.parent.mkdir(parents=True, exist_ok=True)
                save_trained(path, model, label=label, camera=camera or "Canon EOS 5D Mark II")
    return {"camera": camera, "images": len(results.paths), "methods": rows}


def geometric_means(sets: dict) -> dict:
    """Per label present in every NUS-8 set: the geometric mean of each statistic over the cameras."""
    nus = [sets[name]["methods"] for name in NUS8 if name in sets]
    if not nus:
        return {}
    labels = set.intersection(*(set(rows) for rows in nus))
    out = {}
    for label in sorted(labels):
        out[label] = {
            key: float(np.exp(np.mean([np.log(rows[label][key]) for rows in nus])))
            for key in ("mean", "median", "trimean", "best25", "worst25")
            if all(key in rows[label] and rows[label][key] > 0 for rows in nus)
        }
    return {"cameras": len(nus), "methods": out}


def table(report: dict) -> str:
    """The markdown table: one row per set and label, then the NUS-8 geometric means."""
    lines = [
        "| set | method | mean | median | trimean | best 25 % | worst 25 % | train s / fold | ms / image |",
        "|---|---|---|---|---|---|---|---|---|",
    ]

    def cell(row, key, digits=2):
        value = row.get(key)
        return "" if value is None or not math.isfinite(value) else f"{value:.{digits}f}"

    for name, entry in report["sets"].items():
        for label, row in entry["methods"].items():
            lines.append(
                f"| {name} ({entry['images']}) | {label} | {cell(row, 'mean')} | {cell(row, 'median')} | "
                f"{cell(row, 'trimean')} | {cell(row, 'best25')} | {cell(row, 'worst25')} | "
                f"{cell(row, 'train_seconds', 1)} | {cell(row, 'ms_per_image', 3)} |"
            )
    nus = report.get("nus8_geometric_mean") or {}
    for label, row in nus.get("methods", {}).items():
        lines.append(
            f"| NUS-8 geometric mean ({nus['cameras']} cameras) | {label} | {cell(row, 'mean')} | "
            f"{cell(row, 'median')} | {cell(row, 'trimean')} | {cell(row, 'best25')} | {cell(row, 'worst25')} | | |"
        )
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("root", help="folder holding cube_plus/ and nus8-<camera>/")
    parser.add_argument("--saturation", type=float, required=True, help="saturation level in file units")
    parser.add_argument("--sets", default=",".join(("cube_plus", *NUS8)), help="comma-separated set folders")
    parser.add_argument("--train", default="FFCC", help="comma-separated labels trained within the folds")
    parser.add_argument("--methods", default="GW,shades-of-grey-p6,grey-edge-1-6-2", help="comma-separated labels")
    parser.add_argument("--models", default=None, help="write each fold's trained model under this folder")
    parser.add_argument("--quick", action="store_true", help="the first 60 images of each set (a smoke run)")
    parser.add_argument("--no-write", action="store_true", help="print only: leave docs/ unchanged")
    parser.add_argument("--merge", action="store_true", help="keep the other sets of docs/data/photographs.json")
    args = parser.parse_args(argv)
    root = pathlib.Path(args.root)
    models = pathlib.Path(args.models) if args.models else None
    report: dict = {"saturation": args.saturation, "folds": 3, "quick": args.quick, "sets": {}}
    with tempfile.TemporaryDirectory() as scratch:
        for name in args.sets.split(","):
            directory = root / name
            if args.quick:
                directory = _subset(directory, 60, pathlib.Path(scratch))
            entry = evaluate_set(directory, args.methods.split(","), args.train.split(","), args.saturation, models)
            report["sets"][name] = entry
            for label, row in entry["methods"].items():
                print(f"{name:<18}{label:<28}mean {row['mean']:6.2f}  median {row['median']:6.2f}", flush=True)
    existing = DOCS / "data" / "photographs.json"
    if args.merge and existing.exists():
        report["sets"] = {**json.loads(existing.read_text())["sets"], **report["sets"]}
    report["nus8_geometric_mean"] = geometric_means(report["sets"])
    text = table(report)
    print(text)
    if not args.no_write:
        (DOCS / "data" / "photographs.json").write_text(json.dumps(report, indent=1) + "\n")
        page = DOCS / "photographs.md"
        content = page.read_text()
        head, rest = content.split(START, 1)
        _, tail = rest.split(END, 1)
        page.write_text(f"{head}{START}\n{text}\n{END}{tail}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
