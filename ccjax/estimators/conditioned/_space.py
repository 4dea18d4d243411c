"""The camera-independent space of the any-camera estimator, from a camera's curves alone.

Every camera is seen through one fixed *reference camera*: the mean of ccjax's embedded cameras'
curves, each channel scaled to unit area (a typical sensor, so the diagonal model of a change of
light holds in it about as well as in a real camera). A camera's map to it is the 3x3 least-squares
fit over the SFU 1993 reflectances (and a perfect white, weighted as :data:`WHITE_WEIGHT`
surfaces, since a ground truth is mapped as a white is) under a bank of lights: blackbodies
2000-10000 K, CIE daylight 4000-25000 K and CIE fluorescent and LED lights (:func:`light_bank`),
each scaled so that the camera's white has largest channel 1. The camera's *fingerprint* is its
whites under the same bank (:func:`fingerprint`); two cameras are *twins* when they are the same
model from two sources, or when their fingerprints lie within :data:`TWIN_DEGREES` of each other
(:func:`twins`).
"""

from __future__ import annotations

import functools
import re

import numpy as np
from jaxtyping import Float

from ccjax import data
from ccjax.camera import Camera
from ccjax.spectra import blackbody, cie_daylight, resample

__all__ = [
    "TWIN_DEGREES",
    "WHITE_WEIGHT",
    "fingerprint",
    "fingerprint_distance",
    "light_bank",
    "model_name",
    "reference_matrix",
    "reference_sensors",
    "twins",
    "window_lights",
]

TWIN_DEGREES = 0.5
"""Two cameras whose fingerprints differ by less than this mean angle (degrees) are twins."""

WHITE_WEIGHT = 100.0
"""The perfect white's weight in the reference map's least squares, in surfaces."""


@functools.cache
def light_bank() -> np.ndarray:
    """The lights a fingerprint and a reference map are computed under: blackbodies 2000-10000 K
    (500 K steps), CIE daylight 4000-25000 K (1000 K steps), CIE FL1-FL12 and the CIE LED series.

    Returns:
        ``(L, 101)`` spectra on the ccjax grid, each scaled to unit mean.
    """
    import colour  # imported here: colour-science is slow to import

    spectra = [blackbody(np.arange(2000.0, 10000.0 + 1, 500.0)), cie_daylight(np.arange(4000.0, 25000.0 + 1, 1000.0))]
    series = [f"FL{i}" for i in range(1, 13)] + [name for name in colour.SDS_ILLUMINANTS if name.startswith("LED-")]
    spectra.append(_cie_illuminants(series))
    bank = np.concatenate(spectra).astype(np.float64)
    return bank / bank.mean(axis=1, keepdims=True)


def _cie_illuminants(names: list[str]) -> np.ndarray:
    """colour-science's CIE illuminants ``names`` on the ccjax grid, ``(len(names), 101)``."""
    import colour  # imported here: colour-science is slow to import

    named = colour.SDS_ILLUMINANTS
    return np.stack(
        [resample(np.asarray(named[n].wavelengths), np.asarray(named[n].values), kind="light") for n in names]
    )


@functools.cache
def window_lights() -> np.ndarray:
    """Every light the any-camera model's histogram must hold, in the reference camera: its whites
    under :func:`light_bank` and under the CIE high-pressure discharge lamps HP1-HP5 (sodium and
    metal halide, CIE 15:2018 Table 11; street and stadium lighting, far above the Planckian
    locus). A model trained on a few cameras' photographs sets its histogram's window on their
    lights; a camera's light outside that window wraps onto the far side of the torus and is
    estimated tens of degrees away (FFCC §3), so the window is set on these as well.

    Returns:
        ``(L + 5, 3)`` float64 whites, each of unit sum.
    """
    lamps = _cie_illuminants(["HP1", "HP2", "HP3", "HP4", "HP5"])
    whites = np.concatenate([light_bank(), lamps / lamps.mean(axis=1, keepdims=True)]) @ reference_sensors()
    return whites / whites.sum(axis=1, keepdims=True)


@functools.cache
def reference_sensors() -> np.ndarray:
    """The reference camera's curves: the mean of the embedded cameras' curves, each channel
    scaled to unit area first.

    Returns:
        ``(101, 3)`` float64 curves, each channel of unit area.
    """
    curves = np.stack([np.asarray(c, np.float64) for c in data.rawtoaces_cameras().values()])
    curves = curves / curves.sum(axis=1, keepdims=True)
    mean = curves.mean(axis=0)
    return mean / mean.sum(axis=0, keepdims=True)


