"""Materials (Barnard 1999 ch. 7–8): metal reflectances from (n, k), synthetic fluorescent surfaces
and the thesis' NNLS characterisation."""

import math

import jax
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ccjax import materials
from ccjax.spectra import WAVELENGTHS

# -- Fresnel -----------------------------------------------------------------------------------


@given(st.floats(0.05, 10.0), st.floats(0.0, 20.0))
@settings(max_examples=50, deadline=None)
def test_fresnel_matches_the_complex_amplitude(n, k):
    """R = |r|^2 with the complex amplitude r = (N - 1) / (N + 1), N = n + ik (an independent form)."""
    index = complex(n, k)
    want = abs((index - 1) / (index + 1)) ** 2
    assert float(materials.fresnel_reflectance(n, k)) == pytest.approx(want, rel=1e-5, abs=1e-7)


@pytest.mark.parametrize("n", [1.0, 1.33, 1.5, 2.4])
def test_fresnel_dielectric_limit(n):
    """k = 0: the dielectric ((n-1)/(n+1))^2 (glass 1.5 -> 0.04, water 1.33 -> 0.020)."""
    assert float(materials.fresnel_reflectance(n, 0.0)) == pytest.approx(((n - 1) / (n + 1)) ** 2, rel=1e-6, abs=1e-9)


def test_fresnel_perfect_conductor_limit():
    """k -> infinity: every metal becomes a perfect mirror, 1 - R = 4n / k^2 + O(k^-4)."""
    k = np.array([1.0, 10.0, 100.0, 1e3])
    values = np.asarray(materials.fresnel_reflectance(np.full(4, 0.5), k))
    assert np.all(np.diff(values) > 0) and np.all(values[:3] < 1)
    np.testing.assert_allclose(1 - values[2:], 4 * 0.5 / k[2:] ** 2, rtol=2e-2)


# -- metal spectra -------------------------------------------------------------------------------


def test_metal_spectra_are_reflectances_and_unit_mean():
    absolute = materials.metal_spectra(unit_mean=False)
    assert absolute.shape == (len(materials.METALS), WAVELENGTHS.size)
    assert np.all(absolute > 0) and np.all(absolute < 1)
    scaled = materials.metal_spectra()
    np.testing.assert_allclose(scaled.mean(axis=1), 1.0, rtol=1e-12)
    np.testing.assert_allclose(scaled / absolute, scaled[:, :1] / absolute[:, :1] * np.ones_like(scaled), rtol=1e-12)
    assert set(materials.COLOURED_METALS) | set(materials.GREY_METALS) == set(materials.METALS)


# Independent measurements: K. M. McPeak et al., "Plasmonic films can easily be better: rules and
# recipes", ACS Photonics 2, 326-333 (2015), (n, k) at 450 / 550 / 650 nm as tabulated in the
# refractiveindex.info database (main/{Au,Ag,Al}/nk/McPeak.yml). The embedded tables are other
# papers' (Johnson & Christy 1972, Rakić 1995), so this compares two measurements of each metal.
_MCPEAK = {
    "gold": {450: (1.538326354, 1.910745397), 650: (0.125499436, 3.792327795)},
    "silver": {
        450: (0.040932342, 2.675756988),
        550: (0.043817181, 3.610113564),
        650: (0.05091337, 4.460223332),
    },
    "aluminium": {
        450: (0.489220122, 4.778319404),
        550: (0.789405353, 5.851936501),
        650: (1.246364405, 6.852329839),
    },
}


@pytest.mark.parametrize("metal", sorted(_MCPEAK))
def test_metal_reflectance_matches_independent_measurements(metal):
    ours = materials.metal_reflectance(metal)
    for wavelength, (n, k) in _MCPEAK[metal].items():
        published = ((n - 1) ** 2 + k**2) / ((n + 1) ** 2 + k**2)
        index = int(np.flatnonzero(WAVELENGTHS == wavelength - 2)[0])  # 448, 548, 648 nm: mean of the two
        value = 0.5 * (ours[index] + ours[index + 1])
        assert value == pytest.approx(published, abs=0.03), (metal, wavelength)


def test_metal_colours():
    """Gold and copper reflect red far more than blue; silver and aluminium are flat (grey)."""
    r = {name: materials.metal_reflectance(name) for name in materials.METALS}
    at = lambda name, nm: r[name][int(np.flatnonzero(WAVELENGTHS == nm)[0])]
    for name in ("gold", "copper", "brass"):
        assert at(name, 652) > 1.5 * at(name, 452)
    for name in ("silver", "aluminium", "steel"):
        assert abs(at(name, 652) / at(name, 452) - 1) < 0.15


