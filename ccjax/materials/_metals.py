"""Metal specular reflectances from optical constants (Barnard 1999 §8.2–§8.3).

The thesis measured the specular reflectance of brass, copper and grey metals (aluminium, stainless
steel) with a PR-650; those measurements are not available. ccjax computes them instead from
published optical constants: a metal with complex refractive index ``n + i k`` reflects, at normal
incidence from air, the fraction given by the Fresnel equations,

    R(λ) = ((n - 1)^2 + k^2) / ((n + 1)^2 + k^2).

The constants (``ccjax/materials/_metal_data.py``, from the CC0 refractiveindex.info database; the
original papers are cited in ``ccjax/materials/ATTRIBUTION.md``) are interpolated linearly in
wavelength onto :data:`ccjax.spectra.WAVELENGTHS` before the Fresnel step:

* gold, silver, copper: Johnson & Christy (1972);
* aluminium: Rakić (1995);
* brass: Querry (1985), 70 % Cu / 30 % Zn;
* steel: Karlsson & Ribbing (1982), austenitic stainless steel (the thesis' "stainless steel").

API (the defaults are spec ch08-12 §8, A10/A11):

* :func:`fresnel_reflectance` ``(n, k) -> R`` (jit-able, any shape);
* :func:`optical_constants` ``(name) -> OpticalConstants`` (the embedded table and its source);
* :func:`metal_reflectance` ``(name) -> (101,)`` absolute normal-incidence reflectance in [0, 1];
* :func:`metal_spectra` ``(names=METALS, unit_mean=True) -> (M, 101)``: the "metal spectra" of the
  MET gamut, each scaled to unit mean over 380–780 nm (A10);
* :func:`scene_metal_spectra` ``(names=METALS) -> (M, 101)``: the spectra of the scenes' metallic
  highlights, the metals' own (absolute) reflectances, so ``s * M`` with ``s ~ U(0, 4)`` is at most
  four times as bright as a perfect white in every channel (§8.3; why not unit mean: below);
* constants :data:`METALS` (all six: metallic highlights in scenes draw from these, A11),
  :data:`COLOURED_METALS` (brass, copper, gold: the ones the MET canonical gamut adds, A10),
  :data:`GREY_METALS`, :data:`MET_MULTIPLIER` (``k_m = 8``), :data:`METAL_PROBABILITY` (0.25),
  :data:`METAL_MAX_AMOUNT` (4) and :data:`THESIS_CLIP` (300 in thesis units, ``300/255`` on ccjax's
  scale).

**The highlights' scale** (§8.3, A11). The thesis "added metallic specularities which were up to a
factor of four times as bright as a perfect white", drawn uniformly, to 25 % of the surfaces; it
does not say how its measured spectra were scaled. The spec's A11 reads them as unit-mean spectra
(as A10 does for the gamut), but a unit-mean copper times 4 reflects 5.2 times what a perfect white
does at long wavelengths (4.4 times in the Sony camera's red channel), not "up to four times"; the
metals' own reflectances (mean 0.64–0.99 here) keep every channel at most four times white. Table
8.3 points the same way through the methods that ignore metals, whose brightness error depends on
nothing but the highlights: with unit-mean highlights GW, DB-GW and RETINEX err 77 %, 61 % and 70 %
above the thesis in the metallic column (483.7 against 274 for GW), with the reflectances 35 %, 31 %
and 33 %, and SP-ECRULE-MV's brightness error varies over the five conditions by 1.62x with
unit-mean highlights against the thesis' "roughly constant" (at most 1.5x), 1.16x with the
reflectances (``python benchmarks/metal_recipe.py``, the scenes of ``ccjax reproduce 8.3``). So the
scenes use the reflectances; the MET gamut keeps A10's unit mean (its scale is ``k_m``'s: from
``k_m = 8`` to 24 Table 8.2's MET rows move by at most 2.2 % on matte scenes and 10 % with
dielectric highlights, same script).
"""

from __future__ import annotations

from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ccjax.materials import _metal_data
from ccjax.spectra import WAVELENGTHS

METALS: tuple[str, ...] = ("gold", "copper", "brass", "aluminium", "silver", "steel")
"""Every embedded metal; metallic highlights in synthetic scenes draw uniformly from these (A11)."""

COLOURED_METALS: tuple[str, ...] = ("brass", "copper", "gold")
"""The coloured metals whose highlights the MET canonical gamut adds (Barnard 1999 §8.2; A10)."""

GREY_METALS: tuple[str, ...] = ("aluminium", "silver", "steel")
"""Grey metals: in synthetic scenes only (their highlights are close to white, which SP already covers)."""

MET_MULTIPLIER: float = 8.0
"""``k_m``: the MET gamut adds ``k_m * rho_C(M)`` for each coloured metal (A10; the same 8 as SP's white)."""

METAL_PROBABILITY: float = 0.25
"""Probability that a surface of a synthetic scene gets a metallic highlight (§8.3)."""

METAL_MAX_AMOUNT: float = 4.0
"""Metallic highlights are ``s * M`` with ``s ~ U(0, 4)`` and ``M`` a metal's reflectance (§8.3: up to
four times as bright as white; :func:`scene_metal_spectra`)."""

