"""Per-world response tables from which synthetic scenes are gathered (Barnard 1999 §4.7): every
reflectance under every test light, and the colours of the material options (metals, §8.3;
fluorescent surfaces, §7.3) when asked for."""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ccjax.materials import scene_metal_spectra
from ccjax.precision import einsum, matmul
from ccjax.scenes._options import Fluorescent, Metallic
from ccjax.world import World


@runtime_checkable
class RadianceModel(Protocol):
    """Anything that gives the light leaving its surfaces under given lights, ``(..., 101) ->
    (..., F, 101)``: :class:`ccjax.materials.FluorescentSurfaces` (the physical model) or
    :class:`ccjax.materials.Characterisation` (the thesis' NNLS characterisation of them)."""

    def radiance(self, illuminants: Float[ArrayLike, "*lights 101"]) -> Float[ArrayLike, "*lights F 101"]: ...


class SceneTables(eqx.Module):
    """Per-world response tables from which scenes are gathered (computed once per world).

    The metal and fluorescent tables are ``None`` unless :meth:`from_world` was asked for them.
    The lights are the world's test illuminants unless :meth:`from_world` was given
    ``lights="train"`` (then every "test illuminant" below reads "training illuminant").

    Attributes:
        surface_rgb: ``(J, S, 3)`` every reflectance under every test illuminant.
        whites: ``(J, 3)`` a perfect white under every test illuminant.
        canonical_rgb: ``(S, 3)`` every reflectance under the canonical light.
        canonical_white: ``(3,)`` a perfect white under the canonical light.
        metal_rgb, canonical_metal_rgb: the metal spectra likewise (or ``None``).
        fluorescent_rgb, canonical_fluorescent_rgb: the fluorescent surfaces likewise (or ``None``).
        lights: which of the world's light sets the tables hold, ``"test"`` or ``"train"`` (static).
    """

    surface_rgb: Float[Array, "J S 3"]  # every reflectance under every test illuminant
    whites: Float[Array, "J 3"]
    canonical_rgb: Float[Array, "S 3"]
    canonical_white: Float[Array, " 3"]
    metal_rgb: Float[Array, "J M 3"] | None = None  # every metal spectrum under every test illuminant
    canonical_metal_rgb: Float[Array, "M 3"] | None = None
    fluorescent_rgb: Float[Array, "J F 3"] | None = None  # every fluorescent surface under every test illuminant
    canonical_fluorescent_rgb: Float[Array, "F 3"] | None = None
    lights: str = eqx.field(static=True, default="test")

    @classmethod
    def from_world(
        cls,
        world: World,
        *,
        metals: Float[ArrayLike, "M 101"] | bool | None = None,
        fluorescent: RadianceModel | None = None,
        lights: str = "test",
    ) -> SceneTables:
        """Tables of ``world`` under its test (or training) illuminants and its canonical light.

        Arguments:
            world: the world.
            metals: metal specular spectra ``(M, 101)`` for :class:`Metallic` highlights, or
                ``True`` for the reflectances of all six metals
                (:func:`ccjax.materials.scene_metal_spectra`; A11: grey metals included), or ``None``.
            fluorescent: a :class:`RadianceModel` for :class:`Fluorescent` surfaces (e.g.
                ``ccjax.materials.synthetic_fluorescent_surfaces()`` or its
                ``characterise(...)``), or ``None``.
            lights: ``"test"`` (the world's test illuminants, the thesis' scene lights) or
                ``"train"`` (its training illuminants).

        Returns:
            :class:`SceneTables`.
        """
        if lights not in ("test", "train"):
            raise ValueError(f"lights: expected 'test' or 'train', got {lights!r}")
        illuminants = world.test_illuminants if lights == "test" else world.train_illuminants
        sensors = world.camera.sensors
        surface_rgb, whites, canonical_rgb, canonical_white = _world_tables(world, illuminants)
        metal_rgb = canonical_metal_rgb = fluorescent_rgb = canonical_fluorescent_rgb = None
        if metals is not None and metals is not False:
            spectra = _metal_table(metals, sensors.dtype)
            lit_sensors = illuminants[:, :, None] * sensors[None]  # (J, 101, 3)
            metal_rgb = einsum("ml,jlc->jmc", spectra, lit_sensors)
            canonical_metal_rgb = matmul(spectra * world.canonical, sensors)
        if fluorescent is not None:
            if not isinstance(fluorescent, RadianceModel):
                raise ValueError(
                    "fluorescent: expected a model with a radiance(illuminants) method, "
                    f"got {type(fluorescent).__name__}"
                )
            spectra = jnp.concatenate([illuminants, world.canonical[None]])
            signals = jnp.asarray(fluorescent.radiance(spectra), dtype=sensors.dtype)  # (J + 1, F, 101)
            if signals.ndim != 3 or signals.shape[0] != spectra.shape[0] or signals.shape[-1] != spectra.shape[-1]:
                raise ValueError(f"fluorescent: radiance of {spectra.shape} lights has shape {signals.shape}")
            if not bool(jnp.all(jnp.isfinite(signals))) or bool(jnp.any(signals < 0)):
                raise ValueError("fluorescent: radiance contains negative or non-finite values")
            responses = matmul(signals, sensors)
            fluorescent_rgb, canonical_fluorescent_rgb = responses[:-1], responses[-1]
        return cls(
            surface_rgb=surface_rgb,
            whites=whites,
            canonical_rgb=canonical_rgb,
            canonical_white=canonical_white,
            metal_rgb=metal_rgb,
            canonical_metal_rgb=canonical_metal_rgb,
            fluorescent_rgb=fluorescent_rgb,
            canonical_fluorescent_rgb=canonical_fluorescent_rgb,
            lights=lights,
        )


