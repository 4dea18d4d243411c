"""colour-science interoperation: spectral distributions in and out, camera sensitivities as a Camera.

Oracles: closed forms (a linear spectrum resampled linearly stays linear; outside the measured
range a sensor is zero and a reflectance or light holds its edge value) and colour-science's own
interpolation and extrapolation (``SpectralDistribution.align``), an implementation independent of
ccjax's.
"""

import colour
import jaxtyping
import numpy as np
import pytest
from colour.algebra import LinearInterpolator

from ccjax.camera import Camera
from ccjax.spectra import WAVELENGTHS, as_spectra, blackbody, cie_daylight, from_colour, to_colour
from ccjax.world import World

GRID = colour.SpectralShape(380, 780, 4)


def _linear_sd(start=400.0, stop=700.0):
    # Samples every 5 nm of f(lambda) = 0.2 + 0.001 (lambda - 400): linear interpolation is exact.
    wavelengths = np.arange(start, stop + 1e-9, 5.0)
    return colour.SpectralDistribution(0.2 + 0.001 * (wavelengths - 400.0), wavelengths, name="ramp")


def _closed_form(start=400.0, stop=700.0, outside=None):
    inside = 0.2 + 0.001 * (np.clip(WAVELENGTHS, start, stop) - 400.0)
    if outside is None:
        return inside  # edge values held
    return np.where((WAVELENGTHS >= start) & (WAVELENGTHS <= stop), inside, outside)


def test_spectral_distribution_kinds_follow_the_closed_form():
    sd = _linear_sd()
    np.testing.assert_allclose(from_colour(sd, kind="reflectance"), _closed_form(), atol=1e-12)
    np.testing.assert_allclose(from_colour(sd, kind="light"), _closed_form(), atol=1e-12)
    np.testing.assert_allclose(from_colour(sd, kind="sensor"), _closed_form(outside=0.0), atol=1e-12)


def test_the_kind_is_explicit_and_checked():
    with pytest.raises(TypeError, match="kind"):
        from_colour(_linear_sd())  # type: ignore[call-arg]
    # Without the tests' runtime type checks the function's own ValueError names the kinds; with
    # them (pyproject's jaxtyping hook) the Literal annotation refuses it first.
    with pytest.raises((ValueError, jaxtyping.TypeCheckError), match="kind"):
        from_colour(_linear_sd(), kind="paint")  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="distribution"):
        from_colour(np.ones(101), kind="light")


def test_multi_spectral_distributions_match_colour_science_alignment():
    # CIE illuminants on 300-780 nm (5 nm, A) and 380-780 (D65): colour-science aligns them to the
    # ccjax grid with a linear interpolator and its constant (edge-held) extrapolator.
    msds = colour.MultiSpectralDistributions(
        {
            "A": colour.SDS_ILLUMINANTS["A"].copy().align(colour.SpectralShape(360, 830, 5)),
            "D65": colour.SDS_ILLUMINANTS["D65"].copy().align(colour.SpectralShape(360, 830, 5)),
        }
    )
    ours = from_colour(msds, kind="light")
    assert ours.shape == (101, 2)
    for column, label in enumerate(msds.labels):
        reference = colour.SpectralDistribution(msds.signals[label]).align(GRID, interpolator=LinearInterpolator)
        np.testing.assert_allclose(ours[:, column], reference.values, rtol=1e-10)
    # Rows (one light per row) where ccjax stores lights that way.
    np.testing.assert_array_equal(as_spectra(msds, kind="light"), ours.T)
    np.testing.assert_array_equal(as_spectra(ours, kind="light"), ours)


def test_to_colour_round_trip_and_extrapolation():
    values = np.linspace(0.1, 0.9, 101)
    sd = to_colour(values, kind="reflectance", name="grey ramp")
    assert isinstance(sd, colour.SpectralDistribution) and sd.name == "grey ramp"
    np.testing.assert_array_equal(sd.wavelengths, WAVELENGTHS)
    np.testing.assert_array_equal(from_colour(sd, kind="reflectance"), values)
    # colour-science reads outside the grid what ccjax would: edge-held, or zero for a sensor.
    assert sd[300.0] == pytest.approx(0.1) and sd[800.0] == pytest.approx(0.9)
    sensors = to_colour(np.stack([values, values, values], axis=1), kind="sensor", labels=["r", "g", "b"])
    assert isinstance(sensors, colour.MultiSpectralDistributions) and sensors.labels == ["r", "g", "b"]
    np.testing.assert_array_equal(sensors[300.0], 0.0)
    rows = to_colour(np.stack([values, 1 - values]), kind="reflectance")
    np.testing.assert_array_equal(from_colour(rows, kind="reflectance"), np.stack([values, 1 - values], axis=1))
    with pytest.raises(ValueError, match="labels"):
        to_colour(np.stack([values, values]), kind="light", labels=["only one"])
    with pytest.raises(ValueError, match="values"):
        to_colour(np.ones(50), kind="light")


