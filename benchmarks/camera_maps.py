"""Benchmark: the accuracy of camera-to-camera maps fitted from spectra (ccjax.transfer).

For each camera pair, the maps are fitted on the default world of the source camera (SFU 1993
reflectances, every fifth one held back, under the world's training lights) and measured on the
held-back reflectances under the world's test lights (the denser set, lights the maps were not
fitted on), and under blackbody and daylight lights, against the same spectra rendered through the
target camera. Three maps: the global 3x3, the per-light 3x3 on the world's training lights (the
default), and the per-light 3x3 on ``locus_lights()`` (blackbodies and daylights only). Reported:

* angular error (degrees) of the mapped surfaces and of the mapped whites (a perfect white under
  each light, mapped as a ground truth is), mean / median / max;
* the warm-light bias: the mean errors under the test lights below 3500 K (correlated colour
  temperature from CIE 1931 xy, McCamy's formula) against the rest;
* a root-polynomial map (degree 2: R, G, B, sqrt(RG), sqrt(GB), sqrt(RB); Finlayson et al. 2015)
  fitted on the same data, global and per light (interpolated with the per-light map's weights),
  measured here only, to decide whether it earns a place beside the 3x3 maps;
* what a stand-in costs: the embedded curves of a model against the same model measured by
  Jiang et al. 2013 (external data; skipped when it is not found), unmapped and mapped.

Prints a Markdown table. Usage: python benchmarks/camera_maps.py
"""

from __future__ import annotations

import time

import colour
import jax.numpy as jnp
import numpy as np

from ccjax import Camera, World, cameras
from ccjax.spectra import WAVELENGTHS
from ccjax.transfer import (
    PerLightMap,
    fit_camera_map,
    held_back_surfaces,
    locus_lights,
    map_errors,
    paired_responses,
)

PAIRS = [
    ("Canon EOS 600D", "Canon EOS-1Ds Mark III"),
    ("Canon EOS-1Ds Mark III", "Canon EOS 600D"),
    ("Canon EOS 600D", "Nikon D5300"),
    ("Canon EOS 5D Mark II", "Sony ILCE-7M3"),
    ("Fujifilm X-T3", "Canon EOS 600D"),
    ("Panasonic DC-GX9", "Canon EOS-1Ds Mark III"),
]
STAND_INS = [  # (embedded, external measurement of the same model)
    ("Canon EOS 600D", "Jiang: Canon 600D"),
    ("Canon EOS 5D Mark II", "Jiang: Canon 5D Mark II"),
    ("Nikon D5100", "Jiang: Nikon D5100"),
]
WARM_KELVIN = 3500.0


def correlated_colour_temperature(lights: np.ndarray) -> np.ndarray:
    """CCT (K) of each light spectrum: CIE 1931 2-degree xy, then McCamy's formula."""
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    observer = np.stack([np.interp(WAVELENGTHS, cmfs.wavelengths, cmfs.values[:, i]) for i in range(3)], axis=1)
    xyz = lights @ observer
    return np.asarray(colour.temperature.xy_to_CCT(xyz[:, :2] / xyz.sum(axis=1, keepdims=True), method="McCamy 1992"))


def angles(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    cosine = np.sum(a * b, axis=-1) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))
    return np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))


def root_polynomial(rgb: np.ndarray) -> np.ndarray:
    """Degree-2 root-polynomial terms (each of degree 1 in the signal, so exposure carries over)."""
    r, g, b = np.moveaxis(np.maximum(rgb, 0.0), -1, 0)
    return np.stack([r, g, b, np.sqrt(r * g), np.sqrt(g * b), np.sqrt(r * b)], axis=-1)


