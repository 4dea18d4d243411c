"""Tests of 3-D gamut mapping (ccjax.estimators.gamut) against the SciPy oracle in
``tests/gamut_oracle.py`` (exact polytope centroid, convex MV optimum, fine direction quadrature),
LP ray extents, the exact fact (a) of spec ch08-12 §1.8, thesis-level properties and degenerate
input. The default suite compiles two all-selector kernels (CRULE, ECRULE at 8 surfaces) and
reuses them; the 200-scene oracle comparisons are marked slow.
"""

from __future__ import annotations

import equinox as eqx
import gamut_oracle as oracle
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import linprog

from ccjax import metrics
from ccjax.estimators import gamut, registry
from ccjax.estimators.base import AbstractSurfaceEstimator, Estimate, Status, estimate_batch
from ccjax.estimators.gamut import _constraints_3d, _engine, _relaxation
from ccjax.scenes import sample

SELECTORS_E = ("MV", "AVE", "ICA", "SCWIA-12")


# ---------------------------------------------------------------------------------------------
# fixtures


@pytest.fixture(scope="module")
def models(default_world):
    return {
        (c, e): gamut.fit(default_world, constraint=c, extension=e) for c in ("CRULE", "ECRULE") for e in (None, "ND")
    }


_BATCH = 16


def _runner(powers=(12,)):
    """All selectors of a model on a batch of scenes, in chunks of ``_BATCH`` scenes so that one
    compilation per (model, surfaces) serves every test."""
    compiled = eqx.filter_jit(lambda m, r, k: jax.vmap(lambda a, b: gamut.estimate_all(m, a, b, powers=powers))(r, k))

    def run(model, rgb, mask):
        rgb, mask = np.asarray(rgb, np.float32), np.asarray(mask, bool)
        count = rgb.shape[0]
        pad = -count % _BATCH
        rgb = np.concatenate([rgb, np.repeat(rgb[:1], pad, axis=0)])
        mask = np.concatenate([mask, np.repeat(mask[:1], pad, axis=0)])
        chunks = [compiled(model, rgb[i : i + _BATCH], mask[i : i + _BATCH]) for i in range(0, len(rgb), _BATCH)]
        return jax.tree_util.tree_map(lambda *x: np.concatenate(x)[:count], *chunks)

    return run


@pytest.fixture(scope="module")
def run_all():
    """One compiled all-selector kernel per (model, scene shape), shared by the tests."""
    return _runner()


@pytest.fixture(scope="module")
def reference(default_world):
    """The oracle's view of the world: canonical gamut halfspaces, white, illuminant polygon."""
    points = np.asarray(default_world.canonical_rgb, np.float64)
    return {
        None: oracle.hull_halfspaces(points),
        "ND": oracle.hull_halfspaces(gamut._model.canonical_points(default_world, "ND")),
        "white": np.asarray(default_world.canonical_white, np.float64),
        "polygon": oracle.illuminant_polygon(np.asarray(default_world.train_whites)),
        "cone": oracle.map_cone_halfspaces(
            np.asarray(default_world.train_whites), np.asarray(default_world.canonical_white)
        ),
    }


def _chroma(e):
    e = np.asarray(e, np.float64)
    return e[..., :2] / e.sum(axis=-1, keepdims=True)


def _crule_errors(out, scenes, ref, extension=None):
    """Per non-empty scene: AVE centroid error |c - c*|/|c*| and MV product shortfall 1 - prod/prod*."""
    A, b = ref[extension]
    white = ref["white"]
    ave, mv = [], []
    for s in range(scenes.rgb.shape[0]):
        Ad, bd = oracle.scene_constraints(A, b, np.asarray(scenes.rgb[s], np.float64)[np.asarray(scenes.mask[s])])
        poly = oracle.polytope(Ad, bd)
        if poly is None:
            continue
        centroid = white / np.asarray(out["AVE"].illuminant[s], np.float64)
        ave.append(np.linalg.norm(centroid - poly.centroid) / np.linalg.norm(poly.centroid))
        best = oracle.max_log_product(poly)
        mv.append(1.0 - np.prod(white / np.asarray(out["MV"].illuminant[s], np.float64)) / np.prod(best))
    return np.array(ave), np.array(mv)


def _ecrule_errors(out, scenes, ref, step=2e-3):
    """Per scene with a non-empty exact ECRULE set: (r,g) distance of ICA and SCWIA-12 to the
    fine direction quadrature."""
    A, b = ref[None]
    white = ref["white"]
    ica, scwia = [], []
    for s in range(scenes.rgb.shape[0]):
        Ad, bd = oracle.scene_constraints(A, b, np.asarray(scenes.rgb[s], np.float64))
        poly = oracle.polytope(Ad, bd)
        if poly is None:
            continue
        rg, extent = oracle.direction_quadrature(poly, white, ref["polygon"], step=step)
        if np.count_nonzero(extent) < 20:  # empty (or below the quadrature's resolution)
            continue
        e = white / oracle.centroid_by_directions(rg, extent, white)
        ica.append(np.linalg.norm(_chroma(out["ICA"].illuminant[s]) - _chroma(e)))
        scwia.append(
            np.linalg.norm(_chroma(out["SCWIA-12"].illuminant[s]) - oracle.scwia_by_directions(rg, extent, white, 12))
        )
    return np.array(ica), np.array(scwia)


