"""Extensions of the canonical gamut (Barnard 1999 §6.1, ch. 7, §8.2, ch. 9), as point sets whose
hull (with the origin) the direction engine uses in place of the matte canonical gamut.

* **ND** (§6.1): the union over the representative illuminants (the training set and the
  canonical light) of each one's database gamut mapped white-to-white into the canonical light.
* **FL** (ch. 7, §7.2): the ND construction with the fluorescent surfaces' responses (from their
  characterisation, :mod:`ccjax.materials`) added to every per-illuminant gamut. FL implies ND.
* **SP** (§8.2): the standard (dielectric) specular extension, ``k`` times a perfect white added
  as one more "reflectance" (``k = 8`` for all the thesis' results; 2 and 4 were also tried).
  In every per-illuminant gamut it is ``k w_i``, which the white-to-white map sends to ``k w_C``.
* **MET** (§8.2): SP plus ``k_m`` times the specular reflectances of the coloured metals (brass,
  copper and gold by default, each normalised to unit mean, ``k_m = 8``: spec A10); under ND/FL
  the metal points map to illuminant-dependent points (the metals' diagonal failure).

Labels combine one of SP/MET with one of ND/FL, in that order (ch. 9): ``SP-FL-ECRULE-SCWIA-6``,
``MET-ND-ECRULE-ICA``. A multiplier other than 8 is written after the prefix: ``SP2-``, ``SP4-``,
``MET4-`` (``k`` and ``k_m`` alike).
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ccjax.estimators.gamut import _geometry
from ccjax.world import World

SPECULAR_MULTIPLIER = 8.0
"""``k`` of SP and ``k_m`` of MET (§8.2: "k = 8 was used for all results"; 2, 4, 8 were tried)."""

DEFAULT_METALS = ("brass", "copper", "gold")
"""The coloured metals of the MET gamut (§8.2, spec A10); grey metals appear in scenes only."""

DIAGONAL = ("ND", "FL")
SPECULAR = ("SP", "MET")

_TOKEN = re.compile(r"(?P<name>ND|FL|SP|MET)(?P<multiplier>\d+)?")

FluorescentResponses = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""``(illuminants (I, 101), sensors (101, 3)) -> (I, F, 3)`` camera RGB of the fluorescent surfaces."""


@dataclass(frozen=True)
class Extension:
    """Which extensions a canonical gamut has (ch. 9: one per independent idea).

    Attributes:
        diagonal: ``None``, ``"ND"`` or ``"FL"`` (diagonal-failure modelling).
        specular: ``None``, ``"SP"`` or ``"MET"`` (specular modelling).
        multiplier: ``k`` (and ``k_m`` for MET), 8 by default.
    """

    diagonal: str | None = None
    specular: str | None = None
    multiplier: float = SPECULAR_MULTIPLIER

    def __post_init__(self):
        if self.diagonal not in (None, *DIAGONAL):
            raise ValueError(f"extension: diagonal part must be None, ND or FL, got {self.diagonal!r}")
        if self.specular not in (None, *SPECULAR):
            raise ValueError(f"extension: specular part must be None, SP or MET, got {self.specular!r}")
        if not (isinstance(self.multiplier, (int, float)) and np.isfinite(self.multiplier) and self.multiplier > 0):
            raise ValueError(f"extension: the specular multiplier must be a positive number, got {self.multiplier!r}")
        if self.specular is None and self.multiplier != SPECULAR_MULTIPLIER:
            raise ValueError("extension: a specular multiplier needs SP or MET")

    @property
    def label(self) -> str | None:
        """The label prefix without its trailing dash (``"SP-ND"``, ``"MET4-FL"``), ``None`` for none."""
        parts = []
        if self.specular is not None:
            k = self.multiplier
            suffix = "" if k == SPECULAR_MULTIPLIER else (f"{int(k)}" if float(k).is_integer() else f"{k:g}")
            parts.append(self.specular + suffix)
        if self.diagonal is not None:
            parts.append(self.diagonal)
        return "-".join(parts) or None

    @classmethod
    def parse(cls, value) -> Extension:
        """Read an extension.

        Arguments:
            value: ``None``, a prefix string (``"ND"``, ``"SP-FL"``, ``"SP4"``), a tuple of tokens
                (``("SP", "ND")``) or an :class:`Extension`.

        Returns:
            The :class:`Extension`.
        """
        if isinstance(value, Extension):
            return value
        if value is None:
            return cls()
        if isinstance(value, str):
            tokens = [t for t in value.split("-") if t]
        elif isinstance(value, (tuple, list)):
            tokens = list(value)
        else:
            raise ValueError(f"extension: expected None, a string such as 'SP-ND' or a tuple, got {value!r}")
        diagonal = specular = None
        multiplier = SPECULAR_MULTIPLIER
        for token in tokens:
            match = _TOKEN.fullmatch(token) if isinstance(token, str) else None
            if match is None:
                raise ValueError(f"extension: unknown part {token!r} (expected ND, FL, SP[k] or MET[k])")
            name = match["name"]
            if match["multiplier"] is not None and name in DIAGONAL:
                raise ValueError(f"extension: {token!r}: only SP and MET take a multiplier")
            if name in DIAGONAL:
                if diagonal is not None:
                    raise ValueError(f"extension: {value!r} combines {diagonal} and {name}; FL already is ND")
                diagonal = name
            else:
                if specular is not None:
                    raise ValueError(f"extension: {value!r} combines {specular} and {name}; MET includes SP")
                specular = name
                if match["multiplier"] is not None:
                    multiplier = float(match["multiplier"])
        return cls(diagonal=diagonal, specular=specular, multiplier=multiplier)


