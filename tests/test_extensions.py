"""The canonical-gamut extensions SP, MET and FL (Barnard 1999 ch. 7-9) and their labels.

Oracles: the extended point sets are rebuilt here from the spec (spec ch08-12 §1.7.5-1.7.6, §2.3)
with plain loops over the representative lights, their hull with the origin by SciPy's Qhull, and
the fitted model's facets are compared with it (same polytope: every oracle point inside, every
oracle vertex on the boundary, equal volume). Fact (b) of spec ch08-12 §1.8 is a closed form.
"""

from __future__ import annotations

import equinox as eqx
import jax
import numpy as np
import pytest
from scipy.spatial import ConvexHull, HalfspaceIntersection

from ccjax.estimators import gamut, registry
from ccjax.estimators.gamut import _extensions
from ccjax.estimators.gamut._extensions import Extension
from ccjax.runs import store

K = 8.0


def _oracle_points(world, diagonal: bool, specular: bool, metals=None, fluorescent=None, k=K) -> np.ndarray:
    """Spec ch08-12 §2.3 / ch05-07 §4.2 as loops: for the canonical light (and, with ND/FL, every
    training light) the database RGBs, plus k x white (SP/MET), k x each metal (MET), the
    fluorescent RGBs (FL), all mapped white-to-white into the canonical light."""
    sensors = np.asarray(world.camera.sensors, np.float64)
    reflectances = np.asarray(world.reflectances, np.float64)
    canonical = np.asarray(world.canonical, np.float64)
    white_c = canonical @ sensors
    lights = [canonical] + (list(np.asarray(world.train_illuminants, np.float64)) if diagonal else [])
    blocks = []
    for light in lights:
        white = light @ sensors
        block = [(reflectances * light) @ sensors]
        if specular:
            block.append(k * white[None])
        if metals is not None:
            block.append(k * (metals * light) @ sensors)
        if fluorescent is not None:
            block.append(fluorescent(light[None], sensors)[0])
        blocks.append(np.vstack(block) * (white_c / white))
    return np.vstack(blocks)


def _volume_of_facets(model) -> float:
    normals = np.vstack([np.asarray(model.origin_normals), np.asarray(model.top_normals)]).astype(np.float64)
    offsets = np.concatenate([np.zeros(len(model.origin_normals)), np.asarray(model.top_offsets, np.float64)])
    interior = 1e-3 * np.asarray(model.white, np.float64)  # just inside, near the origin's apex
    vertices = HalfspaceIntersection(np.hstack([normals, -offsets[:, None]]), interior).intersections
    return ConvexHull(vertices).volume


def _check_same_polytope(model, points: np.ndarray) -> None:
    hull = ConvexHull(np.vstack([np.zeros(3), points]))
    top_n = np.asarray(model.top_normals, np.float64)
    top_c = np.asarray(model.top_offsets, np.float64)
    origin_n = np.asarray(model.origin_normals, np.float64)
    scale = float(np.max(points))
    # Every oracle point inside the model's polytope (float32 facets: relative 1e-5).
    assert np.all(points @ top_n.T <= top_c + 1e-5 * scale)
    assert np.all(points @ origin_n.T <= 1e-5 * scale)
    # Every oracle vertex on the model's boundary (some facet tight).
    vertices = hull.points[hull.vertices]
    slack = np.minimum(
        np.min(np.abs(vertices @ top_n.T - top_c), axis=1), np.min(np.abs(vertices @ origin_n.T), axis=1)
    )
    assert np.all(slack <= 1e-5 * scale)
    np.testing.assert_allclose(_volume_of_facets(model), hull.volume, rtol=1e-4)


@pytest.mark.parametrize("extension", ["SP", "SP-ND", "SP2", "SP4-ND"])
def test_specular_gamuts_are_the_qhull_of_the_extended_points(default_world, extension):
    parsed = Extension.parse(extension)
    model = gamut.fit(default_world, constraint="CRULE", extension=extension)
    points = _oracle_points(default_world, parsed.diagonal == "ND", True, k=parsed.multiplier)
    _check_same_polytope(model, points)
    # SP only stretches the white apex: the origin facets (chromaticity feasibility) are the
    # matte gamut's, and k x white is a vertex.
    base = gamut.fit(default_world, constraint="CRULE", extension=parsed.diagonal)
    assert model.origin_normals.shape == base.origin_normals.shape
    np.testing.assert_allclose(
        np.sort(np.asarray(model.origin_normals), 0), np.sort(np.asarray(base.origin_normals), 0)
    )
    apex = parsed.multiplier * np.asarray(default_world.canonical_white, np.float64)
    assert np.min(np.abs(np.asarray(model.top_normals, np.float64) @ apex - np.asarray(model.top_offsets))) < 1e-5


