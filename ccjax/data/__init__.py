"""Embedded data and loaders for the external data directory (the data of Barnard 1999 §3.5, §4.4).

Embedded (redistributable): the SFU 1993 reflectances (MIT) and the rawtoaces camera curves
(Apache-2.0); see ``ATTRIBUTION.md`` beside this file. Illuminants of the default world come from
colour-science.

External (licence unclear for redistribution): the Sony DXC-930 curves, the 99 SFU illuminants,
the Jiang et al. camera curves and the SFU-321 / Gehler–Shi ground truths. They are read from a
directory laid out like the project's ``shared/data`` (sub-folders ``sfu_barnard/``,
``camera_ssf_jiang2013_camspec/``, ``gehler_shi_groundtruth/``), looked up in this order:

1. the explicit ``data_dir`` argument;
2. the ``CCJAX_DATA`` environment variable;
3. ``../shared/data`` beside the repository this package (or the working directory) belongs to.
"""

from __future__ import annotations

import csv
import functools
import os
import pathlib
import re
from dataclasses import dataclass

import numpy as np

from ccjax.spectra import WAVELENGTHS, resample

EMBEDDED = pathlib.Path(__file__).parent


class DataNotFoundError(FileNotFoundError):
    """An external data file is missing; the message says how to provide it."""


def _candidate_roots(data_dir: str | os.PathLike | None) -> list[tuple[str, pathlib.Path]]:
    if data_dir is not None:
        return [("the data_dir argument", pathlib.Path(data_dir))]
    roots: list[tuple[str, pathlib.Path]] = []
    if os.environ.get("CCJAX_DATA"):
        roots.append(("$CCJAX_DATA", pathlib.Path(os.environ["CCJAX_DATA"])))
    # A checkout keeps shared/ beside the repository; find the repository from the package
    # (editable installs) or from the working directory (installed copies run in a checkout).
    seen = set()
    for start in (EMBEDDED.parent.parent, pathlib.Path.cwd()):
        for folder in (start, *start.parents):
            if (folder / "pyproject.toml").exists() and folder not in seen:
                seen.add(folder)
                roots.append((f"../shared/data beside {folder}", folder.parent / "shared" / "data"))
                break
    return roots


def find_data_file(relative: str, data_dir: str | os.PathLike | None = None) -> pathlib.Path:
    """Locate an external data file, e.g. ``"sfu_barnard/sony_dxc930_380-780-4nm.csv"``.

    Arguments:
        relative: path inside the data directory.
        data_dir: explicit data directory; if given, it is the only place looked at.

    Returns:
        The path of the first existing candidate.

    Raises:
        DataNotFoundError: naming the file, every place looked at, and how to point ccjax at it.
    """
    roots = _candidate_roots(data_dir)
    for _, root in roots:
        path = root / relative
        if path.is_file():
            return path
    looked = "; ".join(f"{label} ({root / relative})" for label, root in roots) or "nowhere"
    raise DataNotFoundError(
        f"external data file {relative!r} not found. Looked at: {looked}. "
        "Pass data_dir=... (or --data-dir on the command line) or set CCJAX_DATA to a directory "
        "laid out like the project's shared/data (sub-folders sfu_barnard/, "
        "camera_ssf_jiang2013_camspec/, gehler_shi_groundtruth/); the documentation's "
        "'External data' page (docs/external-data.md) says where each file comes from and its format."
    )


# ---------------------------------------------------------------------------------------------
# Embedded data


@dataclass(frozen=True)
class Reflectances:
    """Surface reflectances on the ccjax grid with a category label per spectrum."""

    values: np.ndarray  # (S, 101)
    categories: np.ndarray  # (S,) str


@functools.cache
def sfu_reflectances() -> Reflectances:
    """The 1993 SFU reflectances (Barnard et al. 2002), embedded; Barnard 1999 §4.4.

    Returns:
        The reflectances ``(1993, 101)`` with their category labels.
    """
    with np.load(EMBEDDED / "sfu_reflectances_1993.npz") as f:
        values = resample(f["wavelengths"], f["reflectances"], kind="spectrum")
        return Reflectances(values=values, categories=f["categories"].astype(str))


@functools.cache
def rawtoaces_cameras() -> dict[str, np.ndarray]:
    """The 52 embedded rawtoaces camera curves, name -> sensors ``(101, 3)`` (zero outside 380–780).

    Returns:
        Camera name -> ``(101, 3)`` sensors.
    """
    with np.load(EMBEDDED / "rawtoaces_cameras.npz") as f:
        return {
            str(name): resample(f["wavelengths"], curves, kind="sensor")
            for name, curves in zip(f["names"], f["sensors"])
        }


# ---------------------------------------------------------------------------------------------
# External data


def sony_dxc930(data_dir=None) -> np.ndarray:
    """Sony DXC-930 sensors ``(101, 3)`` (the thesis' camera, Barnard 1999 ch. 3), external.

    Arguments:
        data_dir: external data directory (see :func:`find_data_file` for the look-up order).

    Returns:
        ``(101, 3)`` sensor curves.
    """
    path = find_data_file("sfu_barnard/sony_dxc930_380-780-4nm.csv", data_dir)
    table = np.loadtxt(path, delimiter=",", skiprows=1)
    sensors = table[:, 1:4]
    # The published file carries spline round-off of about 1e-14 (some of it negative) where the
    # sensors are zero; values that small relative to the peak are zero, not data.
    sensors = np.where(np.abs(sensors) < 1e-9 * sensors.max(axis=0), 0.0, sensors)
    return resample(table[:, 0], sensors, kind="sensor")