def light_blocks(
    world: World,
    extension: Extension,
    *,
    metals: np.ndarray | None = None,
    fluorescent: FluorescentResponses | None = None,
) -> list[np.ndarray]:
    """The extra points of an extended gamut, one block per representative illuminant, already
    mapped white-to-white into the canonical light (the database's own points are not included:
    :func:`points` adds them).

    Arguments:
        world: the world (camera, canonical light, training lights).
        extension: which extensions.
        metals: ``(M, 101)`` metal specular reflectances (MET only), unit mean.
        fluorescent: the fluorescent surfaces' responses (FL only).

    Returns:
        A list of ``(n, 3)`` float64 blocks: the canonical light first, then (ND/FL) each training light.
    """
    sensors = np.asarray(world.camera.sensors, np.float64)
    canonical = np.asarray(world.canonical, np.float64)
    lights = [canonical]
    if extension.diagonal is not None:
        lights.extend(np.asarray(world.train_illuminants, np.float64))
    lights = np.stack(lights)
    whites = lights @ sensors
    balance = whites[0] / whites  # (L, 3); the canonical block's factor is exactly 1
    parts = []
    if extension.diagonal == "FL":
        if fluorescent is None:
            raise ValueError("fluorescent: the FL extension needs the fluorescent surfaces' responses")
        parts.append(np.asarray(fluorescent(lights, sensors), np.float64))
    if extension.specular is not None:
        parts.append(extension.multiplier * whites[:, None, :])
    if extension.specular == "MET":
        if metals is None:
            raise ValueError("metals: the MET extension needs metal specular reflectances")
        metals = np.atleast_2d(np.asarray(metals, np.float64))
        parts.append(extension.multiplier * np.einsum("ml,il,lc->imc", metals, lights, sensors))
    if not parts:
        return []
    extra = np.concatenate(parts, axis=1) * balance[:, None, :]
    return list(extra)