def test_metallic_gamut_is_the_qhull_of_the_extended_points(default_world):
    metals = _extensions.default_metals()
    assert metals.shape == (3, 101)
    np.testing.assert_allclose(metals.mean(axis=1), 1.0, rtol=1e-6)  # unit mean (A10)
    for extension, diagonal in (("MET", False), ("MET-ND", True)):
        model = gamut.fit(default_world, constraint="ECRULE", extension=extension)
        _check_same_polytope(model, _oracle_points(default_world, diagonal, True, metals=metals))
    # MET contains SP (it keeps the white specular point) and adds coloured points.
    sp = gamut.fit(default_world, constraint="ECRULE", extension="SP")
    met = gamut.fit(default_world, constraint="ECRULE", extension="MET")
    assert _volume_of_facets(met) > _volume_of_facets(sp)


def test_fluorescent_gamut_adds_the_fluorescent_points_to_nd(default_world):
    rng = np.random.default_rng(0)
    emitted = rng.uniform(0.0, 0.6, (3, 101))  # a fake "measured" set: fixed spectra per light

    def fluorescent(lights, sensors):
        return np.einsum("fl,il,lc->ifc", emitted, lights, sensors) * 1.3  # brighter than any reflectance

    model = gamut.fit(default_world, constraint="CRULE", extension="FL", fluorescent=fluorescent)
    _check_same_polytope(model, _oracle_points(default_world, True, False, fluorescent=fluorescent))
    model = gamut.fit(default_world, constraint="CRULE", extension="SP-FL", fluorescent=fluorescent)
    _check_same_polytope(model, _oracle_points(default_world, True, True, fluorescent=fluorescent))


def test_characterised_responses_are_balanced_by_the_approximated_lights_white(default_world):
    # A grey reflective "fluorescent" surface (reflectance 0.7, no emission) characterised from the
    # measurement lights is predicted as 0.7 Ê (§7.1); balanced by Ê's own white, its FL gamut
    # point under every light is 0.7 times the canonical white exactly (closed form), whatever the
    # light approximation's error (balanced by the true light's white it is off by that error).
    from ccjax import materials

    grey = materials.FluorescentSurfaces(
        names=("grey",), reflectance=jax.numpy.full((1, 101), 0.7), emission=jax.numpy.zeros((1, 101, 101))
    )
    blocks = _extensions.light_blocks(
        default_world, Extension.parse("FL"), fluorescent=_extensions.default_fluorescent(default_world, grey)
    )
    white = np.asarray(default_world.canonical, np.float64) @ np.asarray(default_world.camera.sensors, np.float64)
    assert len(blocks) == 1 + len(default_world.train_illuminants)
    np.testing.assert_allclose(np.concatenate(blocks), np.broadcast_to(0.7 * white, (len(blocks), 3)), rtol=1e-5)


@pytest.mark.parametrize("constraint,extension", [("CRULE", "SP"), ("CRULE", "SP4-ND")])
def test_fact_b_a_single_specular_pixel_gives_its_light(default_world, constraint, extension):
    """Spec ch08-12 §1.8 fact (b): k w_C is the maximum-product point of the SP gamut, so one
    observed pixel k e gives MV = e exactly (chromaticity and brightness), up to the MV
    refinement between grid directions: the apex k w_C is a sharp vertex, so T(u) falls steeply
    off its direction and a (r,g) offset of 1e-5 costs up to ~0.5 % of brightness."""
    k = Extension.parse(extension).multiplier
    model = gamut.fit(default_world, constraint=constraint, extension=extension)
    lights = np.asarray(default_world.test_whites, np.float64)[::25]
    rgb = (k * lights[:, None, :]).astype(np.float32)
    out = eqx.filter_jit(lambda m, r, q: jax.vmap(m)(r, q))(
        gamut.GamutMapping(model, "MV"), rgb, np.ones(rgb.shape[:2], bool)
    )
    estimate = np.asarray(out.illuminant, np.float64)
    rg = lambda x: x[:, :2] / x.sum(axis=1, keepdims=True)
    assert np.max(np.abs(rg(estimate) - rg(lights))) < 1e-4
    np.testing.assert_allclose(estimate, lights, rtol=6e-3)
    assert np.all(np.asarray(out.ok))


