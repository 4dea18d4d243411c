"""The fixed wavelength grid and resampling onto it.

Every spectrum in ccjax lives on 380–780 nm in 4 nm steps (101 samples), the sampling of the
PR-650 spectroradiometer used throughout the thesis (Barnard 1999 §2.2).
Loaders resample once, at load time:

* sensor curves are **zero** outside their measured range (a sensor that was not measured there
  is taken to have no sensitivity there);
* reflectances and illuminants **hold their edge values** (a spectrum is a physical quantity that
  does not drop to zero just because the instrument stopped).

colour-science interoperation: :func:`from_colour` takes a ``colour.SpectralDistribution`` or
``colour.MultiSpectralDistributions`` onto the grid by the same rule, with the kind an explicit
argument (colour-science's own extrapolation is not used: its default holds edge values for every
kind, which is wrong for a sensor), and :func:`to_colour` returns ccjax spectra as colour-science
objects whose extrapolation follows the kind.
"""

from __future__ import annotations

import sys
from typing import Any, Literal

import numpy as np
from jaxtyping import Float

Kind = Literal["sensor", "reflectance", "light", "spectrum"]
"""What a spectrum is, which fixes its values outside the measured range: ``"sensor"`` curves are
zero there; ``"reflectance"``, ``"light"`` (and the generic ``"spectrum"``) hold their edge values."""

KINDS: tuple[str, ...] = ("sensor", "reflectance", "light", "spectrum")

SpectraLike = Any
"""Spectra as a NumPy array on :data:`WAVELENGTHS` or as a colour-science ``SpectralDistribution`` /
``MultiSpectralDistributions`` (converted by :func:`as_spectra`); ``Any`` to the type checkers,
because colour-science is imported only when it is used."""

WAVELENGTHS: np.ndarray = np.arange(380.0, 780.0 + 1e-9, 4.0)
"""The ccjax wavelength grid in nm: 380, 384, ..., 780 (101 samples)."""

N_WAVELENGTHS: int = WAVELENGTHS.size


def resample(
    wavelengths: np.ndarray,
    values: np.ndarray,
    *,
    kind: Kind,
) -> np.ndarray:
    """Resample spectra onto :data:`WAVELENGTHS` by linear interpolation.

    Arguments:
        wavelengths: strictly increasing sample positions in nm, shape ``(L,)``.
        values: samples, shape ``(L,)`` or ``(L, C)`` (wavelength first, channels after), or
            ``(N, L)`` when ``values.shape[-1] == L`` and ``values.shape[0] != L``.
        kind: ``"sensor"`` (zero outside the measured range) or ``"reflectance"``, ``"light"``,
            ``"spectrum"`` (edge values held), see :data:`Kind`.

    Returns:
        Array on the grid: ``(101,)``, ``(101, C)`` or ``(N, 101)`` following the input layout.
    """
    wavelengths = np.asarray(wavelengths, dtype=np.float64)
    values = np.asarray(values, dtype=np.float64)
    if wavelengths.ndim != 1 or wavelengths.size < 2:
        raise ValueError(f"wavelengths: expected a 1-D array of at least 2 samples, got shape {wavelengths.shape}")
    if np.any(np.diff(wavelengths) <= 0):
        raise ValueError("wavelengths: must be strictly increasing")
    if not np.all(np.isfinite(values)):
        raise ValueError("values: contains NaN or infinite samples")
    _check_kind(kind)
    length = wavelengths.size
    if values.ndim == 1:
        if values.size != length:
            raise ValueError(f"values: {values.size} samples for {length} wavelengths")
        columns = values[:, None]
        layout = "vector"
    elif values.shape[0] == length:
        columns = values
        layout = "columns"
    elif values.shape[-1] == length:
        columns = values.T
        layout = "rows"
    else:
        raise ValueError(f"values: shape {values.shape} does not match {length} wavelengths")
    outside = 0.0 if kind == "sensor" else None
    out = np.stack(
        [np.interp(WAVELENGTHS, wavelengths, column, left=outside, right=outside) for column in columns.T],
        axis=1,
    )
    if layout == "vector":
        return out[:, 0]
    return out if layout == "columns" else out.T