# ---------------------------------------------------------------------------------------------
# geometry


def test_canonical_gamut_facets_are_qhulls(default_world):
    points = np.asarray(default_world.canonical_rgb, np.float64)
    facets = gamut.gamut_facets(points)
    A, b = oracle.hull_halfspaces(points)
    # Every database RGB and the origin satisfy every facet; the facet count is Qhull's.
    assert np.all(points @ facets.top_normals.T <= facets.top_offsets + 1e-9)
    assert np.all(points @ facets.origin_normals.T <= 1e-9)
    assert len(facets.origin_normals) + len(facets.top_normals) == len(
        np.unique(np.round(np.hstack([A, b[:, None]]), 9), axis=0)
    )
    # Origin facets are exactly those of Qhull's planes with (numerically) zero offset.
    assert len(facets.origin_normals) == np.count_nonzero(np.abs(b) < 1e-12)
    assert np.all(facets.top_offsets > 0)


def test_nd_gamut_contains_every_white_balanced_training_gamut(default_world, models):
    model = models[("CRULE", "ND")]
    sensors = np.asarray(default_world.camera.sensors, np.float64)
    white = np.asarray(default_world.canonical_white, np.float64)
    for light in np.asarray(default_world.train_illuminants, np.float64)[::10]:
        mapped = ((np.asarray(default_world.reflectances) * light) @ sensors) * (white / (light @ sensors))
        assert np.all(mapped @ np.asarray(model.top_normals, np.float64).T <= np.asarray(model.top_offsets) + 1e-5)
        assert np.all(mapped @ np.asarray(model.origin_normals, np.float64).T <= 1e-6)


def test_illuminant_cone_contains_training_whites_only(default_world):
    whites = np.asarray(default_world.train_whites, np.float64)
    planes = gamut.cone_planes(whites)
    assert np.all(gamut._geometry.cone_violation(planes, whites) <= 1e-9)
    outside = np.array([[1.0, 0.05, 0.05], [0.05, 1.0, 0.05], [0.05, 0.05, 1.0]])
    assert np.all(gamut._geometry.cone_violation(planes, outside) > 0.05)
    # Agrees with the oracle's (r,g) polygon test on random chromaticities.
    rng = np.random.default_rng(0)
    rg = rng.uniform(0.05, 0.6, (500, 2))
    rg = rg[rg.sum(axis=1) < 0.95]
    inside_cone = gamut._geometry.cone_violation(planes, np.column_stack([rg, 1 - rg.sum(axis=1)])) <= 0
    assert np.array_equal(inside_cone, oracle.in_polygon(oracle.illuminant_polygon(whites), rg))


def test_ray_extent_matches_linear_programs(default_world, models, reference):
    """T(u) of the kernel equals the LP max t s.t. t m(u) feasible (spec ch08-12 §9.5 ii)."""
    model = models[("CRULE", None)]
    scenes = sample(jax.random.key(3), default_world, 1, 6)
    rgb, mask = scenes.rgb[0], scenes.mask[0]
    obs, _, _ = _constraints_3d.observations(model, rgb, mask)
    A, b = reference[None]
    Ad, bd = oracle.scene_constraints(A, b, np.asarray(rgb, np.float64))
    white = reference["white"]
    rg = np.random.default_rng(1).uniform(0.15, 0.45, (40, 2))
    u, v, _ = _engine.directions(jnp.asarray(rg, jnp.float32))
    feasible = np.asarray(_constraints_3d.surface_violation(v, obs)) <= 0
    extent = 1.0 / np.asarray(_constraints_3d.inverse_extent(v, obs), np.float64)
    for i in range(len(rg)):
        m = white / np.asarray(u[i], np.float64)
        t_lp = linprog(-1.0, A_ub=(Ad @ m)[:, None], b_ub=bd, bounds=[(0, None)], method="highs").x[0]
        if feasible[i]:
            assert extent[i] == pytest.approx(t_lp, rel=1e-5)
        else:
            assert t_lp < 1e-9  # an infeasible direction admits only the zero map
    assert np.count_nonzero(feasible) >= 5


# ---------------------------------------------------------------------------------------------
# against the exact oracle (fast part; the 200-scene comparisons are marked slow below)


def test_crule_matches_exact_oracle_on_a_few_scenes(default_world, models, reference, run_all):
    scenes = sample(jax.random.key(21), default_world, 16, 8)
    out = run_all(models[("CRULE", None)], scenes.rgb, scenes.mask)
    ave, mv = _crule_errors(out, scenes, reference)
    print(
        f"CRULE 8 surfaces: {len(ave)} non-empty scenes; AVE median {np.median(ave):.2e}; MV median {np.median(mv):.2e}"
    )
    assert len(ave) >= 12
    assert np.median(ave) < 0.005
    assert np.median(np.abs(mv)) < 0.005
    assert np.min(mv) > -1e-4  # never above the exact optimum (would mean an infeasible map)