def test_metal_errors():
    with pytest.raises(ValueError, match="unknown metal 'tin'"):
        materials.metal_reflectance("tin")
    with pytest.raises(ValueError, match="names"):
        materials.metal_spectra(())


# -- fluorescent model ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def surfaces():
    return materials.synthetic_fluorescent_surfaces()


def test_emission_is_stokes_shifted_and_conserves_photons(surfaces):
    emission = np.asarray(surfaces.emission, dtype=np.float64)
    assert emission.shape == (9, 101, 101) and np.all(emission >= 0)
    # Re-emission only at strictly longer wavelengths: upper triangle and diagonal are zero.
    assert np.all(np.triu(emission) == 0)
    # A monochromatic light at λ_j: emitted photons = q * absorbed photons (closed form of the model).
    for params, matrix, rho in zip(materials.FLUORESCENT_SURFACES, emission, np.asarray(surfaces.reflectance)):
        sigma = params.excitation_fwhm / (2 * math.sqrt(2 * math.log(2)))
        absorbed = params.absorptance * np.exp(-0.5 * ((WAVELENGTHS - params.excitation_centre) / sigma) ** 2)
        np.testing.assert_allclose(rho, params.substrate * (1 - absorbed), rtol=1e-5)
        j = int(np.argmin(np.abs(WAVELENGTHS - params.excitation_centre)))
        photons_out = np.sum(matrix[:, j] * WAVELENGTHS)
        assert photons_out == pytest.approx(params.quantum_yield * absorbed[j] * WAVELENGTHS[j], rel=1e-4)


def test_fluorescent_surfaces_glow(surfaces):
    """Under an equal-energy light each surface's emitted light peaks within 8 nm of its emission
    centre and outshines its reflected light there; most surfaces reflect more than they receive
    at that wavelength (radiance factor above 1)."""
    factor = np.asarray(surfaces.total_radiance_factor(np.ones(101)), dtype=np.float64)
    reflected = np.asarray(surfaces.reflectance, dtype=np.float64)
    emitted = factor - reflected
    glowing = 0
    for params, total, rho, light in zip(materials.FLUORESCENT_SURFACES, factor, reflected, emitted):
        assert abs(WAVELENGTHS[light.argmax()] - params.emission_centre) <= 8
        centre = int(np.argmin(np.abs(WAVELENGTHS - params.emission_centre)))
        assert light[centre] > rho[centre]
        glowing += total[centre] > 1.0
    assert glowing >= len(materials.FLUORESCENT_SURFACES) - 1


def test_fluorescent_parameters_are_validated():
    with pytest.raises(ValueError, match="quantum_yield"):
        materials.FluorescentParameters("x", 450.0, 50.0, 520.0, 40.0, 1.5, 0.9, 0.8)
    with pytest.raises(ValueError, match="emission_fwhm"):
        materials.FluorescentParameters("x", 450.0, 50.0, 520.0, float("nan"), 0.5, 0.9, 0.8)


# -- characterisation (§7.1) --------------------------------------------------------------------


def _lights(count: int, seed: int = 0) -> np.ndarray:
    """Smooth positive test lights: a blackbody-like ramp times random broad bumps."""
    rng = np.random.default_rng(seed)
    x = (WAVELENGTHS - 380) / 400
    rows = []
    for _ in range(count):
        slope, centre, width = rng.uniform(-1, 1), rng.uniform(0, 1), rng.uniform(0.1, 0.5)
        rows.append(np.exp(slope * x) * (0.3 + np.exp(-0.5 * ((x - centre) / width) ** 2)))
    return np.stack(rows)


_LIGHTS = _lights(11)


@given(st.lists(st.one_of(st.just(0.0), st.floats(0.01, 5.0)), min_size=11, max_size=11))
@settings(max_examples=25, deadline=None)
def test_characterisation_is_exact_inside_the_cone_of_its_lights(alpha):
    """A light in the non-negative span of the measurement lights is predicted exactly (linearity)."""
    model = materials.synthetic_fluorescent_surfaces()
    characterisation = materials.characterise(model, _LIGHTS)
    light = np.asarray(alpha) @ _LIGHTS + (1e-3 if not any(alpha) else 0.0) * _LIGHTS[0]
    predicted = np.asarray(characterisation.radiance(light), dtype=np.float64)
    truth = np.asarray(model.radiance(light), dtype=np.float64)
    np.testing.assert_allclose(predicted, truth, rtol=2e-4, atol=1e-6 * truth.max())


