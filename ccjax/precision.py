"""The precision policy: every product that carries physics or statistics is float32-exact on
every backend.

GPUs compute float32 matrix products in TF32 (a 10-bit mantissa) unless told otherwise: measured
on an H200, world responses moved by 2e-4 relative, the brightest white channel by 1e-4 and one
entry of the best-linear sharpening map by 30 %. So the spectral integrations (Barnard 1999 eq.
4.1), camera responses, white normalisation, least squares (§5.1), calibration (§3.4), binning
weights, Colour-by-Correlation sums (§4.5.4), the nets' layers and the losses take their products
through :func:`matmul`, :func:`einsum` and :func:`linear`, which pass ``precision=HIGHEST`` explicitly: the same
numbers on CPU (where a float32 product is exact already) and GPU, with no global setting in the
user's program (an explicit precision overrides ``jax_default_matmul_precision``).

The opt-in: :func:`fast_matmul` computes at the backend's default precision (TF32 on recent
NVIDIA GPUs) inside the named scope :data:`FAST_SCOPE`, for products where a test shows the result
unchanged at TF32. :func:`low_precision_products` walks a function's jaxpr and lists every product
below HIGHEST outside that scope; the test suite runs it over the public estimators, world
responses, sharpening, calibration and losses.

Third-party code whose products take no precision argument (jaxopt's ``BoxOSQP`` forms ``A^T A``
and its matvecs with ``jnp.dot``) is called inside :func:`highest_within`, which raises JAX's
default matmul precision for the code traced in that block only.

``jnp.linalg.solve`` and ``jnp.linalg.lstsq`` need no wrapper: their own products (the
``custom_linear_solve`` matvec, the SVD back-substitution) are HIGHEST, and the checker sees them.
"""

from __future__ import annotations

import contextlib
import typing
from collections.abc import Callable, Iterator

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax import lax
from jax.core import ShapedArray
from jax.extend import core as jax_core
from jaxtyping import Array, ArrayLike, Float

__all__ = [
    "FAST_SCOPE",
    "HIGHEST",
    "einsum",
    "fast_matmul",
    "highest_within",
    "jaxpr_low_precision_products",
    "linear",
    "low_precision_products",
    "matmul",
    "scale_down",
]

HIGHEST = lax.Precision.HIGHEST
"""The precision of every physics or statistics product (float32-exact on every backend)."""

FAST_SCOPE = "ccjax_fast_matmul"
"""The named scope of the opt-in products (:func:`fast_matmul`); the checker skips products in it."""

# Primitives with a ``precision`` parameter: matrix products and convolutions.
_PRODUCTS = ("dot_general", "conv_general_dilated")


def matmul(a: ArrayLike, b: ArrayLike) -> Array:
    """``a @ b`` at ``precision=HIGHEST`` (``jnp.matmul`` semantics: batched, 1-D operands as
    vectors).

    Arguments:
        a, b: the operands.

    Returns:
        The product, float32-exact on every backend.
    """
    return jnp.matmul(a, b, precision=HIGHEST)


def einsum(subscripts: str, *operands: ArrayLike) -> Array:
    """``jnp.einsum(subscripts, *operands)`` at ``precision=HIGHEST``.

    Arguments:
        subscripts: the einsum specification, e.g. ``"sl,jlc->jsc"``.
        *operands: the arrays.

    Returns:
        The contraction, float32-exact on every backend.
    """
    return jnp.einsum(subscripts, *operands, precision=HIGHEST)


def device_array(values: ArrayLike) -> Array:
    """A host array on the default device in the dtype ``jnp.asarray`` would give it (float64
    becomes float32 unless ``jax_enable_x64``), cast by NumPy: ``jnp.asarray`` of a NumPy array
    compiles a small conversion program per shape, which a command's start-up pays for each.

    Arguments:
        values: a NumPy array or anything ``np.asarray`` takes.

    Returns:
        The device array (the same values; a cast rounds to nearest as XLA's does).
    """
    host = np.asarray(values)
    return jax.device_put(host.astype(jax.dtypes.canonicalize_dtype(host.dtype), copy=False))


def fast_matmul(a: ArrayLike, b: ArrayLike) -> Array:
    """The opt-in: ``a @ b`` at the backend's default precision (TF32 on recent NVIDIA GPUs,
    exact float32 on CPU), marked with :data:`FAST_SCOPE` so that :func:`low_precision_products`
    accepts it. Only for products whose results a test shows unchanged at TF32 (10-bit
    mantissas).

    Arguments:
        a, b: the operands.

    Returns:
        The product.
    """
    with jax.named_scope(FAST_SCOPE):
        return jnp.matmul(a, b, precision=lax.Precision.DEFAULT)


def highest_within() -> contextlib.AbstractContextManager:
    """A context in which every product traced defaults to HIGHEST (``jax.default_matmul_precision``,
    a thread-local setting for the block only): for third-party solvers whose products take no
    precision argument. Explicit precisions inside keep theirs (so :func:`fast_matmul` stays fast).

    Returns:
        The context manager.
    """
    return jax.default_matmul_precision("highest")