@eqx.filter_jit
def _world_tables(world: World, illuminants: Array) -> tuple[Array, Array, Array, Array]:
    """The tables every scene needs, as one program (eagerly, each product is a program of its own
    to compile): every reflectance and a white under every one of the lights and the canonical one."""
    lit_sensors = illuminants[:, :, None] * world.camera.sensors[None]  # (J, 101, 3)
    surface_rgb = einsum("sl,jlc->jsc", world.reflectances, lit_sensors)
    return surface_rgb, world.camera.response(illuminants), world.canonical_rgb, world.canonical_white


def _metal_table(metals, dtype) -> Float[Array, "M 101"]:
    spectra = scene_metal_spectra() if metals is True else np.asarray(metals, dtype=np.float64)
    if spectra.ndim != 2 or spectra.shape[0] < 1 or spectra.shape[1] != 101:
        raise ValueError(f"metals: expected True or spectra of shape (M, 101) with M >= 1, got {spectra.shape}")
    if not np.all(np.isfinite(spectra)) or np.any(spectra < 0):
        raise ValueError("metals: spectra contain negative or non-finite values")
    return jnp.asarray(spectra, dtype=dtype)


def require_tables(tables: SceneTables, metallic: Metallic | None, fluorescent: Fluorescent | None) -> None:
    """A ``ValueError`` naming the option when ``tables`` lack the colours it needs.

    Arguments:
        tables: the scene tables to draw from.
        metallic: the metallic-highlight option (needs ``tables.metal_rgb``), or ``None``.
        fluorescent: the fluorescent option (needs ``tables.fluorescent_rgb``), or ``None``.
    """
    if metallic is not None and tables.metal_rgb is None:
        raise ValueError(
            "metallic: the scene tables have no metals; build them with SceneTables.from_world(world, metals=True)"
        )
    if fluorescent is not None and tables.fluorescent_rgb is None:
        raise ValueError(
            "fluorescent: the scene tables have no fluorescent surfaces; build them with "
            "SceneTables.from_world(world, fluorescent=model)"
        )


def default_fluorescent(model: RadianceModel | None) -> RadianceModel:
    """``model``, or the default fluorescent surfaces (the nine synthetic ones' physical model)."""
    if model is not None:
        return model
    from ccjax.materials import synthetic_fluorescent_surfaces

    return synthetic_fluorescent_surfaces()