def test_ecrule_ica_scwia_match_quadrature_on_a_few_scenes(default_world, models, reference, run_all):
    scenes = sample(jax.random.key(22), default_world, 6, 8)
    out = run_all(models[("ECRULE", None)], scenes.rgb, scenes.mask)
    ica, scwia = _ecrule_errors(out, scenes, reference)
    print(
        f"ECRULE 8 surfaces: {len(ica)} non-empty scenes; ICA "
        f"median {np.median(ica):.2e}; SCWIA-12 median {np.median(scwia):.2e}"
    )
    assert len(ica) >= 4
    assert np.median(ica) < 0.002
    assert np.median(scwia) < 0.002


def test_ecrule_ave_is_centroid_with_convex_cone_constraint(default_world, models, reference, run_all):
    """ECRULE-AVE: the exact centroid of F_S ∩ cone(w_C / e_j) (Barnard 1999 §4.5.3)."""
    scenes = sample(jax.random.key(23), default_world, 6, 8)
    out = run_all(models[("ECRULE", None)], scenes.rgb, scenes.mask)
    A, b = reference[None]
    errors = []
    for s in range(6):
        Ad, bd = oracle.scene_constraints(A, b, np.asarray(scenes.rgb[s], np.float64))
        cone = reference["cone"]
        poly = oracle.polytope(np.vstack([Ad, cone]), np.concatenate([bd, np.zeros(len(cone))]))
        if poly is None:
            continue
        centroid = reference["white"] / np.asarray(out["AVE"].illuminant[s], np.float64)
        errors.append(np.linalg.norm(centroid - poly.centroid) / np.linalg.norm(poly.centroid))
    assert len(errors) >= 4
    assert np.median(errors) < 0.005


def test_fact_a_database_under_a_light_gives_that_light(default_world, models):
    """Spec ch08-12 §1.8 fact (a): the whole database rendered under e with an exact diagonal
    model gives CRULE-MV = e (a diagonal map of a polytope into itself has determinant <= 1).
    The exact feasible set of directions is a single ray, so the kernel needs the first
    relaxation level and reports ok=False; the answer is still e."""
    model = models[("CRULE", None)]
    white = np.asarray(default_world.canonical_white, np.float64)
    canonical = np.asarray(default_world.canonical_rgb, np.float64)
    lights = np.asarray(default_world.test_whites, np.float64)[[0, 100, 200]]
    rgb = np.stack([canonical * (e / white) for e in lights]).astype(np.float32)
    mask = np.ones(rgb.shape[:2], bool)
    estimator = gamut.GamutMapping(model, "MV")
    out = eqx.filter_jit(lambda est, r, k: jax.vmap(est)(r, k))(estimator, rgb, mask)
    estimate = np.asarray(out.illuminant, np.float64)
    assert np.all(np.isfinite(estimate))
    np.testing.assert_allclose(estimate, lights, rtol=2e-3)
    assert np.all(np.asarray(out.relaxation) <= 2e-3)


# ---------------------------------------------------------------------------------------------
# properties and degenerate input


def _scene(default_world, seed, n=8):
    scenes = sample(jax.random.key(seed), default_world, 1, n)
    return np.asarray(scenes.rgb[0]), np.asarray(scenes.mask[0])


@settings(max_examples=6, deadline=None)
@given(seed=st.integers(0, 10_000), perm_seed=st.integers(0, 10_000), scale=st.floats(0.25, 4.0))
def test_permutation_padding_and_scale(default_world, models, run_all, seed, perm_seed, scale):
    model = models[("ECRULE", None)]
    rgb, mask = _scene(default_world, seed)
    perm = np.random.default_rng(perm_seed).permutation(8)
    # Padding: two slots masked out with junk, versus the six visible surfaces plus duplicates
    # of two of them (duplicates add no constraint).
    padded = rgb.copy()
    padded[6:] = [[5.0, 0.0, 9.0], [0.0, 0.0, 0.0]]
    padded_mask = np.array([True] * 6 + [False] * 2)
    duplicated = rgb.copy()
    duplicated[6:] = rgb[:2]
    batch = np.stack([rgb, rgb[perm], rgb * scale, padded, duplicated]).astype(np.float32)
    masks = np.stack([mask, mask[perm], mask, padded_mask, np.ones(8, bool)])
    out = run_all(model, batch, masks)
    for name in SELECTORS_E:
        e = np.asarray(out[name].illuminant, np.float64)
        assert np.all(np.isfinite(e))
        np.testing.assert_allclose(e[1], e[0], rtol=1e-4, err_msg=f"{name}: permutation")
        np.testing.assert_allclose(e[2], scale * e[0], rtol=1e-3, err_msg=f"{name}: scale equivariance")
        np.testing.assert_allclose(e[3], e[4], rtol=1e-4, err_msg=f"{name}: padding")