def _check_kind(kind) -> None:
    if kind not in KINDS:
        raise ValueError(
            f"kind: expected one of {KINDS} (sensor curves are zero outside their range, the others hold "
            f"their edge values), got {kind!r}"
        )


def is_colour_distribution(value: Any) -> bool:
    """True for a colour-science ``SpectralDistribution`` or ``MultiSpectralDistributions``
    (camera sensitivities included); colour-science is not imported to answer.

    Arguments:
        value: anything.

    Returns:
        Whether ``value`` is one of colour-science's spectral distribution types.
    """
    colour = sys.modules.get("colour")
    if colour is None:  # an object of colour-science's types implies colour-science is imported
        return False
    return isinstance(value, colour.SpectralDistribution | colour.MultiSpectralDistributions)


def from_colour(distribution: Any, *, kind: Kind) -> np.ndarray:
    """A colour-science spectral distribution on :data:`WAVELENGTHS`.

    The samples of ``distribution`` (its ``wavelengths`` and ``values``) are resampled by
    :func:`resample` with ``kind`` deciding the values outside their range; the distribution's own
    interpolator and extrapolator are not used, so a sensor curve is zero outside its range whatever
    colour-science would extrapolate.

    Arguments:
        distribution: a ``colour.SpectralDistribution`` or a ``colour.MultiSpectralDistributions``
            (e.g. ``colour.characterisation.RGB_CameraSensitivities``).
        kind: ``"sensor"``, ``"reflectance"``, ``"light"`` or ``"spectrum"`` (:data:`Kind`); no
            default, because the two rules give different numbers.

    Returns:
        ``(101,)`` for a ``SpectralDistribution``; ``(101, C)`` for ``C`` distributions (wavelength
        first, one column per label, as colour-science stores them).
    """
    _check_kind(kind)
    if not is_colour_distribution(distribution):
        raise TypeError(
            "distribution: expected a colour.SpectralDistribution or colour.MultiSpectralDistributions, "
            f"got {type(distribution).__name__}"
        )
    return resample(np.asarray(distribution.wavelengths), np.asarray(distribution.values), kind=kind)


def as_spectra(value: Any, *, kind: Kind, rows: bool = True) -> np.ndarray:
    """Spectra as a NumPy array on the grid: colour-science distributions converted, arrays as given.

    For functions that take spectra either way (``World.from_sources``, ``Camera.from_array``).

    Arguments:
        value: an array already on :data:`WAVELENGTHS`, or a colour-science distribution.
        kind: the kind of a colour-science distribution (see :func:`from_colour`).
        rows: for ``MultiSpectralDistributions``, return ``(C, 101)`` (one spectrum per row, as
            ccjax stores reflectances and lights) rather than ``(101, C)`` (as it stores sensors).

    Returns:
        A float64 array; arrays are returned unchanged (``np.asarray``).
    """
    if not is_colour_distribution(value):
        return np.asarray(value, dtype=np.float64)
    out = from_colour(value, kind=kind)
    return out.T if rows and out.ndim == 2 else out