def points(
    world: World,
    extension: Extension | str | tuple | None = None,
    *,
    metals: np.ndarray | None = None,
    fluorescent: FluorescentResponses | None = None,
) -> np.ndarray:
    """The points whose hull with the origin is the (extended) canonical gamut.

    The database part is the canonical RGBs (no diagonal extension) or ND's white-balanced
    per-illuminant database gamuts (:func:`~ccjax.estimators.gamut._geometry.nd_points`, §6.1); the
    extensions' points (:func:`light_blocks`) are appended.

    Returns:
        ``(N, 3)`` float64 non-negative RGBs.
    """
    extension = Extension.parse(extension)
    if extension.diagonal is None:
        base = np.asarray(world.canonical_rgb, np.float64)
    else:
        base = _geometry.nd_points(
            np.asarray(world.reflectances),
            np.asarray(world.camera.sensors),
            np.asarray(world.train_illuminants),
            np.asarray(world.canonical),
        )
    extra = light_blocks(world, extension, metals=metals, fluorescent=fluorescent)
    return np.vstack([base, *extra]) if extra else base


def default_metals(names: tuple[str, ...] = DEFAULT_METALS) -> np.ndarray:
    """``(M, 101)`` unit-mean specular reflectances of the MET gamut's metals (spec A10), from
    their optical constants (:func:`ccjax.materials.metal_spectra`)."""
    from ccjax import materials

    return np.asarray(materials.metal_spectra(names, unit_mean=True), np.float64)


MEASUREMENT_LIGHTS = 11
"""The characterisation's measurement lights: the world's first 11 training lights (its priority
lights come first; in the thesis world these are the 11 lab lights, A19)."""


def characterised_fluorescents(world: World, surfaces=None):
    """Fluorescent surfaces characterised as the thesis characterised its measured ones (§7.1):
    responses under the world's first :data:`MEASUREMENT_LIGHTS` training lights, recombined by
    NNLS for any other light.

    Arguments:
        world: the world (its first training lights are the measurement lights).
        surfaces: the surfaces' physical model (a :class:`ccjax.materials.FluorescentSurfaces`;
            default: the nine synthetic surfaces of :mod:`ccjax.materials`).

    Returns:
        A :class:`ccjax.materials.Characterisation` (``.radiance(lights) -> (..., F, 101)``).
    """
    from ccjax import materials

    if surfaces is None:
        surfaces = materials.synthetic_fluorescent_surfaces()
    lights = np.asarray(world.train_illuminants, np.float64)[:MEASUREMENT_LIGHTS]
    return materials.characterise(surfaces, lights)


def default_fluorescent(world: World, surfaces=None) -> FluorescentResponses:
    """The camera responses of :func:`characterised_fluorescents` (what FL's gamut is built from:
    the algorithm knows only the characterisation, as in the thesis); ``surfaces`` as there.

    The characterisation predicts a surface under the light's NNLS approximation
    ``Ê = Σ α_k E_k`` (§7.1), so its responses are white-balanced by that approximation's own white
    ``ŵ = Ê Q`` rather than the true ``w`` (spec ch05-07 §4.2 leaves which white open): they are
    returned as ``x · w / ŵ``, which :func:`light_blocks`' white-to-white map ``w_C / w`` turns into
    ``x · w_C / ŵ``. Balancing a prediction made under ``Ê`` by the white of ``E`` would add the
    light approximation's own error to every point: with the 11 lab lights a non-fluorescent white
    lands 0.046 (r,g) from the canonical white, and the FL gamut grew 7.6x the matte gamut's volume
    (FL-CRULE-MV 0.124 rg RMS at 4 surfaces against CRULE-MV's 0.075; 0.081 with this balance).

    Arguments:
        world: the world (its first training lights are the measurement lights).
        surfaces: as :func:`characterised_fluorescents`.

    Returns:
        A ``FluorescentResponses`` callable: ``(illuminants (I, 101), sensors (101, 3)) -> (I, F, 3)``.
    """
    characterised = characterised_fluorescents(world, surfaces)
    measurement = np.asarray(characterised.lights, np.float64)

    def responses(lights: np.ndarray, sensors: np.ndarray) -> np.ndarray:
        x = np.einsum("ifl,lc->ifc", np.asarray(characterised.radiance(lights), np.float64), sensors)
        approximated = characterised.weights(lights) @ measurement  # (L, 101): Ê of each light
        return x * ((lights @ sensors) / (approximated @ sensors))[:, None, :]

    return responses