THESIS_CLIP: float = 300.0 / 255.0
"""The clip level of Tables 8.2/8.3's clipped conditions, 300 in thesis units, on ccjax's scale (A6)."""


@dataclass(frozen=True)
class OpticalConstants:
    """A metal's tabulated complex refractive index ``n + i k``.

    Attributes:
        name: the metal.
        wavelengths: ``(L,)`` nm, increasing (the table's own sampling, bracketing 380–780 nm).
        n: ``(L,)`` refractive index.
        k: ``(L,)`` extinction coefficient.
        source: the original paper (the values come through the refractiveindex.info database, CC0).
    """

    name: str
    wavelengths: np.ndarray
    n: np.ndarray
    k: np.ndarray
    source: str


def fresnel_reflectance(n: Float[ArrayLike, "*shape"], k: Float[ArrayLike, "*shape"]) -> Float[Array, "*shape"]:
    """Normal-incidence reflectance of an absorbing medium in air (the Fresnel equations at 0°).

    ``R = |(N - 1) / (N + 1)|^2`` with ``N = n + i k``, i.e. ``((n-1)^2 + k^2) / ((n+1)^2 + k^2)``:
    ``k = 0`` gives the dielectric ``((n-1)/(n+1))^2``; ``k -> inf`` the perfect conductor ``R -> 1``.

    Arguments:
        n: refractive index (> 0), any shape.
        k: extinction coefficient (>= 0), broadcastable with ``n``.

    Returns:
        Reflectance in [0, 1), the broadcast shape of ``n`` and ``k``.
    """
    n, k = jnp.asarray(n), jnp.asarray(k)
    return ((n - 1) ** 2 + k**2) / ((n + 1) ** 2 + k**2)


def optical_constants(name: str) -> OpticalConstants:
    """The embedded (n, k) table of one metal.

    Arguments:
        name: one of :data:`METALS`.

    Returns:
        :class:`OpticalConstants` at the table's own wavelengths.
    """
    if name not in _metal_data.TABLES:
        raise ValueError(f"name: unknown metal {name!r}; expected one of {', '.join(METALS)}")
    table = np.asarray(_metal_data.TABLES[name], dtype=np.float64)
    return OpticalConstants(
        name=name, wavelengths=table[:, 0], n=table[:, 1], k=table[:, 2], source=_metal_data.SOURCES[name][1]
    )


def metal_reflectance(name: str) -> np.ndarray:
    """Normal-incidence reflectance of a metal on :data:`ccjax.spectra.WAVELENGTHS` (Barnard 1999 §8.2:
    the metal's specular reflectance ``M(λ)``).

    n and k are interpolated linearly in wavelength (every table brackets 380–780 nm, so nothing is
    extrapolated), then :func:`fresnel_reflectance` is applied.

    Arguments:
        name: one of :data:`METALS`.

    Returns:
        ``(101,)`` float64 reflectance in [0, 1].
    """
    constants = optical_constants(name)
    n = np.interp(WAVELENGTHS, constants.wavelengths, constants.n)
    k = np.interp(WAVELENGTHS, constants.wavelengths, constants.k)
    return ((n - 1) ** 2 + k**2) / ((n + 1) ** 2 + k**2)


def metal_spectra(names: tuple[str, ...] | list[str] = METALS, *, unit_mean: bool = True) -> np.ndarray:
    """Metal specular spectra, one row per metal: unit mean for the MET gamut (A10), absolute for
    scenes (:func:`scene_metal_spectra`).

    Arguments:
        names: metals, from :data:`METALS` (default: all six; the MET gamut uses
            :data:`COLOURED_METALS`).
        unit_mean: scale each spectrum to mean 1 over the 101 samples of 380–780 nm (A10: the
            thesis does not say how its measured spectra were scaled; unit mean makes ``s * M`` as
            bright as ``s`` times a perfect white, roughly); ``False``: absolute reflectance.

    Returns:
        ``(len(names), 101)`` float64.
    """
    if isinstance(names, str):
        raise ValueError(f"names: expected a sequence of metal names, got the string {names!r}")
    if len(names) == 0:
        raise ValueError("names: expected at least one metal")
    spectra = np.stack([metal_reflectance(name) for name in names])
    if unit_mean:
        spectra = spectra / spectra.mean(axis=1, keepdims=True)
    return spectra


def scene_metal_spectra(names: tuple[str, ...] | list[str] = METALS) -> np.ndarray:
    """The spectra of synthetic scenes' metallic highlights: each metal's own normal-incidence
    reflectance (Barnard 1999 §8.3: highlights "up to a factor of four times as bright as a perfect
    white" are ``s * M`` with ``s ~ U(0, 4)`` and ``M <= 1``; why not unit mean: the module notes).

    Arguments:
        names: metals, from :data:`METALS` (default: all six, A11: grey metals included).

    Returns:
        ``(len(names), 101)`` float64 reflectances in [0, 1].
    """
    return metal_spectra(names, unit_mean=False)