def root_polynomial_errors(source, target, world, held, per_light_map: PerLightMap):
    """Held-back surface and white errors of a global and a per-light root-polynomial map
    (least squares in float64; the per-light one white-preserving, blended with the 3x3 map's
    interpolation weights)."""
    reflectances = np.asarray(world.reflectances, np.float64)
    train = np.asarray(world.train_illuminants, np.float64)
    test = np.asarray(world.test_illuminants, np.float64)
    fit_a, fit_b = paired_responses(source, target, reflectances[~held], train)
    test_a, test_b = paired_responses(source, target, reflectances[held], test)
    white_fit_a, white_fit_b = (x[:, 0] for x in paired_responses(source, target, np.ones((1, 101)), train))
    white_a, white_b = (x[:, 0] for x in paired_responses(source, target, np.ones((1, 101)), test))
    features = root_polynomial(fit_a)
    gram = np.einsum("lsi,lsj->lij", features, features)
    cross = np.einsum("lsi,lsj->lij", features, fit_b)
    results = {}
    coefficients = np.linalg.solve(gram.sum(0), cross.sum(0))
    results["root-polynomial (global)"] = (
        angles(root_polynomial(test_a) @ coefficients, test_b),
        angles(root_polynomial(white_a) @ coefficients, white_b),
    )
    rows = np.linalg.solve(gram, cross)  # (L, 6, 3)
    w = root_polynomial(white_fit_a)
    v = np.linalg.solve(gram, w[..., None])[..., 0]
    rows = (
        rows - v[:, :, None] * ((np.einsum("li,lij->lj", w, rows) - white_fit_b) / np.sum(w * v, 1)[:, None])[:, None]
    )
    weights = np.stack([np.asarray(per_light_map.weights(jnp.asarray(e, jnp.float32)), np.float64) for e in white_a])
    blended = np.einsum("jl,lik->jik", weights, rows)
    results["root-polynomial (per light)"] = (
        angles(np.einsum("jsi,jik->jsk", root_polynomial(test_a), blended), test_b),
        angles(np.einsum("ji,jik->jk", root_polynomial(white_a), blended), white_b),
    )
    return results


def row(pair: str, name: str, surfaces, whites, warm_mask) -> str:
    """A table row from arrays of errors (surfaces (J, N), whites (J,))."""
    s, w = np.asarray(surfaces), np.asarray(whites)
    stats = lambda e: f"{e.mean():.2f} / {np.median(e):.2f} / {e.max():.2f}"
    bias = lambda e: f"{e[warm_mask].mean():.2f} / {e[~warm_mask].mean():.2f}"
    return f"| {pair} | {name} | {stats(s)} | {stats(w)} | {bias(s)} | {bias(w)} |"


HEADER = [
    "| source → target | map | surfaces: mean / median / max | whites: mean / median / max "
    "| surfaces: warm / rest mean | whites: warm / rest mean |",
    "|---|---|---|---|---|---|",
]


