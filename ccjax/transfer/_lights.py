"""Light sets to fit per-light camera maps on, beside a world's own lights."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from jaxtyping import Float

from ccjax.spectra import resample

BLACKBODY_KELVIN = tuple(float(k) for k in np.arange(2000.0, 10000.0 + 1, 250.0))
"""The default blackbodies of :func:`locus_lights`: 2000–10000 K in 250 K steps (as the default world's)."""

DAYLIGHT_KELVIN = tuple(float(k) for k in np.arange(4000.0, 25000.0 + 1, 500.0))
"""The default CIE daylights of :func:`locus_lights`: 4000–25000 K in 500 K steps (as the default world's)."""


def locus_lights(
    blackbody: Sequence[float] | Float[np.ndarray, " B"] = BLACKBODY_KELVIN,
    daylight: Sequence[float] | Float[np.ndarray, " D"] = DAYLIGHT_KELVIN,
) -> np.ndarray:
    """Blackbody (Planck) and CIE daylight spectra: the smooth lights of the Planckian and
    daylight loci (the default world's measured lights of these two families, without its
    fluorescent, LED and mixed lights).

    A per-light map fitted on these (``fit_camera_map(..., lights=locus_lights())``) maps the
    whites of smooth lights almost exactly, tungsten included, where a map fitted on a world's
    lights blends in the matrices of fluorescent or mixed lights of the same chromaticity, whose
    spectra differ (measured in ``benchmarks/camera_maps.py``).

    Arguments:
        blackbody: temperatures in kelvin of the blackbodies (colour-science's ``sd_blackbody``).
        daylight: correlated colour temperatures of the CIE daylights (``sd_CIE_illuminant_D_series``;
            at least 4000 K, the range of the CIE daylight locus).

    Returns:
        ``(B + D, 101)`` spectra on the ccjax grid (unnormalised: the fit scales each light for
        the source camera).
    """
    import colour  # imported here: colour-science is slow to import and only needed for this

    blackbody = np.atleast_1d(np.asarray(blackbody, np.float64))
    daylight = np.atleast_1d(np.asarray(daylight, np.float64))
    if blackbody.ndim != 1 or np.any(blackbody <= 0):
        raise ValueError(f"blackbody: expected positive temperatures in kelvin, got {blackbody}")
    if daylight.ndim != 1 or np.any((daylight < 4000) | (daylight > 25000)):
        raise ValueError(f"daylight: expected temperatures in [4000, 25000] K (the CIE daylight locus), got {daylight}")
    if blackbody.size + daylight.size < 2:
        raise ValueError("blackbody, daylight: at least two lights in all")
    shape = colour.SpectralShape(380, 780, 4)

    def grid(sd) -> np.ndarray:
        return resample(np.asarray(sd.wavelengths), np.asarray(sd.values), kind="light")

    spectra = [grid(colour.sd_blackbody(kelvin, shape)) for kelvin in blackbody]
    spectra += [grid(colour.sd_CIE_illuminant_D_series(colour.temperature.CCT_to_xy_CIE_D(k))) for k in daylight]
    return np.stack(spectra)
