"""Cameras: sensor curves on the ccjax grid and the response of colour signals.

Image formation (Barnard 1999 eq. 2.5 / 4.1, discretised as in §2.2): the linear response of
channel k to a colour signal ``L`` is ``rho_k = sum_lambda L(lambda) R_k(lambda)``, i.e.
``signal @ sensors``. A camera may carry a linearisation ``F`` (chapter 3); the synthetic world
works on linear responses and never needs it.
"""

from __future__ import annotations

import difflib
import os
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ccjax import data
from ccjax.precision import matmul
from ccjax.spectra import N_WAVELENGTHS, as_spectra, is_colour_distribution, to_colour


class Camera(eqx.Module):
    """A camera: three sensor curves on :data:`ccjax.spectra.WAVELENGTHS`.

    Attributes:
        sensors: ``(101, 3)`` spectral sensitivities (R, G, B columns), non-negative.
        name: a label for printing.
        linearisation: optional callable mapping raw pixel values to linear responses
            (Barnard 1999 ch. 3, ``F``); ``None`` means the camera is linear.
    """

    sensors: Float[Array, "101 3"]
    name: str = eqx.field(static=True, default="custom")
    linearisation: Callable | None = eqx.field(static=True, default=None)

    def __check_init__(self):
        shape = np.shape(self.sensors)
        if shape != (N_WAVELENGTHS, 3):
            raise ValueError(f"sensors: expected shape ({N_WAVELENGTHS}, 3), got {shape}")

    @classmethod
    def from_array(cls, sensors, name: str = "custom") -> Camera:
        """Build a camera from sensor curves, validating them (finite, non-negative).

        Arguments:
            sensors: a ``(101, 3)`` array on :data:`ccjax.spectra.WAVELENGTHS` (R, G, B columns),
                or a three-channel colour-science ``MultiSpectralDistributions`` (resampled as
                sensor curves, zero outside their range).
            name: a label for printing.

        Returns:
            The camera (float32 sensors; float64 when built under ``jax_enable_x64``).
        """
        sensors = as_spectra(sensors, kind="sensor", rows=False)
        if sensors.shape != (N_WAVELENGTHS, 3):
            raise ValueError(f"sensors: expected shape ({N_WAVELENGTHS}, 3), got {sensors.shape}")
        if not np.all(np.isfinite(sensors)):
            raise ValueError("sensors: contains NaN or infinite values")
        if np.any(sensors < 0):
            raise ValueError("sensors: contains negative sensitivities")
        if np.any(sensors.sum(axis=0) <= 0):
            raise ValueError("sensors: a channel has no sensitivity anywhere")
        # JAX's float: float32, or float64 under jax_enable_x64 (cast on the host, then device_put).
        width = jax.dtypes.canonicalize_dtype(np.float64)
        return cls(sensors=jax.device_put(np.asarray(sensors, width)), name=name)

    @classmethod
    def from_colour(cls, sensitivities, name: str | None = None) -> Camera:
        """A camera from colour-science camera sensitivities.

        Arguments:
            sensitivities: a ``colour.characterisation.RGB_CameraSensitivities`` (or any
                ``MultiSpectralDistributions`` with three channels in R, G, B order), or the name of
                one in ``colour.MSDS_CAMERA_SENSITIVITIES`` (e.g. ``"Nikon 5100 (NPL)"``). Resampled
                onto the ccjax grid as sensor curves: linear interpolation, zero outside the
                measured range.
            name: a label (default: the distributions' name).

        Returns:
            The camera.
        """
        if isinstance(sensitivities, str):
            import colour  # imported here: colour-science is slow to import

            known = colour.MSDS_CAMERA_SENSITIVITIES
            if sensitivities not in known:
                raise ValueError(
                    f"sensitivities: {sensitivities!r} is not in colour.MSDS_CAMERA_SENSITIVITIES "
                    f"({', '.join(sorted(known))})"
                )
            sensitivities = known[sensitivities]
        if not is_colour_distribution(sensitivities) or np.ndim(sensitivities.values) != 2:
            raise TypeError(
                "sensitivities: expected colour-science camera sensitivities (a MultiSpectralDistributions), "
                f"got {type(sensitivities).__name__}"
            )
        if sensitivities.values.shape[1] != 3:
            raise ValueError(f"sensitivities: expected 3 channels (R, G, B), got {sensitivities.values.shape[1]}")
        return cls.from_array(sensitivities, name=name or sensitivities.name)

    def to_colour(self):
        """The sensor curves as ``colour.characterisation.RGB_CameraSensitivities`` on the ccjax grid
        (extrapolated as zero outside 380–780 nm, as ccjax treats sensors).

        Returns:
            The colour-science camera sensitivities, labels ``red``, ``green``, ``blue``.
        """
        from colour.characterisation import RGB_CameraSensitivities

        curves = to_colour(np.asarray(self.sensors, np.float64), kind="sensor", name=self.name)
        return RGB_CameraSensitivities(
            curves, labels=["red", "green", "blue"], name=self.name, extrapolator_kwargs=curves.extrapolator_kwargs
        )

    @classmethod
    def from_name(cls, name: str, data_dir: str | os.PathLike | None = None) -> Camera:
        """Look a camera up by name: embedded rawtoaces cameras first, then external data.

        Arguments:
            name: e.g. ``"Canon EOS 5D Mark II"`` (embedded), ``"Sony DXC-930"`` or
                ``"Jiang: Canon 5D Mark II"`` (external data directory).
            data_dir: external data directory (see :func:`ccjax.data.find_data_file`).

        Returns:
            The camera. (colour-science's own cameras: :meth:`from_colour`.)
        """
        embedded = data.rawtoaces_cameras()
        if name in embedded:
            return cls.from_array(embedded[name], name=name)
        if name == "Sony DXC-930":
            return cls.from_array(data.sony_dxc930(data_dir), name=name)
        if name.startswith("Jiang: "):
            jiang = data.jiang_cameras(data_dir)
            if name in jiang:
                return cls.from_array(jiang[name], name=name)
        close = difflib.get_close_matches(name, list(embedded), n=3, cutoff=0.6)
        hint = f" Did you mean {' or '.join(repr(c) for c in close)}?" if close else ""
        raise ValueError(
            f"camera: unknown name {name!r}.{hint} 'Sony DXC-930' and 'Jiang: <model>' need the external data; "
            f"the `ccjax cameras` command (or ccjax.cameras()) lists all {len(embedded)} embedded cameras."
        )

    def response(self, signal: Float[ArrayLike, "... 101"]) -> Float[Array, "... 3"]:
        """Linear camera response of colour signals (reflectance x illuminant), ``signal @ sensors``.

        Arguments:
            signal: ``(..., 101)`` colour signals on the grid.

        Returns:
            ``(..., 3)`` linear responses.
        """
        return matmul(jnp.asarray(signal), self.sensors)


def cameras(data_dir: str | os.PathLike | None = None) -> dict[str, str]:
    """Every camera ccjax can build, name -> source (``"embedded"`` or ``"external"``).

    External cameras are listed only when the external data directory is found.

    Arguments:
        data_dir: external data directory (see :func:`ccjax.data.find_data_file`).

    Returns:
        Name -> source.
    """
    listing = {name: "embedded (rawtoaces-data, Apache-2.0)" for name in data.rawtoaces_cameras()}
    try:
        data.sony_dxc930(data_dir)
        listing["Sony DXC-930"] = "external (sfu_barnard)"
        listing.update({name: "external (Jiang et al. 2013)" for name in data.jiang_cameras(data_dir)})
    except data.DataNotFoundError:
        pass
    return listing