def test_extension_parsing_and_labels(default_world):
    assert Extension.parse("SP-ND") == Extension(diagonal="ND", specular="SP")
    assert Extension.parse(("MET", "FL")).label == "MET-FL"
    assert Extension.parse("SP4").multiplier == 4.0 and Extension.parse("SP4").label == "SP4"
    assert Extension.parse(None).label is None and Extension.parse("ND").label == "ND"
    for bad, message in (("ND-FL", "FL already is ND"), ("SP-MET", "MET includes SP"), ("XY", "unknown part")):
        with pytest.raises(ValueError, match=message):
            Extension.parse(bad)
    with pytest.raises(ValueError, match="multiplier"):
        Extension.parse("ND4")
    cases = {
        "SP-ECRULE-MV": "SP",
        "SP-ND-ECRULE-ICA": "SP-ND",
        "SP-ND-ECRULE-MV": "SP-ND",
        "SP2-CRULE-AVE": "SP2",
        "MET-ND-ECRULE-SCWIA-6": "MET-ND",
        "MET4-ECRULE-ICA": "MET4",
        "ND-ECRULE-MV": "ND",
    }
    for label, extension in cases.items():
        estimator = registry.fit(label, default_world)
        assert estimator.model.extension == extension, label
    assert registry.fit("MET-ND-ECRULE-SCWIA-6", default_world).power == 6.0
    for label in ("SP-FL-ECRULE-SCWIA-6", "MET-FL-ECRULE-ICA", "FL-ECRULE-MV", "FL-CRULE-AVE"):
        entry, _ = registry.lookup(label)
        assert "FL" in entry.grammar or "(SP|MET)" in entry.grammar, label
    for label in ("ND-SP-ECRULE-MV", "FL-ND-ECRULE-MV", "SP-MET-ECRULE-MV"):
        with pytest.raises(ValueError, match="unknown label"):
            registry.lookup(label)
    with pytest.raises(ValueError, match="ICA"):
        registry.fit("SP-CRULE-ICA", default_world)


@pytest.mark.slow
def test_extended_estimates_are_finite_on_degenerate_scenes(default_world):
    from ccjax.estimators.base import Status

    model = store.fit("MET-ND-ECRULE-SCWIA-6", default_world)
    assert store.fit("MET-ND-ECRULE-SCWIA-6", default_world) is model
    rgb = np.zeros((4, 8, 3), np.float32)
    mask = np.ones((4, 8), bool)
    rgb[1] = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0]] * 2, np.float32) * 0.5  # no diagonal map
    rgb[2, :, :] = 1e6  # far beyond any specular multiplier
    mask[3] = False
    out = jax.vmap(model)(rgb, mask)
    assert np.all(np.isfinite(np.asarray(out.illuminant)))
    assert not bool(out.ok[0]) and not bool(out.ok[3])
    assert int(out.status[0]) == int(out.status[3]) == Status.NO_DATA


@pytest.mark.slow
def test_chapter8_columns_reuse_the_chapter4_scenes(default_world):
    """Table 8.2's columns 1-3 are Tables 4.2, 4.3 and 4.4 (clip 300) on the same scene draws (§8.3),
    so their cells agree to 1e-6 for the same key."""
    from ccjax import experiments

    key, methods = jax.random.key(3), ["GW", "RETINEX"]
    ours = {
        (r["method"], r["column"]): r["ours"]
        for r in experiments.reproduce("8.2", default_world, methods, 24, key, progress=False).rows
    }
    chapter4 = {}
    for table, column in (("4.2", "rg"), ("4.3", "rg"), ("4.4", "rg@300")):
        for r in experiments.reproduce(table, default_world, methods, 24, key, progress=False).rows:
            if r["column"] == column:
                chapter4[(r["method"], table)] = r["ours"]
    for method in methods:
        for table, column in (("4.2", "rg@matte"), ("4.3", "rg@spec"), ("4.4", "rg@spec+clip")):
            np.testing.assert_allclose(ours[(method, column)], chapter4[(method, table)], rtol=1e-6)
    # The metallic columns are other scenes (highlights coloured by metals): different numbers.
    assert abs(ours[("GW", "rg@metal")] - ours[("GW", "rg@spec")]) > 1e-4


def test_claims_print_ok_or_miss():
    from ccjax.experiments.table_protocols import check_claim

    ours = {("A", "c"): 0.04, ("B", "c"): 0.05, ("ECRULE-MV", "c"): 0.045, ("X-ECRULE-ICA", "c"): 0.03}
    assert check_claim(("less", "A", "B", "c"), ours).endswith(": ok")
    assert check_claim(("less", "B", "A", "c"), ours).endswith(": MISS")
    assert check_claim(("ratio", "B", "A", "c", 1.15), ours).endswith(": MISS")  # 1.25 > 1.15
    assert check_claim(("ratio", "B", "A", "c", 1.3), ours).endswith(": ok")
    assert check_claim(("best", ("X-ECRULE-ICA",), "gamut", "c"), ours).endswith(": ok")
    assert check_claim(("best", ("ECRULE-MV",), "gamut", "c"), ours).endswith(": MISS")
    assert check_claim(("less", "A", "missing", "c"), ours) is None
    spread = {("S", f"k{i}"): v for i, v in enumerate((100.0, 140.0, 120.0))}
    assert check_claim(("spread", "S", ("k0", "k1", "k2"), 1.0, 1.5), spread).endswith("1.40 in [1, 1.5]: ok")
    assert check_claim(("spread", "S", ("k0", "k1", "k2"), 3.0, float("inf")), spread).endswith(">= 3: MISS")