def test_masked_slots_anywhere_are_never_read(default_world, models, run_all):
    """Small scenes read only their usable observations (moved to the leading slots, in order):
    eight surfaces scattered over 32 slots between masked junk give, bitwise, what the same eight
    in the first slots give, for every selector; the fine grid counts eight observations."""
    model = models[("ECRULE", "ND")]
    rgb, mask = _scene(default_world, 21)
    assert mask.all()
    rng = np.random.default_rng(4)
    batch = rng.uniform(-3.0, 50.0, (2, 32, 3)).astype(np.float32)  # junk in the masked slots
    slots = np.sort(rng.choice(32, 8, replace=False))
    batch[0, slots], batch[1, :8] = rgb, rgb
    masks = np.zeros((2, 32), bool)
    masks[0, slots], masks[1, :8] = True, True
    out = run_all(model, batch, masks)
    for name in SELECTORS_E:
        e = np.asarray(out[name].illuminant)
        np.testing.assert_array_equal(e[0], e[1], err_msg=name)
        assert np.all(np.isfinite(e))
    grid = jax.jit(jax.vmap(lambda r, m: _constraints_3d.evaluate(model, r, m)))(batch, masks)
    assert grid.count is not None
    np.testing.assert_array_equal(np.asarray(grid.count), [8, 8])


def test_degenerate_scenes_are_finite_with_ok_false(default_world, models, run_all):
    rgb, mask = _scene(default_world, 6)  # a scene every selector solves without relaxation
    nothing = np.zeros((8, 3), np.float32)
    primaries = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0]] * 2, np.float32) * 0.5
    batch = np.stack([rgb, rgb, nothing, primaries])
    masks = np.stack([mask, np.zeros(8, bool), np.ones(8, bool), np.ones(8, bool)])
    for key in (("ECRULE", None), ("CRULE", None)):
        out = run_all(models[key], batch, masks)
        fallback = np.asarray(models[key].fallback)
        for name, estimate in out.items():
            e = np.asarray(estimate.illuminant)
            assert np.all(np.isfinite(e)), name
            assert bool(estimate.ok[0]), name
            assert not bool(estimate.ok[1]) and not bool(estimate.ok[2]), name
            np.testing.assert_allclose(e[1], fallback, rtol=1e-6)
            np.testing.assert_allclose(e[2], fallback, rtol=1e-6)
            assert int(estimate.status[1]) == int(estimate.status[2]) == Status.NO_DATA, name
            # Saturated primaries fit no diagonal map: relaxed (or fallen back), never NaN.
            assert int(estimate.status[3]) in (Status.RELAXED, Status.EMPTY_SET), name
            if int(estimate.status[3]) == Status.RELAXED:
                assert float(estimate.relaxation[3]) > 0, name


def test_relaxation_levels_are_zero_then_doubling():
    """Barnard 1999 §4.3.2: eps = 0, then eps_1 = 1e-3 doubling; the first level not below the
    smallest violation is used, and beyond the last level (2.048, above any sine) there is no
    solution."""
    violation = jnp.array([-0.3, 0.0, 1e-5, 1e-3, 1.001e-3, 3e-3, 0.5, 1.0, 2.5])
    level, failed = _relaxation.relaxation_level(violation)
    np.testing.assert_allclose(np.asarray(level)[:8], [0.0, 0.0, 1e-3, 1e-3, 2e-3, 4e-3, 0.512, 1.024], rtol=1e-6)
    assert np.asarray(failed).tolist() == [False] * 8 + [True]


# ---------------------------------------------------------------------------------------------
# thesis-level behaviour, labels


def test_labels(default_world):
    for label in (
        "CRULE-MV",
        "CRULE-AVE",
        "ECRULE-MV",
        "ECRULE-AVE",
        "ECRULE-ICA",
        "ECRULE-SCWIA-12",
        "CRULE-SCWIA-6",
        "ND-ECRULE-SCWIA-12",
        "ND-CRULE-AVE",
        "soft-ECRULE-SCWIA-12",
    ):
        estimator = registry.fit(label, default_world)
        assert estimator.estimates_brightness
    assert registry.fit("ND-ECRULE-ICA", default_world).model.extension == "ND"
    assert registry.fit("ECRULE-SCWIA-18", default_world).power == 18.0
    with pytest.raises(ValueError, match="ICA"):
        registry.fit("CRULE-ICA", default_world)
    with pytest.raises(ValueError, match="constraint"):
        gamut.fit(default_world, constraint="CIP")
    with pytest.raises(ValueError, match="soft"):
        registry.fit("ECRULE-MV", default_world, tau=0.1)