def _is_highest(precision) -> bool:
    """Whether a product's ``precision`` parameter is float32-exact (HIGHEST for both operands,
    or an algorithm that accumulates and multiplies in float32 or wider)."""
    if isinstance(precision, tuple):
        return all(p == HIGHEST for p in precision)
    if isinstance(precision, lax.DotAlgorithmPreset):
        return precision in (lax.DotAlgorithmPreset.F32_F32_F32, lax.DotAlgorithmPreset.F64_F64_F64)
    return precision == HIGHEST


# Frames of these packages are skipped when naming the source line of a product.
_LIBRARY_FRAMES = ("/jax/", "/jaxlib/", "/equinox/", "/jaxopt/", "/optax/", "/optimistix/", "/lineax/")


def _source_line(traceback) -> str:
    """The innermost frame outside JAX and the libraries on it (the line that asked for the product)."""
    for frame in [] if traceback is None else traceback.frames:
        if not any(part in frame.file_name for part in _LIBRARY_FRAMES):
            return f"{frame.file_name}:{frame.line_num}"
    return "?"


def _walk(jaxpr: jax_core.Jaxpr, fast: bool) -> Iterator[str]:
    for eqn in jaxpr.eqns:
        in_fast = fast or FAST_SCOPE in str(eqn.source_info.name_stack)
        if eqn.primitive.name in _PRODUCTS and not in_fast:
            # Operands of products are arrays (ShapedArray: dtype and shape).
            avals = [typing.cast(ShapedArray, var.aval) for var in eqn.invars]
            floating = any(jnp.issubdtype(aval.dtype, jnp.floating) for aval in avals)
            if floating and not _is_highest(eqn.params.get("precision")):
                shapes = " x ".join(f"{aval.dtype}{list(aval.shape)}" for aval in avals)
                where = _source_line(eqn.source_info.traceback)
                yield f"{eqn.primitive.name} {shapes} precision={eqn.params.get('precision')} at {where}"
        for sub in jax_core.jaxprs_in_params(eqn.params):
            yield from _walk(sub, in_fast)


def low_precision_products(fn: Callable, *args, **kwargs) -> list[str]:
    """The matrix products and convolutions of ``fn(*args, **kwargs)`` below ``precision=HIGHEST``
    outside :data:`FAST_SCOPE`, found by tracing it (``jax.make_jaxpr``; nothing is computed) and
    walking its jaxpr and every sub-jaxpr. Products of integer or boolean operands are exact and
    not listed.

    Arguments:
        fn: a JAX-traceable function.
        *args, **kwargs: example arguments (arrays or shapes with dtypes).

    Returns:
        One line per product: primitive, operand types, precision and the source line.
    """
    return jaxpr_low_precision_products(jax.make_jaxpr(fn)(*args, **kwargs))


def jaxpr_low_precision_products(jaxpr: jax_core.ClosedJaxpr | jax_core.Jaxpr) -> list[str]:
    """:func:`low_precision_products` of a jaxpr already traced (e.g. ``jax.jit(f).trace(...).jaxpr``).

    Arguments:
        jaxpr: the jaxpr.

    Returns:
        One line per product below HIGHEST outside :data:`FAST_SCOPE`.
    """
    return list(_walk(jaxpr.jaxpr if isinstance(jaxpr, jax_core.ClosedJaxpr) else jaxpr, False))


def linear(layer: eqx.nn.Linear, x: Float[Array, " n_in"]) -> Float[Array, " n_out"]:
    """An ``eqx.nn.Linear`` layer on a vector at ``precision=HIGHEST`` (equinox's own call uses
    the backend's default precision): ``weight @ x + bias``.

    Arguments:
        layer: the layer.
        x: ``(in_features,)`` the input.

    Returns:
        ``(out_features,)``.
    """
    y = matmul(layer.weight, x)
    return y if layer.bias is None else y + layer.bias


def scale_down(x: Float[ArrayLike, "..."], largest: Float[ArrayLike, "..."]) -> Float[Array, "..."]:
    """``x / largest`` computed so that it is right at any float32 scale (a zero ``largest``
    leaves ``x`` as it is).

    Dividing by ``largest`` directly is compiled as a product with its reciprocal, which for
    ``largest`` above about 8.5e37 is a subnormal number that devices flush to zero: every value
    came out 0 (an angle of 0 between ``[1e38, 0, 0]`` and ``[0, 1e38, 0]``). Here the exponent
    ``e`` of ``largest = m 2^e`` is shifted out first (``ldexp``, exact), then the mantissa
    ``m`` in ``[0.5, 1)`` divided, whose reciprocal is in ``(1, 2]``.

    Arguments:
        x: the values.
        largest: their scale, broadcast against ``x`` (held out of the gradient).

    Returns:
        ``x / largest``.
    """
    mantissa, exponent = jnp.frexp(jax.lax.stop_gradient(jnp.asarray(largest)))
    return jnp.ldexp(jnp.asarray(x), -exponent) / jnp.where(mantissa != 0, mantissa, 1.0)
