"""The development-set table of docs/photographs.md: the field's protocol on folders of
photographs with ground truth (each set 3-fold cross-validated, the learned methods trained
within the folds; over the NUS-8 cameras, the geometric mean of each statistic, as the field
reports it), with training seconds per fold and inference milliseconds per image. The protocol
is the library's (:func:`ccjax.evaluation.evaluate_folder_sets`, ``ccjax evaluate DIR DIR ...``); this
script chooses the sets and their cameras and writes the page's table.

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


def evaluate_sets(directories, methods, train, saturation: float, models: pathlib.Path | None) -> dict:
    """Each set's 3-fold run (:func:`ccjax.evaluation.evaluate_folder_sets`, each set
    with its camera, world-based labels left out of sets without curves):
    ``{set: {camera, images, methods: {label: {mean, median, ..., ms_per_image, train_seconds}}}}``."""
    from ccjax.evaluation import FolderSet, evaluate_folder_sets

    folders = [
        FolderSet(directory, directory / "groundtruth.csv", CAMERAS.get(directory.name)) for directory in directories
    ]
    evaluation = evaluate_folder_sets(
        folders,
        methods,
        folds=3,
        train=train,
        read_options={"saturation": saturation},
        log=lambda line: print(line, file=sys.stderr),
    )
    if models is not None:
        evaluation.save_models(models, overwrite=True)
    return {
        result.folder.label: {"camera": result.folder.camera, "images": result.images, "methods": result.rows}
        for result in evaluation.sets
    }


def nus8_geometric_means(sets: dict) -> dict:
    """Per label present in every NUS-8 set: the geometric mean of each statistic over the cameras."""
    from ccjax.evaluation import geometric_means

    nus = [sets[name]["methods"] for name in NUS8 if name in sets]
    return {"cameras": len(nus), "methods": geometric_means(nus)} if nus else {}


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
        directories = [root / name for name in args.sets.split(",")]
        if args.quick:
            directories = [_subset(directory, 60, pathlib.Path(scratch)) for directory in directories]
        report["sets"] = evaluate_sets(
            directories, args.methods.split(","), args.train.split(","), args.saturation, models
        )
    for name, entry in report["sets"].items():
        for label, row in entry["methods"].items():
            print(f"{name:<18}{label:<28}mean {row['mean']:6.2f}  median {row['median']:6.2f}", flush=True)
    existing = DOCS / "data" / "photographs.json"
    if args.merge and existing.exists():
        report["sets"] = {**json.loads(existing.read_text())["sets"], **report["sets"]}
    report["nus8_geometric_mean"] = nus8_geometric_means(report["sets"])
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
