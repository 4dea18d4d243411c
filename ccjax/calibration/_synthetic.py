"""Synthetic calibration data mirroring the thesis' experiment (Barnard 1999 §3.5).

The Macbeth ColorChecker (24 patches, colour-science's "ColorChecker N Ohta") is measured under
26 lights; each colour signal goes through a known sensor set, gets Gaussian noise with the
chapter-3 noise model (variance ``a rho + b``, shot noise plus a floor, on the unit scale where the
brightest channel of a perfect white under an unexposed light is 1), then through the inverse of a
known linearisation F (eq. 3.14, in 0–255 pixel units); measurements with a clipped channel are
removed, leaving about 612 of the 624 as in the thesis. Each light gets its own exposure (a fixed
spread of brightness factors in a seeded order), which is what makes a few measurements clip and
spreads the responses over the camera's range.

Lights (:data:`LightChoice`): the 11 SFU lab lights plus 15 other SFU lights
(:data:`SFU_OTHER_LIGHTS`, external data), or 26 CIE lights (:data:`CIE_LIGHTS`, embedded); the
default ``"auto"`` takes SFU when the external data are found and records in the result when it
did not.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Literal

import numpy as np

from ccjax import data
from ccjax.calibration.linearisation import Linearisation, invert_linearisation
from ccjax.camera import Camera
from ccjax.spectra import N_WAVELENGTHS, resample
from ccjax.world import normalise_illuminants

DEFAULT_NOISE_GAIN = 2e-6
"""Shot-noise coefficient ``a`` of the variance ``a rho + b`` on the unit scale."""
DEFAULT_NOISE_FLOOR = (0.05 / 255.0) ** 2
"""Intensity-independent variance ``b`` on the unit scale (0.05 pixel units standard deviation)."""
DEFAULT_LINEARISATION = {"black": 10.0, "a0": 12.0, "a1": 4.0, "exp_rate": 0.15}
"""F(x) = x - a0 - a1 exp(-C (x - b)) in 0–255 pixel units (eq. 3.14), the same for every channel."""
FULL_SCALE = 255.0
CLIP_LEVEL = 255.0
EXPOSURES = (0.5, 1.4)
"""Brightness factors of the 26 lights: evenly spaced over this range, assigned in a seeded order."""

COLORCHECKER = "ColorChecker N Ohta"

CIE_LIGHTS: tuple[str, ...] = (
    "A",
    "D50",
    "D55",
    "D65",
    "D75",
    "FL1",
    "FL2",
    "FL3",
    "FL4",
    "FL5",
    "FL6",
    "FL7",
    "FL8",
    "FL9",
    "FL10",
    "FL11",
    "FL12",
    "LED-B1",
    "LED-B2",
    "LED-B3",
    "LED-B4",
    "LED-B5",
    "LED-BH1",
    "LED-RGB1",
    "LED-V1",
    "LED-V2",
)
"""The 26 colour-science lights used when the SFU illuminants are not available."""

SFU_OTHER_LIGHTS: tuple[str, ...] = (
    "Halogen",
    "Judge DAY: Macbeth 5000 Tube",
    "Judge U30: Philips TL18W/84 Tube",
    "Judge DAY: Macbeth 6500 Tube",
    "Judge DAY: Macbeth 7500 Tube",
    "Studio",
    "Incadescent",
    "P-CW",
    "S-WW",
    "desk",
    "ref-sun",
    "ref-shade",
    "Courtyard between ASc and Kines: Bright sun",
    "Shade in very open denuded forest",
    "Floor near north end of atrium (10000 level), cloudy daylight",
)
"""The 15 SFU lights added to the 11 lab lights: the 10 non-lab sources and 5 daylights."""


@functools.cache
def colorchecker() -> tuple[tuple[str, ...], np.ndarray]:
    """The 24 ColorChecker reflectances and their names (colour-science).

    Returns:
        ``(names, reflectances (24, 101))``.
    """
    import colour

    sds = colour.SDS_COLOURCHECKERS[COLORCHECKER]
    names = tuple(sds)
    values = np.stack([resample(sds[n].wavelengths, sds[n].values, kind="spectrum") for n in names])
    return names, values


LightChoice = Literal["auto", "sfu", "cie"]
"""Which 26 lights the synthetic experiment uses: ``"sfu"`` the thesis' (external data), ``"cie"``
the colour-science ones (embedded), ``"auto"`` SFU when the external data are found, else CIE (and
the report says so)."""

SFU_SOURCE = "SFU (11 lab lights + 15 others)"
CIE_SOURCE = "CIE (colour-science)"


@functools.cache
def calibration_lights(data_dir=None, lights: LightChoice = "auto") -> tuple[tuple[str, ...], np.ndarray, str, str]:
    """The 26 lights of the synthetic experiment (Barnard 1999 §3.5 used 26 lights).

    Arguments:
        data_dir: external data directory (see :func:`ccjax.data.find_data_file`).
        lights: ``"sfu"``, ``"cie"`` or ``"auto"`` (see :data:`LightChoice`).

    Returns:
        ``(names, spectra (26, 101), source, note)``: ``source`` names the set; ``note`` is empty
        unless ``"auto"`` fell back to the CIE lights, when it says why.

    Raises:
        ccjax.data.DataNotFoundError: ``lights="sfu"`` and the SFU illuminants are not found.
    """
    if lights not in ("auto", "sfu", "cie"):
        raise ValueError(f"lights: expected 'auto', 'sfu' or 'cie', got {lights!r}")
    note = ""
    if lights != "cie":
        try:
            sfu = data.sfu_illuminants(data_dir)
        except data.DataNotFoundError as error:
            if lights == "sfu":
                raise
            note = f"the SFU illuminants were not found, so the CIE lights are used ({error})"
        else:
            names = tuple(data.SFU_LAB_LIGHTS.values()) + SFU_OTHER_LIGHTS
            values = np.stack([sfu.values[sfu.names.index(n)] for n in names])
            return names, values, SFU_SOURCE, note
    import colour

    values = np.stack(
        [
            resample(colour.SDS_ILLUMINANTS[n].wavelengths, colour.SDS_ILLUMINANTS[n].values, kind="spectrum")
            for n in CIE_LIGHTS
        ]
    )
    return CIE_LIGHTS, values, CIE_SOURCE, note


@dataclass(frozen=True)
class SyntheticCalibration:
    """A synthetic calibration data set with its ground truth (all 624 measurements kept).

    Attributes:
        spectra: ``(624, 101)`` colour signals (reflectance x light x exposure).
        raw: ``(624, 3)`` raw pixel values (0–255 units) after noise and the inverse of F.
        linear: ``(624, 3)`` noise-free linear responses in pixel units (the truth).
        noisy_linear: ``(624, 3)`` linear responses with noise, before the inverse of F.
        usable: ``(624,)`` True where no channel clipped (raw < 255).
        sensors: ``(101, 3)`` true curves in the units of ``spectra -> pixel values``.
        linearisation: the true F.
        noise_gain, noise_floor: the noise model on the unit scale.
        lights, patches: names; ``light_index``, ``patch_index`` ``(624,)`` say which is which.
        exposures: ``(26,)`` brightness factor per light.
        light_source: which light set was used.
        camera: name of the true camera.
        light_note: empty, or why the light set is not the one asked for (``lights="auto"``
            without the SFU illuminants).
    """

    spectra: np.ndarray
    raw: np.ndarray
    linear: np.ndarray
    noisy_linear: np.ndarray
    usable: np.ndarray
    sensors: np.ndarray
    linearisation: Linearisation
    noise_gain: float
    noise_floor: float
    lights: tuple[str, ...]
    patches: tuple[str, ...]
    light_index: np.ndarray
    patch_index: np.ndarray
    exposures: np.ndarray
    light_source: str
    camera: str
    light_note: str = ""

    @property
    def n_usable(self) -> int:
        return int(self.usable.sum())

    @property
    def noise_level(self) -> float:
        """RMS relative noise of the usable linear responses (the floor any fit can reach)."""
        rel = (self.noisy_linear - self.linear) / self.linear
        return float(np.sqrt(np.mean(rel[self.usable] ** 2)))

    def usable_data(self) -> tuple[np.ndarray, np.ndarray]:
        """The usable measurements only (what a real experiment would keep).

        Returns:
            ``(spectra, raw)``: ``(M, 101)`` spectra and ``(M, 3)`` raw responses.
        """
        return self.spectra[self.usable], self.raw[self.usable]


def _camera_sensors(camera, data_dir) -> tuple[np.ndarray, str]:
    if isinstance(camera, Camera):
        return np.asarray(camera.sensors, dtype=np.float64), camera.name
    if isinstance(camera, str):
        return np.asarray(Camera.from_name(camera, data_dir).sensors, dtype=np.float64), camera
    sensors = np.asarray(camera, dtype=np.float64)
    if sensors.shape != (N_WAVELENGTHS, 3):
        raise ValueError(
            f"camera: expected a name, a Camera or a ({N_WAVELENGTHS}, 3) array, got shape {sensors.shape}"
        )
    return sensors, "custom"


def synthetic_calibration(
    camera="Sony DXC-930",
    *,
    seed: int = 0,
    noise_gain: float = DEFAULT_NOISE_GAIN,
    noise_floor: float = DEFAULT_NOISE_FLOOR,
    black: float = DEFAULT_LINEARISATION["black"],
    a0: float = DEFAULT_LINEARISATION["a0"],
    a1: float = DEFAULT_LINEARISATION["a1"],
    exp_rate: float = DEFAULT_LINEARISATION["exp_rate"],
    exposures: tuple[float, float] = EXPOSURES,
    data_dir=None,
    lights: LightChoice = "auto",
) -> SyntheticCalibration:
    """Generate the thesis' calibration experiment for a known camera (Barnard 1999 §3.5).

    Arguments:
        camera: the truth: a name (``"Sony DXC-930"`` needs the external data), a
            :class:`~ccjax.camera.Camera` or a ``(101, 3)`` array.
        seed: NumPy seed of the exposure order and the noise.
        noise_gain, noise_floor: ``a`` and ``b`` of the noise variance ``a rho + b`` (unit scale).
        black, a0, a1, exp_rate: the true F (eq. 3.14, pixel units), the same for each channel;
            ``a1=0`` (and ``a0=0``) make the camera linear.
        exposures: range of the per-light brightness factors.
        data_dir: external data directory (SFU lights; Sony curves).
        lights: the light set (:data:`LightChoice`); the result records which one was used
            (``light_source``) and, for ``"auto"`` without the SFU data, why (``light_note``).

    Returns:
        A :class:`SyntheticCalibration` with every measurement and the ``usable`` mask.
    """
    for name, value in (("noise_gain", noise_gain), ("noise_floor", noise_floor), ("a1", a1), ("exp_rate", exp_rate)):
        if not (np.isfinite(value) and value >= 0):
            raise ValueError(f"{name}: expected a finite value >= 0, got {value!r}")
    if not (0 < exposures[0] <= exposures[1]):
        raise ValueError(f"exposures: expected 0 < low <= high, got {exposures!r}")
    sensors, camera_name = _camera_sensors(camera, data_dir)
    patches, reflectances = colorchecker()
    lights_used, light_spectra, source, note = calibration_lights(data_dir, lights)
    rng = np.random.default_rng(seed)
    exposure = np.linspace(exposures[0], exposures[1], len(lights_used))[rng.permutation(len(lights_used))]
    light_spectra = normalise_illuminants(light_spectra, sensors) * exposure[:, None]
    spectra = (light_spectra[:, None, :] * reflectances[None, :, :]).reshape(-1, N_WAVELENGTHS)
    unit = spectra @ sensors  # unit scale: white under an unexposed light has max channel 1
    noisy = unit + rng.standard_normal(unit.shape) * np.sqrt(noise_gain * unit + noise_floor)
    raw = invert_linearisation(FULL_SCALE * noisy, a0, a1, exp_rate, black)
    usable = np.all(raw < CLIP_LEVEL, axis=1)
    truth = Linearisation.per_channel(a0=a0, a1=a1, exp_rate=exp_rate, black=black)
    return SyntheticCalibration(
        spectra=spectra,
        raw=np.minimum(raw, CLIP_LEVEL),
        linear=FULL_SCALE * unit,
        noisy_linear=FULL_SCALE * noisy,
        usable=usable,
        sensors=FULL_SCALE * sensors,
        linearisation=truth,
        noise_gain=float(noise_gain),
        noise_floor=float(noise_floor),
        lights=tuple(lights_used),
        patches=patches,
        light_index=np.repeat(np.arange(len(lights_used)), len(patches)),
        patch_index=np.tile(np.arange(len(patches)), len(lights_used)),
        exposures=exposure,
        light_source=source,
        camera=camera_name,
        light_note=note,
    )


def has_external_lights(data_dir=None) -> bool:
    """Whether the SFU illuminants are available (the thesis' light set).

    Arguments:
        data_dir: the external data directory (see :func:`ccjax.data.find_data_file`).

    Returns:
        True when the illuminant file is found.
    """
    try:
        data.find_data_file("sfu_barnard/sfu_illuminants_380-780-4nm.csv", data_dir)
    except data.DataNotFoundError:
        return False
    return True


__all__ = [
    "CIE_LIGHTS",
    "DEFAULT_LINEARISATION",
    "DEFAULT_NOISE_FLOOR",
    "DEFAULT_NOISE_GAIN",
    "SFU_OTHER_LIGHTS",
    "LightChoice",
    "SyntheticCalibration",
    "calibration_lights",
    "colorchecker",
    "has_external_lights",
    "synthetic_calibration",
]