@pytest.mark.slow
@pytest.mark.external_data
def test_mv_brightness_beats_averaging_and_scwia_interpolates(barnard_world, run_all):
    """Thesis §4.7 / §6.2 on 300 scenes of the thesis world: MV estimates brightness better than
    AVE; SCWIA-12's chromaticity beats both MV and ICA at 8 surfaces."""
    scenes = sample(jax.random.key(31), barnard_world, 300, 8)
    out = run_all(gamut.fit(barnard_world, constraint="ECRULE"), scenes.rgb, scenes.mask)
    rms = lambda x: float(np.sqrt(np.mean(np.square(x))))
    truth = scenes.illuminant
    assert rms(metrics.brightness_error(out["MV"].illuminant, truth)) < rms(
        metrics.brightness_error(out["AVE"].illuminant, truth)
    )
    rg = {name: rms(metrics.rg_error(out[name].illuminant, truth)) for name in SELECTORS_E}
    assert rg["SCWIA-12"] < rg["MV"] < rg["ICA"]


# ---------------------------------------------------------------------------------------------
# differentiable variant


@pytest.mark.slow
def test_soft_variant_gradients_x64(default_world, models):
    from jax.test_util import check_grads

    with jax.enable_x64(True):
        model = jax.tree_util.tree_map(
            lambda x: x.astype(jnp.float64) if eqx.is_array(x) else x, models[("ECRULE", None)]
        )
        rgb, mask = _scene(default_world, 8)
        rgb, mask = jnp.asarray(rgb, jnp.float64), jnp.asarray(mask)
        soft = gamut.SoftGamutMapping(model, "SCWIA", 12.0)
        f = jax.jit(lambda r: soft(r, mask).illuminant)
        check_grads(f, (rgb,), order=1, modes=["rev"], eps=1e-6)
        # One gradient for both: the input RGB and the canonical gamut's facets.
        total = lambda pair: jnp.sum(gamut.SoftGamutMapping(pair[0], "SCWIA", 12.0)(pair[1], mask).illuminant)
        grad_model, grad_rgb = jax.jit(jax.grad(total))((model, rgb))
        assert float(jnp.linalg.norm(grad_rgb)) > 1e-3
        assert float(jnp.linalg.norm(grad_model.top_normals)) > 0 and float(jnp.linalg.norm(grad_model.top_offsets)) > 0


@pytest.mark.slow
def test_soft_agrees_with_hard(default_world, models):
    scenes = sample(jax.random.key(41), default_world, 100, 8)
    model = models[("ECRULE", None)]
    run = eqx.filter_jit(lambda e, r, k: jax.vmap(e)(r, k))
    hard = run(gamut.GamutMapping(model, "SCWIA", 12.0), scenes.rgb, scenes.mask)
    soft = run(gamut.SoftGamutMapping(model, "SCWIA", 12.0), scenes.rgb, scenes.mask)
    distance = np.asarray(metrics.rg_error(soft.illuminant, hard.illuminant))
    print(f"soft vs hard ECRULE-SCWIA-12, 100 scenes: median (r,g) distance {np.median(distance):.5f}")
    assert np.median(distance) < 0.005


# ---------------------------------------------------------------------------------------------
# the full oracle comparisons: 200 scenes per size


@pytest.mark.slow
@pytest.mark.parametrize("n_surfaces,extension", [(4, None), (8, None), (64, None), (1024, "ND")])
def test_crule_against_oracle_200_scenes(default_world, models, reference, n_surfaces, extension):
    scenes = sample(jax.random.key(100 + n_surfaces), default_world, 200, n_surfaces)
    out = _runner(powers=())(models[("CRULE", extension)], scenes.rgb, scenes.mask)
    ave, mv = _crule_errors(out, scenes, reference, extension)
    label = "ND-CRULE" if extension else "CRULE"
    print(
        f"{label} {n_surfaces} surfaces: {len(ave)}/200 non-empty; AVE centroid "
        f"error median {np.median(ave):.2e}; MV product shortfall median {np.median(mv):.2e}"
    )
    assert len(ave) >= 100
    assert np.median(ave) < 0.005
    assert np.median(np.abs(mv)) < 0.005


@pytest.mark.slow
@pytest.mark.parametrize("n_surfaces", [4, 8, 64])
def test_ecrule_against_quadrature_200_scenes(default_world, models, reference, n_surfaces):
    scenes = sample(jax.random.key(200 + n_surfaces), default_world, 200, n_surfaces)
    out = _runner()(models[("ECRULE", None)], scenes.rgb, scenes.mask)
    ica, scwia = _ecrule_errors(out, scenes, reference)
    print(
        f"ECRULE {n_surfaces} surfaces: {len(ica)}/200 non-empty; ICA "
        f"(r,g) error median {np.median(ica):.2e}; SCWIA-12 median {np.median(scwia):.2e}"
    )
    assert len(ica) >= 100
    assert np.median(ica) < 0.002
    assert np.median(scwia) < 0.002


