"""Rebuild the embedded data files of ``ccjax/data`` from a ``shared/data``-style directory.

Run once by maintainers (``python -m ccjax.data.build_embedded ../shared/data``); the package
itself only reads the ``.npz`` files written here. Only redistributable sources are embedded (they
ship in the wheel): the SFU 1993 reflectances (MIT, gfxdisp packaging) and the rawtoaces camera
curves (Apache-2.0). Values are stored as published (no resampling); loaders resample once.
"""

from __future__ import annotations

import json
import pathlib
import shutil
import sys

import numpy as np
import scipy.io

HERE = pathlib.Path(__file__).parent


def build(source: pathlib.Path) -> None:
    sfu = scipy.io.loadmat(source / "sfu_barnard" / "SFU_1993.mat")
    categories = ["additional", "macbeth", "dupont", "krinov", "munsell", "objects"]
    # The `all` matrix is ordered additional+macbeth, dupont, krinov, munsell, objects (README);
    # rebuild the labels by matching each row against the per-category matrices.
    all_rows = sfu["all"]
    labels = np.empty(len(all_rows), dtype=object)
    for name in categories:
        block = sfu[name]
        for row in block:
            hits = np.flatnonzero(np.all(all_rows == row, axis=1))
            labels[hits] = name
    if any(label is None for label in labels):
        raise RuntimeError("could not label every SFU spectrum")
    np.savez_compressed(
        HERE / "sfu_reflectances_1993.npz",
        wavelengths=sfu["wavelength"].ravel().astype(np.float64),
        reflectances=all_rows.astype(np.float64),
        categories=labels.astype(str),
    )
    shutil.copy(source / "sfu_barnard" / "LICENSE_gfxdisp_MIT.txt", HERE / "LICENSE_sfu_reflectances_MIT.txt")

    names, curves, headers = [], [], []
    wavelengths = None
    for path in sorted((source / "camera_ssf_rawtoaces").glob("*.json")):
        doc = json.loads(path.read_text())
        header = doc["header"]
        data = doc["spectral_data"]["data"]["main"]
        wl = np.array(sorted(float(k) for k in data))
        values = np.array([data[k] for k in sorted(data, key=float)], dtype=np.float64)
        if wavelengths is None:
            wavelengths = wl
        elif not np.array_equal(wl, wavelengths):
            raise RuntimeError(f"{path.name}: unexpected wavelength sampling")
        names.append(f"{header['manufacturer']} {header['model']}")
        curves.append(values)
        headers.append(json.dumps({k: header.get(k) for k in ("manufacturer", "model", "document_creator", "license")}))
    if wavelengths is None:
        raise RuntimeError(f"{source / 'camera_ssf_rawtoaces'}: no camera curve files found")
    np.savez_compressed(
        HERE / "rawtoaces_cameras.npz",
        wavelengths=wavelengths,
        names=np.array(names),
        sensors=np.stack(curves),
        headers=np.array(headers),
    )
    shutil.copy(source / "camera_ssf_rawtoaces" / "LICENSE", HERE / "LICENSE_rawtoaces_Apache-2.0.txt")


if __name__ == "__main__":
    build(pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else "../shared/data"))