def test_a_reflective_surface_is_predicted_as_its_reflectance_times_the_approximated_light():
    """§7.1's model has no separate reflective part: for a non-fluorescent surface ``s`` it predicts
    ``s * (Σ α_k E_k)``, so its error is exactly the NNLS approximation error of the light itself
    (why a white surface costs 0.046 in (r,g) from the 11 lab lights: the light, not the fit)."""
    from scipy.optimize import nnls

    reflectance = 0.2 + 0.6 * np.exp(-0.5 * ((WAVELENGTHS - 520) / 60) ** 2)
    surface = materials.FluorescentSurfaces(
        names=("matte",),
        reflectance=jax.numpy.asarray(reflectance[None]),
        emission=jax.numpy.zeros((1, WAVELENGTHS.size, WAVELENGTHS.size)),
    )
    targets = _lights(6, seed=3)
    predicted = np.asarray(materials.characterise(surface, _LIGHTS).radiance(targets), np.float64)[:, 0]
    approximated = np.stack([nnls(_LIGHTS.T, target)[0] @ _LIGHTS for target in targets])  # SciPy oracle
    np.testing.assert_allclose(predicted, reflectance * approximated, rtol=1e-4, atol=1e-6 * predicted.max())
    assert np.max(np.abs(approximated - targets)) > 1e-3  # the lights are outside the cone: not trivially exact


def test_nnls_weights_satisfy_the_optimality_conditions():
    """KKT of min ||E - a L||, a >= 0: gradient zero on the support, non-negative off it."""
    targets = _lights(20, seed=5)
    weights = materials.nnls_weights(_LIGHTS, targets)
    assert weights.shape == (20, 11) and np.all(weights >= 0)
    gradient = (weights @ _LIGHTS - targets) @ _LIGHTS.T
    scale = np.linalg.norm(targets, axis=1, keepdims=True) * np.linalg.norm(_LIGHTS, axis=1)[None]
    assert np.all(np.abs(np.where(weights > 1e-9, gradient, 0.0)) <= 1e-6 * scale)
    assert np.all(np.where(weights <= 1e-9, gradient, 0.0) >= -1e-6 * scale)


def test_prediction_error(surfaces):
    sensors = np.stack([np.exp(-0.5 * ((WAVELENGTHS - c) / 30) ** 2) for c in (600, 540, 450)], axis=1)
    characterisation = materials.characterise(surfaces, _LIGHTS)
    inside = np.random.default_rng(1).uniform(0, 1, (5, 11)) @ _LIGHTS
    outside = _lights(30, seed=9)
    exact = materials.prediction_error(surfaces, characterisation, np.concatenate([inside, _LIGHTS]), sensors)
    assert exact.n_lights == 5  # the measurement lights themselves are dropped
    assert np.all(exact.rg < 1e-5) and np.all(exact.rgb < 1e-4)
    other = materials.prediction_error(surfaces, characterisation, outside, sensors)
    assert other.n_lights == 30 and np.all(other.spectral > 1e-4) and np.all(np.isfinite(other.rg))
    assert [row["surface"] for row in other.rows()] == list(surfaces.names)
    with pytest.raises(ValueError, match="no light left"):
        materials.prediction_error(surfaces, characterisation, _LIGHTS, sensors)
    with pytest.raises(ValueError, match="lights"):
        materials.characterise(surfaces, -_LIGHTS)


@pytest.mark.external_data
def test_lab_lights_are_the_eleven_sfu_lab_sources():
    lights = materials.lab_lights()
    assert lights.shape == (11, 101) and np.all(lights >= 0) and np.all(lights.max(axis=1) > 0)


def test_fluorescent_weights():
    """50x each of 9 surfaces against 1995 reflectances: 450 / 2445 of occurrences (A20)."""
    default = materials.fluorescent_weights(1995)
    assert default.fluorescent == 50.0 and default.fraction == pytest.approx(450 / 2445)
    matched = materials.fluorescent_weights(1995, 9, fraction=0.15)
    assert matched.fraction == pytest.approx(0.15)
    assert matched.fluorescent == pytest.approx(0.15 * 1995 / (0.85 * 9))
    for bad in ({"fraction": 1.0}, {"multiplier": -1.0}, {"multiplier": None}):
        with pytest.raises(ValueError):
            materials.fluorescent_weights(1995, **bad)  # pyright: ignore[reportArgumentType]  (bad input on purpose)


def test_models_are_pytrees(surfaces):
    """Both radiance models pass through jit (the physical one) and tree utilities."""
    light = _LIGHTS[3]
    jitted = jax.jit(lambda model, e: model.radiance(e))(surfaces, light)
    np.testing.assert_allclose(np.asarray(jitted), np.asarray(surfaces.radiance(light)), rtol=1e-6)
    characterisation = materials.characterise(surfaces, _LIGHTS)
    assert len(jax.tree_util.tree_leaves(characterisation)) == 2