@pytest.mark.slow
def test_kernel_runs_in_x64(default_world, models):
    with jax.enable_x64(True):
        model = models[("ECRULE", "ND")]
        rgb, mask = _scene(default_world, 9, 16)
        out = gamut.estimate_all(model, jnp.asarray(rgb, jnp.float64), jnp.asarray(mask), powers=(12,))
        for name, estimate in out.items():
            assert estimate.illuminant.dtype == jnp.float64, name
            assert np.all(np.isfinite(np.asarray(estimate.illuminant))), name


def test_estimate_batch_blocks_equal_one_vmap(default_world, models, monkeypatch):
    # 2 * block + 1 scenes: three equal blocks, the last padded with one copy of the first scene.
    estimator = gamut.GamutMapping(models[("ECRULE", None)], "SCWIA", 12.0)
    block = estimator.block_size(jax.default_backend())
    assert block is not None and block > 1
    scenes = sample(jax.random.key(43), default_world, 2 * block + 1, 8)
    calls = []
    call = type(estimator).__call__
    monkeypatch.setattr(type(estimator), "__call__", lambda self, *a: calls.append(1) or call(self, *a))
    blocked = eqx.filter_jit(estimate_batch)(estimator, scenes.rgb, scenes.mask)
    monkeypatch.undo()
    # One traced copy of the model (no separately vmapped remainder to trace and compile).
    assert len(calls) == 1
    assert blocked.illuminant.shape == (2 * block + 1, 3)
    whole = eqx.filter_jit(lambda e, r, k: jax.vmap(e)(r, k))(estimator, scenes.rgb, scenes.mask)
    np.testing.assert_allclose(np.asarray(blocked.illuminant), np.asarray(whole.illuminant), rtol=1e-5)
    np.testing.assert_array_equal(np.asarray(blocked.ok), np.asarray(whole.ok))


def test_models_are_final_surface_estimators_and_jit_arguments(default_world, models):
    """The estimator contract: a model is a jit argument (its configuration static, its arrays
    leaves) and returns the one Estimate type with a status."""
    rgb, mask = _scene(default_world, 6)
    call = jax.jit(lambda m, *a: m(*a))
    for estimator in (
        gamut.GamutMapping(models[("ECRULE", None)], "SCWIA", 12.0),
        gamut.SoftGamutMapping(models[("CRULE", None)], "AVE"),
    ):
        assert isinstance(estimator, AbstractSurfaceEstimator)
        estimate = call(estimator, rgb, mask)
        assert type(estimate) is Estimate
        assert int(estimate.status) == Status.ESTIMATED and float(estimate.relaxation) == 0.0
    assert bool(
        jax.jit(gamut.GamutMapping.reduction_exact)(gamut.GamutMapping(models[("CRULE", None)], "MV"), rgb, mask)
    )


def test_scenes_scaled_by_1e_minus_12_and_1e6_give_the_same_answer(default_world, models, run_all):
    """No absolute threshold: the constraints are scale-invariant and T scales with the scene, so
    a scene times s has the estimate times s and the same status (also for a relaxed scene)."""
    rgb, mask = _scene(default_world, 6)
    primaries = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0]] * 2, np.float32) * 0.5
    scales = (1.0, 1e-12, 1e6)
    batch = np.stack([rgb * s for s in scales] + [primaries * s for s in scales]).astype(np.float32)
    masks = np.stack([mask] * 3 + [np.ones(8, bool)] * 3)
    for key in (("ECRULE", None), ("CRULE", None)):
        out = run_all(models[key], batch, masks)
        for name, estimate in out.items():
            e = np.asarray(estimate.illuminant, np.float64)
            status = np.asarray(estimate.status)
            assert status[0] == Status.ESTIMATED and status[3] == Status.RELAXED, name
            for base in (0, 3):
                for k, s in enumerate(scales[1:], start=1):
                    assert status[base + k] == status[base], (name, s)
                    np.testing.assert_allclose(e[base + k], s * e[base], rtol=1e-5, err_msg=f"{name} x{s}")


def test_forms_argmax_is_numpys_first_argmax():
    """The observation reductions of large scenes are a running maximum over the observations
    (``_engine.forms_argmax``); against NumPy's ``argmax`` (first maximum) over the full
    ``(observations, forms)`` score array, with unusable observations, exact ties (repeated
    observations) and an observation count that is not a multiple of the loop's step."""
    rng = np.random.default_rng(7)
    q = rng.uniform(0.05, 1.0, (101, 3)).astype(np.float32)
    q[60:70] = q[10:20]  # repeats: the first of equal maxima must win
    usable = rng.uniform(size=101) > 0.2
    origin = rng.normal(size=(12, 3)).astype(np.float32)
    squares = rng.uniform(0.5, 2.0, (4, 3)).astype(np.float32)  # 4 groups of 3 origin forms
    top = rng.normal(size=(30, 3)).astype(np.float32)
    got = np.asarray(jax.jit(_engine.forms_argmax)(q, usable, origin, squares, top))
    q64 = q.astype(np.float64)
    norms = np.repeat(np.sqrt((q64 * q64) @ squares.T.astype(np.float64)), 3, axis=1)
    origin_scores = (q64 @ origin.T.astype(np.float64)) / norms
    scores = np.concatenate([origin_scores, q64 @ top.T.astype(np.float64)], axis=1)
    scores[~usable] = -np.inf
    np.testing.assert_array_equal(got, np.argmax(scores, axis=0))