def to_colour(
    values: Any,
    *,
    kind: Kind,
    name: str | None = None,
    labels: list[str] | None = None,
) -> Any:
    """ccjax spectra as colour-science distributions on :data:`WAVELENGTHS`.

    The result's extrapolation follows ``kind``: a sensor extrapolates to zero, the other kinds hold
    their edge values, so colour-science reads outside 380–780 nm what ccjax would.

    Arguments:
        values: ``(101,)`` (one spectrum), ``(101, C)`` (sensor-style columns) or ``(N, 101)``
            (one spectrum per row) on the grid.
        kind: ``"sensor"``, ``"reflectance"``, ``"light"`` or ``"spectrum"`` (:data:`Kind`).
        name: the distribution's name.
        labels: the names of the ``C`` (or ``N``) distributions (default ``"0"``, ``"1"``, ...).

    Returns:
        A ``colour.SpectralDistribution`` for ``(101,)``, else a ``colour.MultiSpectralDistributions``.
    """
    import colour  # imported here: colour-science is slow to import

    _check_kind(kind)
    values = np.asarray(values, dtype=np.float64)
    edge = 0.0 if kind == "sensor" else None
    extrapolation = {"extrapolator_kwargs": {"method": "Constant", "left": edge, "right": edge}}
    if values.ndim == 1 and values.size == N_WAVELENGTHS:
        return colour.SpectralDistribution(values, WAVELENGTHS, name=name or kind, **extrapolation)
    if values.ndim == 2 and N_WAVELENGTHS in values.shape:
        columns = values if values.shape[0] == N_WAVELENGTHS else values.T
        labels = labels or [str(i) for i in range(columns.shape[1])]
        if len(labels) != columns.shape[1]:
            raise ValueError(f"labels: {len(labels)} names for {columns.shape[1]} spectra")
        return colour.MultiSpectralDistributions(
            columns, WAVELENGTHS, labels=list(labels), name=name or kind, **extrapolation
        )
    raise ValueError(f"values: expected shape (101,), (101, C) or (N, 101) on the ccjax grid, got {values.shape}")


def blackbody(kelvin: Float[np.ndarray, " T"]) -> Float[np.ndarray, "T 101"]:
    """Planckian radiators (blackbodies) on :data:`WAVELENGTHS`, colour-science's ``sd_blackbody``
    (Planck's law with CIE 015:2018's c2 = 1.4388e-2 m K).

    Arguments:
        kelvin: ``(T,)`` colour temperatures in K, each positive.

    Returns:
        ``(T, 101)`` spectral radiances (W sr^-1 m^-2 nm^-1), one light per row.

    Raises:
        ValueError: ``kelvin`` is not a 1-D array of finite positive temperatures.
    """
    import colour  # imported here: colour-science is slow to import

    kelvin = _temperatures("kelvin", kelvin, 0.0, np.inf)
    shape = colour.SpectralShape(WAVELENGTHS[0], WAVELENGTHS[-1], WAVELENGTHS[1] - WAVELENGTHS[0])
    return np.stack([from_colour(colour.sd_blackbody(t, shape), kind="light") for t in kelvin])


def cie_daylight(kelvin: Float[np.ndarray, " T"]) -> Float[np.ndarray, "T 101"]:
    """CIE daylight illuminants (D series) at correlated colour temperatures on :data:`WAVELENGTHS`
    (CIE 015:2018 §3.1: chromaticity from the CCT, spectrum from the S0, S1, S2 components).

    Arguments:
        kelvin: ``(T,)`` correlated colour temperatures in K, each in the D series' 4000-25000 K.

    Returns:
        ``(T, 101)`` relative spectral power distributions (100 at 560 nm), one light per row.

    Raises:
        ValueError: ``kelvin`` is not a 1-D array of temperatures in 4000-25000 K.
    """
    import colour  # imported here: colour-science is slow to import

    kelvin = _temperatures("kelvin", kelvin, 4000.0, 25000.0)
    lights = [colour.sd_CIE_illuminant_D_series(colour.temperature.CCT_to_xy_CIE_D(t)) for t in kelvin]
    return np.stack([from_colour(sd, kind="light") for sd in lights])


def _temperatures(name: str, kelvin: Any, low: float, high: float) -> np.ndarray:
    """``kelvin`` as a 1-D float array, each in ``(low, high]`` K (``low`` excluded only when 0)."""
    kelvin = np.asarray(kelvin, dtype=np.float64)
    if kelvin.ndim != 1 or kelvin.size == 0 or not np.all(np.isfinite(kelvin)):
        raise ValueError(f"{name}: expected a 1-D array of finite temperatures in K, got shape {kelvin.shape}")
    outside = (kelvin <= 0) if low == 0 else (kelvin < low)
    if np.any(outside | (kelvin > high)):
        span = "positive" if low == 0 else f"in {low:.0f}-{high:.0f} K"
        raise ValueError(f"{name}: every temperature must be {span}, got {kelvin.min()}-{kelvin.max()} K")
    return kelvin
