"""The camera linearisation F of Barnard 1999 §3.4 (eqs. 3.14-3.15): apply, invert, carry."""

from __future__ import annotations

from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float


@dataclass(frozen=True)
class Linearisation:
    """The fitted linearisation ``F(x) = x - a0 - a1 exp(-C (x - b))`` per channel (eq. 3.14).

    Hashable, so it can be a :class:`~ccjax.camera.Camera`'s static ``linearisation``. Calling it
    maps raw responses ``(..., 3)`` to linear ones. ``a1 = 0`` is the offset-only form (3.15).

    Attributes:
        a0: offset per channel.
        a1: exponential term's amplitude per channel (0: the offset-only form).
        exp_rate: the exponential rate ``C`` per channel.
        black: the camera black ``b`` per channel.
    """

    a0: tuple[float, float, float]
    a1: tuple[float, float, float]
    exp_rate: tuple[float, float, float]
    black: tuple[float, float, float]

    @classmethod
    def per_channel(cls, a0, a1, exp_rate, black) -> Linearisation:
        """Build F from per-channel values: each argument a scalar (the same for every channel) or
        three numbers (R, G, B).

        Arguments:
            a0: offset.
            a1: exponential term's amplitude (0: the offset-only form).
            exp_rate: the exponential rate ``C``.
            black: the camera black ``b``.

        Returns:
            The :class:`Linearisation`.
        """

        def triple(values) -> tuple[float, float, float]:
            r, g, b = (float(v) for v in np.broadcast_to(np.asarray(values, np.float64), (3,)))
            return r, g, b

        return cls(a0=triple(a0), a1=triple(a1), exp_rate=triple(exp_rate), black=triple(black))

    def __call__(self, raw: Float[ArrayLike, "... 3"]) -> Float[Array, "... 3"]:
        return apply_linearisation(
            raw, jnp.asarray(self.a0), jnp.asarray(self.a1), jnp.asarray(self.exp_rate), jnp.asarray(self.black)
        )


def apply_linearisation(raw, a0, a1, exp_rate, black):
    """``F(raw) = raw - a0 - a1 exp(-C (raw - b))`` element-wise per channel (eq. 3.14).

    Arguments:
        raw: raw responses ``(..., 3)``.
        a0, a1, exp_rate, black: the parameters of ``F`` per channel (broadcast against ``raw``).

    Returns:
        The linear responses, the shape of ``raw``.
    """
    raw = jnp.asarray(raw)
    return raw - a0 - a1 * jnp.exp(-exp_rate * (raw - black))


def invert_linearisation(linear, a0, a1, exp_rate, black, *, steps: int = 60):
    """Raw values ``x`` with ``F(x) = linear`` (Newton; F is strictly increasing for a1, C >= 0).

    Arguments:
        linear: linear responses ``(..., 3)``.
        a0, a1, exp_rate, black: the parameters of ``F`` per channel.
        steps: Newton iterations.

    Returns:
        The raw values, the shape of ``linear``.
    """
    linear = np.asarray(linear, dtype=np.float64)
    x = linear + a0 + np.maximum(a1, 0.0)
    for _ in range(steps):
        e = np.exp(-exp_rate * (x - black))
        x = x - (x - a0 - a1 * e - linear) / (1.0 + a1 * exp_rate * e)
    return x