@dataclass(frozen=True)
class NamedSpectra:
    names: tuple[str, ...]
    values: np.ndarray  # (N, 101)


def sfu_illuminants(data_dir=None) -> NamedSpectra:
    """The 99 SFU illuminant spectra (78 measured, the 11 lab lights, 10 others), external.

    Arguments:
        data_dir: external data directory (see :func:`find_data_file` for the look-up order).

    Returns:
        The spectra ``(99, 101)`` with their names.
    """
    path = find_data_file("sfu_barnard/sfu_illuminants_380-780-4nm.csv", data_dir)
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    names = tuple(rows[0][1:])
    table = np.array(rows[1:], dtype=np.float64)
    return NamedSpectra(names=names, values=resample(table[:, 0], table[:, 1:], kind="spectrum").T)


SFU_LAB_LIGHTS: dict[str, str] = {
    # SFU-321 light code -> name in the SFU illuminant file (Barnard 1999 §4.4, the 11 lab lights)
    "syl-50MR16Q": "Sylvania 50MR16Q (12VDC)",
    "syl-50MR16Q+3202": "Sylvania 50MR16Q (12VDC) + Roscolux 3202",
    "solux-3500": "Solux 3500K (12VDC)",
    "solux-3500+3202": "Solux 3500K (12VDC) + Roscolux 3202",
    "solux-4100": "Solux 4100K (12VDC)",
    "solux-4100+3202": "Solux 4100K (12VDC) + Roscolux 3202",
    "solux-4700": "Solux 4700K (12VDC)",
    "solux-4700+3202": "Solux 4700K (12VDC) + Roscolux 3202",
    "syl-wwf": "Sylvania Warm White Fluorescent",
    "syl-cwf": "Sylvania Cool White Fluorescent",
    "ph-ulm": "Philips Ultralume Fluorescent",
}
"""The 11 lab lights of SFU-321 (Barnard 1999 §4.4): each light code of the data set's file names to
the light's name in the SFU illuminant file (:func:`sfu_illuminants`)."""


@dataclass(frozen=True)
class GroundTruth:
    """Per-image ground-truth illuminant RGB (camera space) with image names and labels."""

    images: tuple[str, ...]
    rgb: np.ndarray  # (N, 3)
    labels: tuple[str, ...]  # light code (SFU-321) or fold number (Gehler–Shi)


def _read_groundtruth(path: pathlib.Path, image: str, rgb: tuple[str, str, str], label: str) -> GroundTruth:
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    return GroundTruth(
        images=tuple(r[image] for r in rows),
        rgb=np.array([[float(r[c]) for c in rgb] for r in rows]),
        labels=tuple(r[label] for r in rows),
    )


def sfu321_groundtruth(data_dir=None) -> GroundTruth:
    """Ground-truth illuminants of the 321 SFU lab images (unit-norm Sony DXC-930 RGB), external.

    Arguments:
        data_dir: external data directory (see :func:`find_data_file` for the look-up order).

    Returns:
        The ground truth (image names, illuminant RGBs).
    """
    path = find_data_file("sfu_barnard/sfu321_groundtruth.csv", data_dir)
    return _read_groundtruth(path, "image", ("r", "g", "b"), "light")


def gehler_shi_groundtruth(data_dir=None) -> GroundTruth:
    """Gehler–Shi (568 images) recommended ground truth (Hemrit et al. 2018) with folds, external.

    Arguments:
        data_dir: external data directory (see :func:`find_data_file` for the look-up order).

    Returns:
        The ground truth (image names, illuminant RGBs, folds).
    """
    path = find_data_file("gehler_shi_groundtruth/GT_HemritRec.txt", data_dir)
    return _read_groundtruth(path, "File", ("R", "G", "B"), "Fold")


def jiang_cameras(data_dir=None) -> dict[str, np.ndarray]:
    """The 28 Jiang et al. (2013) camera curves as ``"Jiang: <make> <model>" -> (101, 3)``, external.

    Arguments:
        data_dir: external data directory (see :func:`find_data_file` for the look-up order).

    Returns:
        Camera name -> ``(101, 3)`` sensors.
    """
    folder = find_data_file("camera_ssf_jiang2013_camspec/README.md", data_dir).parent
    cameras = {}
    for path in sorted(folder.glob("*.csv")):
        with open(path) as f:
            first = f.readline()
        model = first.split(":", 1)[1].strip() if first.startswith("#Camera:") else path.stem.replace("_", " ")
        model = re.sub(r"(\S)Mark(I+)$", r"\1 Mark \2", model)  # "5DMarkII" -> "5D Mark II"
        table = np.loadtxt(path, delimiter=",", comments="#")
        cameras[f"Jiang: {model}"] = resample(table[:, 0], table[:, 1:4], kind="sensor")
    return cameras


__all__ = [
    "SFU_LAB_LIGHTS",
    "WAVELENGTHS",
    "DataNotFoundError",
    "find_data_file",
    "gehler_shi_groundtruth",
    "jiang_cameras",
    "rawtoaces_cameras",
    "sfu321_groundtruth",
    "sfu_illuminants",
    "sfu_reflectances",
    "sony_dxc930",
]