def test_colour_science_camera_sensitivities_as_a_camera():
    nikon = colour.MSDS_CAMERA_SENSITIVITIES["Nikon 5100 (NPL)"]
    camera = Camera.from_colour(nikon)
    assert camera.name == nikon.name and camera.sensors.shape == (101, 3)
    # Oracle: colour-science's own alignment, extrapolating sensors as zero.
    for channel, label in enumerate(nikon.labels):
        reference = colour.SpectralDistribution(nikon.signals[label]).align(
            GRID, interpolator=LinearInterpolator, extrapolator_kwargs={"method": "Constant", "left": 0, "right": 0}
        )
        np.testing.assert_allclose(np.asarray(camera.sensors[:, channel]), reference.values, rtol=1e-6, atol=1e-9)
    # By name, and through from_array; the response of a flat light is the sum of each sensor.
    by_name = Camera.from_colour("Nikon 5100 (NPL)")
    np.testing.assert_array_equal(by_name.sensors, camera.sensors)
    np.testing.assert_array_equal(Camera.from_array(nikon, name="n").sensors, camera.sensors)
    flat = np.asarray(camera.response(np.ones(101)))
    np.testing.assert_allclose(flat, np.asarray(camera.sensors).sum(axis=0), rtol=1e-6)
    # Back to colour-science: the same curves, zero outside the grid.
    back = camera.to_colour()
    assert isinstance(back, colour.characterisation.RGB_CameraSensitivities)
    np.testing.assert_allclose(back.values, np.asarray(camera.sensors), rtol=1e-7)
    np.testing.assert_array_equal(back[370.0], 0.0)


def test_camera_from_colour_refuses_bad_input():
    with pytest.raises(ValueError, match="MSDS_CAMERA_SENSITIVITIES"):
        Camera.from_colour("No Such Camera")
    with pytest.raises(TypeError, match="sensitivities"):
        Camera.from_colour(np.ones((101, 3)))
    two = colour.MultiSpectralDistributions(np.ones((5, 2)), [400, 450, 500, 550, 600], labels=["a", "b"])
    with pytest.raises(ValueError, match="3 channels"):
        Camera.from_colour(two)


def test_world_from_colour_distributions():
    # Reflectances, lights and the canonical light as colour-science objects give the world the
    # same arrays would.
    camera = Camera.from_colour("Nikon 5100 (NPL)")
    names = ["A", "D50", "D65", "FL2", "FL11"]
    shape = colour.SpectralShape(380, 780, 5)
    lights = colour.MultiSpectralDistributions({n: colour.SDS_ILLUMINANTS[n].copy().align(shape) for n in names})
    patches = colour.characterisation.SDS_COLOURCHECKERS["ISO 17321-1"]
    surfaces = colour.MultiSpectralDistributions({n: sd.copy().align(shape) for n, sd in patches.items()})
    canonical = colour.SDS_ILLUMINANTS["D65"]
    common = {"n_priority": 2, "camera": camera, "seed": 0}
    ours = World.from_sources(reflectances=surfaces, sources=lights, canonical=canonical, **common)
    arrays = World.from_sources(
        reflectances=from_colour(surfaces, kind="reflectance").T,
        sources=from_colour(lights, kind="light").T,
        canonical=from_colour(canonical, kind="light"),
        **common,
    )
    assert ours.reflectances.shape == (len(patches), 101)
    for field in ("reflectances", "train_illuminants", "test_illuminants", "canonical"):
        np.testing.assert_array_equal(getattr(ours, field), getattr(arrays, field))


def test_blackbody_is_plancks_law():
    """Planck's law written here: c1 = 2 pi h c^2 over pi sr (radiance), CIE 015:2018's c2, per nm."""
    kelvin = np.array([1500.0, 2856.0, 6500.0, 20000.0])
    metres = WAVELENGTHS[None] * 1e-9
    want = 1e-9 * 3.741771e-16 / np.pi * metres**-5 / np.expm1(1.4388e-2 / (metres * kelvin[:, None]))
    np.testing.assert_allclose(blackbody(kelvin), want, rtol=1e-6)
    for bad in (np.array([0.0, 5000.0]), np.array([-1.0]), np.array([np.nan])):
        with pytest.raises(ValueError, match="kelvin"):
            blackbody(bad)


def test_cie_daylight_at_d65s_temperature_is_the_d65_table():
    """The D series at D65's correlated colour temperature (6504 K) against CIE's tabulated D65
    (the table was computed from the same components with rounded coefficients: within 0.5 %)."""
    d65 = colour.SDS_ILLUMINANTS["D65"]
    table = np.interp(WAVELENGTHS, d65.wavelengths, d65.values)
    np.testing.assert_allclose(cie_daylight(np.array([6504.0]))[0], table, rtol=5e-3)
    assert cie_daylight(np.array([4000.0, 25000.0])).shape == (2, WAVELENGTHS.size)
    for bad in (np.array([3000.0]), np.array([26000.0])):
        with pytest.raises(ValueError, match="4000-25000 K"):
            cie_daylight(bad)