def _sensors(camera: Camera | np.ndarray) -> np.ndarray:
    sensors = np.asarray(camera.sensors if isinstance(camera, Camera) else camera, np.float64)
    if sensors.shape != (101, 3):
        raise ValueError(f"camera: expected a Camera or (101, 3) curves, got shape {sensors.shape}")
    return sensors


def fingerprint(camera: Camera | Float[np.ndarray, "101 3"]) -> np.ndarray:
    """The camera's whites under :func:`light_bank`: its Planckian, daylight, fluorescent and LED
    loci as its own sensor sees them.

    Arguments:
        camera: a :class:`~ccjax.camera.Camera` (or its ``(101, 3)`` curves).

    Returns:
        ``(L, 3)`` float64 whites, each of unit sum.
    """
    whites = light_bank() @ _sensors(camera)
    return whites / whites.sum(axis=1, keepdims=True)


def fingerprint_distance(a: Camera | np.ndarray, b: Camera | np.ndarray) -> float:
    """The mean angle (degrees) between two cameras' fingerprints, light by light.

    Arguments:
        a, b: the cameras (or their curves).

    Returns:
        The mean angular difference in degrees.
    """
    fa, fb = fingerprint(a), fingerprint(b)
    cosine = np.sum(fa * fb, axis=1) / (np.linalg.norm(fa, axis=1) * np.linalg.norm(fb, axis=1))
    return float(np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0))).mean())


def model_name(name: str) -> str:
    """A camera's model without its source: ``"Jiang: Canon 600D"`` and ``"Canon EOS 600D"`` both
    give ``"canon 600d"`` (the source prefix, Canon's "EOS" and case dropped).

    Arguments:
        name: a camera name of :func:`ccjax.cameras`.

    Returns:
        The normalised model name.
    """
    model = name.split(":", 1)[1] if ":" in name else name
    words = [word for word in re.split(r"[\s_]+", model.strip().lower()) if word and word != "eos"]
    return " ".join(words)


def twins(camera: Camera, others: dict[str, Camera]) -> list[str]:
    """The names among ``others`` that are ``camera`` or its twin: the same model from another
    source (:func:`model_name`), or a fingerprint within :data:`TWIN_DEGREES`.

    Arguments:
        camera: the camera.
        others: ``{name: camera}`` the candidates.

    Returns:
        The twins' names, in ``others``' order.
    """
    own = model_name(camera.name)
    return [
        name
        for name, other in others.items()
        if name == camera.name or model_name(name) == own or fingerprint_distance(camera, other) < TWIN_DEGREES
    ]


def reference_matrix(camera: Camera | Float[np.ndarray, "101 3"]) -> np.ndarray:
    """The 3x3 that takes the camera's raw RGB to the reference camera's (module docstring): least
    squares over the SFU 1993 reflectances and a perfect white under :func:`light_bank`.

    Arguments:
        camera: a :class:`~ccjax.camera.Camera` (or its ``(101, 3)`` curves).

    Returns:
        ``(3, 3)`` float64 ``M`` with ``reference_rgb ~ M @ camera_rgb`` (up to one scale,
        chosen so that the equal-energy white's largest channel is kept).
    """
    sensors = _sensors(camera)
    return _reference_matrix(sensors.tobytes())


@functools.lru_cache(maxsize=256)
def _reference_matrix(key: bytes) -> np.ndarray:
    sensors = np.frombuffer(key, np.float64).reshape(101, 3)
    reflectances = np.asarray(data.sfu_reflectances().values, np.float64)
    surfaces = np.concatenate([reflectances, np.ones((1, reflectances.shape[1]))])
    weights = np.ones(len(surfaces))
    weights[-1] = WHITE_WEIGHT
    lights = light_bank()
    scale = (lights @ sensors).max(axis=1)  # each light scaled so the camera's white peaks at 1
    signals = (lights / scale[:, None])[:, None, :] * surfaces[None, :, :]
    source = (signals @ sensors).reshape(-1, 3)
    target = (signals @ reference_sensors()).reshape(-1, 3)
    w = np.tile(weights, len(lights))[:, None]
    rows, *_ = np.linalg.lstsq(source * np.sqrt(w), target * np.sqrt(w), rcond=None)
    matrix = rows.T
    # Brightness kept: the equal-energy white's largest channel is the same on both sides, so the
    # mapped image keeps its exposure (the histogram's minimum intensity applies as in the camera).
    white = sensors.sum(axis=0)
    return matrix * (white.max() / (matrix @ white).max())