def main() -> None:
    start = time.perf_counter()
    cloud, locus, counts, notes = list(HEADER), list(HEADER), [], []
    worlds: dict[str, World] = {}
    # Between the fitting lights of locus_lights() (250 K and 500 K steps): none is one of them.
    smooth = locus_lights(np.arange(2125.0, 9876.0, 250.0), np.arange(4250.0, 24751.0, 500.0))
    fitting_locus = locus_lights()
    smooth_warm = correlated_colour_temperature(smooth) < WARM_KELVIN
    for source_name, target_name in PAIRS:
        world = worlds.setdefault(source_name, World.default(camera=source_name))
        source, target = Camera.from_name(source_name), Camera.from_name(target_name)
        held = held_back_surfaces(world)
        lights = np.asarray(world.test_illuminants, np.float64)
        warm = correlated_colour_temperature(lights) < WARM_KELVIN
        counts.append(f"{source_name}: {lights.shape[0]} ({int(warm.sum())} warm)")
        pair = f"{source_name} → {target_name}"
        global_map = fit_camera_map(source, target, kind="global", world=world, surfaces=~held)
        per_light_map = fit_camera_map(source, target, kind="per-light", world=world, surfaces=~held)
        assert isinstance(per_light_map, PerLightMap)
        locus_map = fit_camera_map(source, target, kind="per-light", world=world, surfaces=~held, lights=fitting_locus)
        maps = (
            ("global 3x3", global_map),
            ("per-light 3x3", per_light_map),
            ("per-light 3x3, locus lights", locus_map),
        )
        for name, camera_map in maps:
            errors = map_errors(camera_map, source, target, world, held)
            if errors.negative.any():
                share = 100 * errors.negative.mean()
                notes.append(f"{pair}, {name}: {share:.3f} % of mapped surfaces have a negative channel")
            cloud.append(row(pair, name, errors.surfaces, errors.whites, warm))
            errors = map_errors(camera_map, source, target, world, held, lights=smooth)
            locus.append(row(pair, name, errors.surfaces, errors.whites, smooth_warm))
        for name, (surfaces, whites) in root_polynomial_errors(source, target, world, held, per_light_map).items():
            cloud.append(row(pair, name + " *", surfaces, whites, warm))
    print(
        "Held-back surfaces: every fifth SFU 1993 reflectance (the maps are fitted on the other four fifths under "
        "the source world's training lights, or under the 76 lights of locus_lights()). Angular errors in degrees; "
        f"warm: correlated colour temperature below {WARM_KELVIN:.0f} K.\n"
    )
    print("Under the source world's test lights (" + "; ".join(dict.fromkeys(counts)) + "):\n")
    print("\n".join(cloud))
    print("\n\\* measured only (not in ccjax.transfer).")
    if notes:
        print("\n" + "\n".join(notes))
    print(
        f"\nUnder {smooth.shape[0]} blackbody and daylight lights between those of locus_lights() "
        f"({int(smooth_warm.sum())} warm):\n"
    )
    print("\n".join(locus))

    known = cameras()
    stand_ins = [(a, b) for a, b in STAND_INS if b in known]
    if not stand_ins:
        print("\nStand-ins: the external data (Jiang et al. 2013) was not found; skipped.")
    else:
        print("\nWhat a stand-in costs: the embedded curves against an external measurement of the same model,")
        print(
            "under the embedded camera's world's test lights "
            "('unmapped': the embedded camera's RGB taken as the other's):\n"
        )
        print("\n".join(HEADER))
        for embedded, external in stand_ins:
            world = worlds.setdefault(embedded, World.default(camera=embedded))
            source, target = Camera.from_name(embedded), Camera.from_name(external)
            held = held_back_surfaces(world)
            lights = np.asarray(world.test_illuminants, np.float64)
            warm = correlated_colour_temperature(lights) < WARM_KELVIN
            pair = f"{embedded} → {external}"
            reflectances = np.asarray(world.reflectances, np.float64)
            test_a, test_b = paired_responses(source, target, reflectances[held], lights)
            white_a, white_b = (x[:, 0] for x in paired_responses(source, target, np.ones((1, 101)), lights))
            print(row(pair, "unmapped (stand-in as is)", angles(test_a, test_b), angles(white_a, white_b), warm))
            # Per-channel gains only (least squares on the fitting data): what is left once the two
            # measurements' channel scales (their normalisation conventions) are matched.
            fit_a, fit_b = paired_responses(source, target, reflectances[~held], world.train_illuminants)
            gains = np.sum(fit_a * fit_b, axis=(0, 1)) / np.sum(fit_a * fit_a, axis=(0, 1))
            print(row(pair, "channel gains *", angles(test_a * gains, test_b), angles(white_a * gains, white_b), warm))
            for kind in ("global", "per-light"):
                camera_map = fit_camera_map(source, target, kind=kind, world=world, surfaces=~held)  # type: ignore[arg-type]
                errors = map_errors(camera_map, source, target, world, held)
                print(row(pair, f"{kind} 3x3", errors.surfaces, errors.whites, warm))
    print(f"\n({time.perf_counter() - start:.0f} s)")


if __name__ == "__main__":
    main()
