"""A small world built in milliseconds (Planck lights, every 8th SFU reflectance, Canon curves),
for image tests that need a world but not the thesis' illuminant sets."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ccjax import data
from ccjax.camera import Camera
from ccjax.spectra import WAVELENGTHS
from ccjax.world import World, normalise_illuminants


def planck(kelvin: float) -> np.ndarray:
    metres = WAVELENGTHS * 1e-9
    return 1.0 / (metres**5 * (np.exp(1.4388e-2 / (metres * kelvin)) - 1.0))


def small_world() -> World:
    camera = Camera.from_name("Canon EOS 5D Mark II")
    sensors = np.asarray(camera.sensors, np.float64)
    lights = normalise_illuminants(np.stack([planck(t) for t in np.arange(2500.0, 10001.0, 250.0)]), sensors)
    canonical = normalise_illuminants(planck(6500.0), sensors)[0]
    return World(
        reflectances=jnp.asarray(data.sfu_reflectances().values[::8], jnp.float32),
        train_illuminants=jnp.asarray(lights[::2], jnp.float32),
        test_illuminants=jnp.asarray(lights, jnp.float32),
        canonical=jnp.asarray(canonical, jnp.float32),
        camera=camera,
        name="small test world",
    )