def test_certified_forms_give_every_maximum_on_the_grid():
    """The fine stage's ``1/T`` reads only the top-facet forms a box bound cannot exclude
    (``_engine.binding_forms``): on a grid of directions with invalid ones, forms of which many are
    within a hair of each maximum, near-ties (forms nudged by 1e-6) and a count below the number
    of forms, the maximum over the kept forms is NumPy's float64 maximum over the first ``count``
    forms at every valid direction (to float32 rounding), and fewer forms are kept than given."""
    rng = np.random.default_rng(23)
    n, tile = 24, 3
    r, g = np.meshgrid(np.linspace(0.2, 0.45, n), np.linspace(0.15, 0.4, n), indexing="ij")
    rg = jnp.asarray(np.stack([r.ravel(), g.ravel()], axis=1), jnp.float32)
    _, v, valid = _engine.directions(rg)
    valid = valid & jnp.asarray(rng.uniform(size=n * n) > 0.1)  # some directions not read
    # Unit vectors of directions across the grid: the support function of a sphere, so each
    # direction has its own nearby winner and many forms are within a hair of every maximum.
    _, around, _ = _engine.directions(jnp.asarray(rng.uniform([0.1, 0.1], [0.55, 0.5], (400, 2)), jnp.float32))
    coef = np.asarray(around, np.float64) / np.linalg.norm(np.asarray(around, np.float64), axis=1, keepdims=True)
    coef[200:260] = coef[100:160] * (1 + 1e-6)  # near-ties
    coef = jnp.asarray(coef, jnp.float32)
    count = 350

    def pruned(v, valid, coef):
        centre, half, occupied = _engine.tile_boxes(v, valid, n, tile)
        order, kept = _engine.binding_forms(coef, jnp.int32(count), centre, half, occupied)
        return _engine.max_of_forms(v, coef[order], kept), kept

    got, kept = jax.jit(pruned)(v, valid, coef)
    expected = (np.asarray(v, np.float64) @ np.asarray(coef, np.float64)[:count].T).max(axis=1)
    inside = np.asarray(valid)
    np.testing.assert_allclose(np.asarray(got)[inside], expected[inside], rtol=1e-6)
    assert 0 < int(kept) < count


@pytest.mark.slow
def test_certified_inverse_extent_is_the_full_one_bitwise(default_world):
    """On 1,024-surface scenes, the certified fine stage's ``1/T`` equals the one over every
    form, bitwise, at every valid direction of each scene's fine grid (the same form reaches each
    maximum), while reading a small fraction of the forms."""
    model = gamut.fit(default_world, constraint="CRULE")
    scenes = sample(jax.random.key(46), default_world, 24, 1024)
    options = model.options

    def both(rgb, mask):
        grid = _constraints_3d.evaluate(model, rgb, mask)
        _, v, valid = _engine.directions(grid.rg)
        return _constraints_3d.inverse_extent(v, grid.observations), grid.inverse_extent, valid

    full, certified, valid = map(np.asarray, jax.jit(jax.vmap(both))(scenes.rgb, scenes.mask))
    assert options.certificate_tile > 0 and options.fine_points % options.certificate_tile == 0
    np.testing.assert_array_equal(certified[valid], full[valid])


def test_leading_forms_loop_reads_only_what_it_is_told():
    """``max_of_forms(..., count)`` and ``surface_violation(..., count)`` (the fine stage reads
    only a reduced scene's leading support points): against NumPy float64 maxima over the first
    ``count`` forms / observations, under ``vmap`` with a different count per scene (the loop runs
    to the batch's largest), and at least one step for a count of 0."""
    rng = np.random.default_rng(11)
    v = jnp.asarray(rng.uniform(1.2, 6.0, (37, 3)), jnp.float32)
    coef = jnp.asarray(rng.normal(size=(4, 50, 3)), jnp.float32)
    counts = np.array([50, 17, 1, 0], np.int32)
    got = np.asarray(jax.jit(jax.vmap(_engine.max_of_forms, in_axes=(None, 0, 0)))(v, coef, counts))
    values = np.einsum("gc,smc->sgm", np.asarray(v, np.float64), np.asarray(coef, np.float64))
    for scene, count in enumerate(counts):
        # A count below one step still reads the first step (FORMS_PER_STEP forms).
        read = max(int(np.ceil(count / _engine.FORMS_PER_STEP)), 1) * _engine.FORMS_PER_STEP
        np.testing.assert_allclose(got[scene], values[scene, :, :read].max(axis=1), rtol=1e-5)
    # Observations past the count never enter V_S, whatever their coefficients.
    obs = _constraints_3d.Observations(
        origin=jnp.asarray(rng.normal(size=(9, 10, 3)), jnp.float32),
        scale=jnp.asarray(rng.uniform(0.1, 1.0, (9, 3)), jnp.float32),
        top=jnp.asarray(rng.normal(size=(9, 5, 3)), jnp.float32),
    )
    for count in (9, 4, 1):
        head = _constraints_3d.Observations(origin=obs.origin[:count], scale=obs.scale[:count], top=obs.top[:count])
        np.testing.assert_array_equal(
            np.asarray(jax.jit(_constraints_3d.surface_violation)(v, obs, jnp.int32(count))),
            np.asarray(jax.jit(_constraints_3d.surface_violation)(v, head)),
        )
        origin = np.asarray(head.origin, np.float64)
        scale = np.asarray(head.scale, np.float64)
        v64 = np.asarray(v, np.float64)
        expected = (
            np.einsum("gc,pkc->gpk", v64, origin).max(axis=2) / np.sqrt(((v64[:, None] * scale) ** 2).sum(-1))
        ).max(1)
        np.testing.assert_allclose(
            np.asarray(_constraints_3d.surface_violation(v, obs, jnp.int32(count))), expected, rtol=1e-5
        )


