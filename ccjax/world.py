"""Worlds: reflectances, training and test illuminant sets, canonical light and camera.

The illuminant sets follow Barnard 1999 §4.4 (Fig. 4.1): (r,g) space is cut into square
cells (0.02 for training, 0.01 — four times denser — for testing); the priority lights (the 11 lab
lights in the thesis world) are placed first, then the other measured lights go into cells that
are still empty, then random convex mixtures of pairs of source spectra fill empty cells until no
new cell is reached. Every illuminant is normalised so that the brightest channel of the camera
response to a perfect white is 1.0 (the thesis states its constants where that channel is 255).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ccjax import data
from ccjax._colour import rg_numpy
from ccjax.camera import Camera
from ccjax.spectra import WAVELENGTHS, SpectraLike, as_spectra, blackbody, cie_daylight, resample

TRAIN_CELL = 0.02
TEST_CELL = 0.01


def normalise_illuminants(illuminants: np.ndarray, sensors: np.ndarray) -> np.ndarray:
    """Scale each illuminant so the brightest channel of its white response is 1 (ccjax's scale; the thesis' is 255).

    Arguments:
        illuminants: ``(N, 101)`` spectral power distributions.
        sensors: ``(101, 3)`` camera curves.

    Returns:
        ``(N, 101)`` scaled illuminants.
    """
    illuminants = np.atleast_2d(np.asarray(illuminants, dtype=np.float64))
    white = illuminants @ np.asarray(sensors, dtype=np.float64)
    peak = white.max(axis=1, keepdims=True)
    if np.any(peak <= 0):
        bad = np.flatnonzero(peak[:, 0] <= 0).tolist()
        raise ValueError(f"illuminants: rows {bad} give no camera response to white")
    return illuminants / peak


@dataclass(frozen=True)
class IlluminantSet:
    """An illuminant set and how each member was made."""

    spectra: np.ndarray  # (N, 101), normalised
    origin: np.ndarray  # (N,) str: "priority", "measured" or "mixture"


def build_illuminant_set(
    sources: np.ndarray,
    sensors: np.ndarray,
    *,
    n_priority: int,
    cell: float,
    seed: int,
    n_candidates: int = 200_000,
) -> IlluminantSet:
    """Build an illuminant set by the thesis procedure (Barnard 1999 §4.4, Fig. 4.1).

    Arguments:
        sources: ``(N, 101)`` source spectra; the first ``n_priority`` are placed unconditionally
            (the thesis' 11 lab lights), the rest only into still-empty (r,g) cells.
        sensors: ``(101, 3)`` camera curves (cells are in this camera's (r,g)).
        n_priority: how many leading sources are placed first.
        cell: (r,g) cell width (0.02 training, 0.01 testing).
        seed: NumPy seed of the mixtures (the sets are reproducible).
        n_candidates: random pair mixtures drawn; each is kept only if its cell is still empty,
            in draw order. The default reaches every cell the mixtures can reach for the worlds
            shipped here (no new cell in the last half of the draws).

    Returns:
        The normalised illuminant set, priority lights first.
    """
    sources = normalise_illuminants(sources, sensors)
    rg = rg_numpy(sources @ sensors)
    cells = np.floor(rg / cell).astype(np.int64)
    occupied: set[tuple[int, int]] = set()
    chosen: list[np.ndarray] = []
    origin: list[str] = []
    for index, (spectrum, key) in enumerate(zip(sources, map(tuple, cells))):
        if index < n_priority or key not in occupied:
            occupied.add(key)
            chosen.append(spectrum)
            origin.append("priority" if index < n_priority else "measured")

    # Random convex mixtures of two sources (the thesis' "random linear combinations").
    rng = np.random.default_rng(seed)
    first = rng.integers(0, len(sources), n_candidates)
    second = rng.integers(0, len(sources), n_candidates)
    weight = rng.uniform(0.0, 1.0, n_candidates)[:, None]
    white = sources @ sensors
    mixed_rg = rg_numpy(weight * white[first] + (1 - weight) * white[second])
    mixed_cells = np.floor(mixed_rg / cell).astype(np.int64)
    for index, key in enumerate(map(tuple, mixed_cells)):
        if key not in occupied:
            occupied.add(key)
            chosen.append(weight[index, 0] * sources[first[index]] + (1 - weight[index, 0]) * sources[second[index]])
            origin.append("mixture")
    spectra = normalise_illuminants(np.stack(chosen), sensors)
    return IlluminantSet(spectra=spectra, origin=np.array(origin))


class World(eqx.Module):
    """A synthetic world (Barnard 1999 §4.4): everything a scene or a fitted estimator needs.

    Its arrays are JAX's float at construction: float32, or float64 when built (by
    :meth:`from_sources`, :meth:`default`, :meth:`barnard1999`) under ``jax_enable_x64``; then
    its responses, the scenes drawn from it and the estimates on them are float64 too, and the
    same key draws the same scenes as in float32 (the random numbers are drawn in float32 and
    cast), so a float64 re-check sees the same data to float32 rounding.

    Attributes:
        reflectances: ``(S, 101)`` surface reflectances.
        train_illuminants: ``(I, 101)`` training illuminants (fits, AVE-ILLUM, constraints).
        test_illuminants: ``(J, 101)`` test illuminants (synthetic scenes).
        canonical: ``(101,)`` canonical illuminant.
        camera: the camera.
        name: a label.
    """

    reflectances: Float[Array, "S 101"]
    train_illuminants: Float[Array, "I 101"]
    test_illuminants: Float[Array, "J 101"]
    canonical: Float[Array, "101"]
    camera: Camera
    name: str = eqx.field(static=True, default="custom")

    # -- derived quantities (cheap, jit-able) --------------------------------------------------
    @property
    def canonical_white(self) -> Float[Array, "3"]:
        """Camera RGB of a perfect white under the canonical light, ``w_C``."""
        return self.camera.response(self.canonical)

    @property
    def train_whites(self) -> Float[Array, "I 3"]:
        return self.camera.response(self.train_illuminants)

    @property
    def test_whites(self) -> Float[Array, "J 3"]:
        return self.camera.response(self.test_illuminants)

    @property
    def canonical_rgb(self) -> Float[Array, "S 3"]:
        """Camera RGB of every reflectance under the canonical light."""
        return self.responses(self.canonical)

    def responses(self, illuminants: Float[ArrayLike, "*lights 101"]) -> Float[Array, "*lights S 3"]:
        """Camera RGB of every reflectance of the world under each of a set of lights.

        The image formation of Barnard 1999 §4.2 (eq. 4.1, discretised as in §2.2): surface ``s``
        under light ``E`` gives ``rho_k = sum_lambda E(lambda) S_s(lambda) R_k(lambda)``, computed as
        ``(reflectances * E) @ sensors``, in the world's dtype: float32, or float64 for a world
        built under ``jax_enable_x64`` (:meth:`from_sources`, :meth:`default`).

        Arguments:
            illuminants: ``(..., 101)`` spectra, e.g. ``world.train_illuminants`` ``(I, 101)`` or
                ``world.canonical`` ``(101,)``; any leading shape.

        Returns:
            ``(..., S, 3)``: for each light, the responses of the ``S`` reflectances (rows are
            surfaces, the thesis' ``A``/``B`` matrices of chapter 5).
        """
        lights = jnp.asarray(illuminants)
        return self.camera.response(self.reflectances * lights[..., None, :])

    def sizes(self) -> dict[str, int]:
        return {
            "reflectances": int(self.reflectances.shape[0]),
            "training illuminants": int(self.train_illuminants.shape[0]),
            "test illuminants": int(self.test_illuminants.shape[0]),
        }

    # -- constructors ----------------------------------------------------------------------------
    @classmethod
    def from_sources(
        cls,
        *,
        reflectances: SpectraLike,
        sources: SpectraLike,
        n_priority: int,
        canonical: SpectraLike,
        camera: Camera,
        seed: int = 0,
        name: str = "custom",
    ) -> World:
        """Build a world from source spectra by the thesis' illuminant-set procedure.

        Each spectrum argument also takes colour-science distributions (a
        ``MultiSpectralDistributions`` with one distribution per surface or light, a
        ``SpectralDistribution`` for ``canonical``), resampled with edge values held
        (:func:`ccjax.spectra.from_colour`, kinds ``"reflectance"`` and ``"light"``).

        Arguments:
            reflectances: ``(S, 101)`` reflectances in [0, 1] (values above 1 allowed: fluorescent
                or specular surfaces).
            sources: ``(N, 101)`` illuminant spectra, priority lights first.
            n_priority: how many leading sources are placed unconditionally.
            canonical: ``(101,)`` canonical illuminant spectrum.
            camera: the camera.
            seed: seed of the random mixtures (test set uses ``seed + 1``).
            name: a label.

        Returns:
            The world.
        """
        reflectances = _validated_spectra("reflectances", as_spectra(reflectances, kind="reflectance"), 2)
        sources = _validated_spectra("sources", as_spectra(sources, kind="light"), 2)
        canonical = _validated_spectra("canonical", as_spectra(canonical, kind="light"), 1)
        sensors = np.asarray(camera.sensors, dtype=np.float64)
        train = build_illuminant_set(sources, sensors, n_priority=n_priority, cell=TRAIN_CELL, seed=seed)
        test = build_illuminant_set(sources, sensors, n_priority=n_priority, cell=TEST_CELL, seed=seed + 1)
        # JAX's float (float32; float64 under jax_enable_x64), cast on the host and device_put:
        # jnp.asarray compiles a small program per shape (start-up time).
        width = jax.dtypes.canonicalize_dtype(np.float64)
        put = lambda x: jax.device_put(np.asarray(x, width))
        if camera.sensors.dtype != width:
            camera = eqx.tree_at(lambda c: c.sensors, camera, put(camera.sensors))
        return cls(
            reflectances=put(reflectances),
            train_illuminants=put(train.spectra),
            test_illuminants=put(test.spectra),
            canonical=put(normalise_illuminants(canonical, sensors)[0]),
            camera=camera,
            name=name,
        )

    @classmethod
    def default(cls, camera: str | Camera = "Canon EOS 5D Mark II", *, seed: int = 0) -> World:
        """The default world, from embedded data only (the thesis' procedure, §4.4, on redistributable data).

        SFU 1993 reflectances; canonical CIE D65; sources CIE A, D50, D55, D65, D75, FL2, FL7,
        FL11 first, then CIE daylight 4000–25000 K (500 K steps), blackbody 2000–10000 K (250 K
        steps), FL1–12, FL3.x, LED and HP series into empty cells, then random mixtures.

        Arguments:
            camera: an embedded camera name or a :class:`Camera`.
            seed: seed of the illuminant mixtures.

        Returns:
            The :class:`World`.
        """
        cam = camera if isinstance(camera, Camera) else Camera.from_name(camera)
        sources, n_priority, canonical = _default_sources()
        return cls.from_sources(
            reflectances=data.sfu_reflectances().values,
            sources=sources,
            n_priority=n_priority,
            canonical=canonical,
            camera=cam,
            seed=seed,
            name=f"default ({cam.name})",
        )

    @classmethod
    def barnard1999(cls, data_dir: str | os.PathLike | None = None, *, seed: int = 0) -> World:
        """The thesis world (Barnard 1999 §4.4): Sony DXC-930, SFU reflectances, SFU illuminants.

        The 11 lab lights are placed first, the other 88 SFU lights into empty cells, then random
        mixtures; canonical Sylvania 50MR16Q. Needs the external data (see
        :func:`ccjax.data.find_data_file` for the look-up order).

        Arguments:
            data_dir: the external data's folder (``None``: the look-up order).
            seed: seed of the illuminant mixtures.

        Returns:
            The :class:`World`.
        """
        camera = Camera.from_name("Sony DXC-930", data_dir=data_dir)
        lights = data.sfu_illuminants(data_dir)
        lab = [lights.names.index(name) for name in data.SFU_LAB_LIGHTS.values()]
        others = [i for i in range(len(lights.names)) if i not in lab]
        sources = lights.values[lab + others]
        canonical = lights.values[lights.names.index(data.SFU_LAB_LIGHTS["syl-50MR16Q"])]
        return cls.from_sources(
            reflectances=data.sfu_reflectances().values,
            sources=sources,
            n_priority=len(lab),
            canonical=canonical,
            camera=camera,
            seed=seed,
            name="barnard1999",
        )


def _validated_spectra(name: str, values, ndim: int) -> np.ndarray:
    values = np.asarray(values, dtype=np.float64)
    if values.ndim != ndim or values.shape[-1] != WAVELENGTHS.size:
        want = "(101,)" if ndim == 1 else "(N, 101)"
        raise ValueError(f"{name}: expected shape {want} on the ccjax grid, got {values.shape}")
    if not np.all(np.isfinite(values)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    if np.any(values < 0):
        raise ValueError(f"{name}: contains negative values")
    return values


def _default_sources() -> tuple[np.ndarray, int, np.ndarray]:
    import colour  # imported here: colour-science is slow to import and only needed for this

    def grid(sd) -> np.ndarray:
        return resample(np.asarray(sd.wavelengths), np.asarray(sd.values), kind="spectrum")

    cie = colour.SDS_ILLUMINANTS
    priority = ["A", "D50", "D55", "D65", "D75", "FL2", "FL7", "FL11"]
    spectra = [grid(cie[name]) for name in priority]
    spectra += list(cie_daylight(np.arange(4000.0, 25000.0 + 1, 500.0)))
    spectra += list(blackbody(np.arange(2000.0, 10000.0 + 1, 250.0)))
    series = [f"FL{i}" for i in range(1, 13)] + [f"FL3.{i}" for i in range(1, 16)]
    series += [name for name in cie if name.startswith(("LED-", "HP"))]
    spectra += [grid(cie[name]) for name in series if name not in priority]
    return np.stack(spectra), len(priority), grid(cie["D65"])