@pytest.mark.slow
def test_relaxed_scenes_equal_the_unreduced_engine(default_world):
    """Pruning observations is exact only at relaxation level 0 (the normalised violation of a
    relaxed scene is not a linear function of the observation), so on scenes that relax the
    default engine (support-point reduction of scenes above ``fine_observations``) must give the
    unreduced engine's answer (``exact_scene`` above the scene size: every observation in the fine
    stage), selector by selector: same status, same relaxation level, same illuminant."""
    scenes = sample(jax.random.key(45), default_world, 96, 128)
    run = _runner()
    for constraint in ("CRULE", "ECRULE"):
        pruned = gamut.fit(default_world, constraint=constraint)
        full = gamut.fit(default_world, constraint=constraint, options=_engine.GridOptions(exact_scene=10**6))
        assert pruned.options == _engine.GridOptions() and scenes.rgb.shape[1] > pruned.options.fine_observations
        out_pruned, out_full = run(pruned, scenes.rgb, scenes.mask), run(full, scenes.rgb, scenes.mask)
        for name, estimate in out_full.items():
            relaxed = np.asarray(estimate.status) == Status.RELAXED
            assert relaxed.sum() >= 5, (constraint, name, int(relaxed.sum()))
            other = out_pruned[name]
            np.testing.assert_array_equal(np.asarray(other.status)[relaxed], np.asarray(estimate.status)[relaxed])
            np.testing.assert_array_equal(
                np.asarray(other.relaxation)[relaxed], np.asarray(estimate.relaxation)[relaxed]
            )
            np.testing.assert_allclose(
                np.asarray(other.illuminant)[relaxed],
                np.asarray(estimate.illuminant)[relaxed],
                rtol=1e-5,
                err_msg=f"{constraint}-{name}",
            )


@pytest.mark.parametrize(
    "n_surfaces", [pytest.param(8, marks=pytest.mark.slow), 32, pytest.param(64, marks=pytest.mark.slow)]
)
def test_mv_box_forms_keep_every_maximum_in_the_box(default_world, models, n_surfaces):
    """MV's objective reads, inside a box around its start, only `_mv.box_forms`' forms: at
    random valid directions of the box, their maximum is the maximum over every top-facet form
    (NumPy, float64, the same forms), and the certificate drops most forms (it is not a no-op)."""
    from ccjax.estimators.gamut import _mv

    model = models[("ECRULE", "ND")]
    rgb, mask = _scene(default_world, 41 + n_surfaces, n_surfaces)
    grid = _constraints_3d.evaluate(model, jnp.asarray(rgb), jnp.asarray(mask))
    centre = np.asarray(grid.rg)[np.argmin(np.asarray(grid.surface))]
    lo, hi = centre - 4 * np.asarray(grid.step), centre + 4 * np.asarray(grid.step)
    order, kept = _mv.box_forms(grid.observations, grid.count, jnp.asarray(lo), jnp.asarray(hi))
    forms = np.asarray(grid.observations.top, np.float64).reshape(-1, 3)
    if grid.count is not None:
        forms = forms.reshape(-1, model.top_normals.shape[0], 3)[: int(grid.count)].reshape(-1, 3)
    near = np.asarray(grid.observations.top, np.float64).reshape(-1, 3)[np.asarray(order)[: int(kept)]]
    assert 0 < int(kept) < 0.5 * forms.shape[0]
    rg = np.random.default_rng(0).uniform(lo, hi, size=(2000, 2))
    u = np.concatenate([rg, 1 - rg.sum(axis=1, keepdims=True)], axis=1)
    v = 1 / u[np.all(u > _engine.EDGE, axis=1)]
    np.testing.assert_array_equal((v @ near.T).max(axis=1), (v @ forms.T).max(axis=1))
