"""Sharpening transforms and the chapter-5 error measures (Barnard 1999 §5.1, §5.2, §5.4, §5.7).

A sharpening transform ``T`` (3x3) replaces responses ``x`` (rows) by ``x @ T``; a diagonal-model
algorithm runs there and its map ``d#`` acts back in camera space as ``T diag(d#) T^-1``.

Scale: white's brightest channel is 1, so RGB mapping errors are multiplied by
:data:`THESIS_SCALE` (255) to compare with the thesis' tables.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ccjax.precision import matmul
from ccjax.world import World

THESIS_SCALE = 255.0
"""The thesis' units: the brightest channel of white is 255 (ccjax's is 1)."""


def database_responses(world: World, spectra: Float[Array, "... 101"]) -> Float[Array, "... S 3"]:
    """Camera responses of every reflectance of ``world`` under each illuminant spectrum (§5.1).

    Arguments:
        world: the world (reflectances, camera).
        spectra: ``(..., 101)`` illuminant spectra.

    Returns:
        ``(..., S, 3)`` responses (rows are surfaces, the thesis' ``A``/``B`` matrices).
    """
    spectra = jnp.asarray(spectra)
    return world.camera.response(world.reflectances * spectra[..., None, :])


def best_linear_map(source: Float[Array, "S 3"], target: Float[Array, "S 3"]) -> Float[Array, "3 3"]:
    """Least-squares ``M`` with ``source @ M ~ target`` (Barnard 1999 §5.1; the 3x3 normal equations).

    Arguments:
        source: ``(S, 3)`` database under the source light.
        target: ``(S, 3)`` database under the canonical light.

    Returns:
        ``(3, 3)`` map ``M``.
    """
    gram = matmul(source.T, source)
    return jnp.linalg.solve(gram, matmul(source.T, target))


def mapping_error(
    source: Float[Array, "S 3"],
    target: Float[Array, "S 3"],
    transform: Float[Array, "3 3"],
    diagonal: Float[Array, " 3"],
) -> Float[Array, ""]:
    """RMS RGB mapping error over the whole reflectance set (Barnard 1999 §5.4):
    ``sqrt(mean_j |((x_j T) * d#) T^-1 - c_j|^2)`` on the scale of its inputs.

    Arguments:
        source: ``(S, 3)`` database under the scene light.
        target: ``(S, 3)`` database under the canonical light.
        transform: sharpening ``T`` (identity: no sharpening).
        diagonal: ``d#``, the map in sharpened space.

    Returns:
        The RMS error (a scalar).
    """
    mapped = matmul(matmul(source, transform) * diagonal, jnp.linalg.inv(transform))
    return jnp.sqrt(jnp.mean(jnp.sum((mapped - target) ** 2, axis=-1)))


def best_linear_error(source: Float[Array, "S 3"], target: Float[Array, "S 3"]) -> Float[Array, ""]:
    """RMS RGB error of the best linear map (BEST-LINEAR of Barnard 1999 §5.7).

    Arguments:
        source: ``(S, 3)`` database under the scene light.
        target: ``(S, 3)`` database under the canonical light.

    Returns:
        The RMS error (a scalar).
    """
    residual = matmul(source, best_linear_map(source, target)) - target
    return jnp.sqrt(jnp.mean(jnp.sum(residual**2, axis=-1)))


def best_diagonal_map(
    source: Float[Array, "S 3"], target: Float[Array, "S 3"], transform: Float[Array, "3 3"]
) -> Float[Array, " 3"]:
    """BEST-DIAGONAL's ``d#`` (Barnard 1999 §5.7): least squares in camera space over three
    unknowns, ``argmin_d |((X T) * d) T^-1 - X_c|_F``.

    The mapped matrix is ``sum_k d_k y_k t_k`` (``y_k`` column k of ``X T``, ``t_k`` row k of
    ``T^-1``): linear in ``d`` with a three-column design whose column k is ``vec(y_k t_k)``. It is
    solved as least squares on that design rather than by its normal equations
    ``((Y^T Y) * (U U^T)) d = diag(Y^T X_c U^T)``, whose condition number is the design's squared:
    in float32 they fail for an ill-conditioned ``T``.

    Arguments:
        source: ``(S, 3)`` database under the scene light.
        target: ``(S, 3)`` database under the canonical light.
        transform: sharpening ``T``.

    Returns:
        ``(3,)`` diagonal map in sharpened space.
    """
    sharp = matmul(source, transform)
    inverse = jnp.linalg.inv(transform)
    # Row (s, j) of the design: sharp[s, k] * inverse[k, j] for each unknown d_k.
    design = (sharp[:, None, :] * inverse.T[None, :, :]).reshape(-1, 3)
    return jnp.linalg.lstsq(design, target.reshape(-1))[0]


def diagonal_error(
    source: Float[Array, "S 3"], target: Float[Array, "S 3"], transform: Float[Array, "3 3"]
) -> Float[Array, ""]:
    """Mapping error of the best diagonal map in the space sharpened by ``transform`` (§5.7).

    Arguments:
        source: ``(S, 3)`` database under the scene light.
        target: ``(S, 3)`` database under the canonical light.
        transform: sharpening ``T``.

    Returns:
        The RMS error (a scalar).
    """
    return mapping_error(source, target, transform, best_diagonal_map(source, target, transform))


def actual_error(
    source: Float[Array, "S 3"],
    target: Float[Array, "S 3"],
    transform: Float[Array, "3 3"],
    truth: Float[Array, " 3"],
    canonical_white: Float[Array, " 3"],
) -> Float[Array, ""]:
    """Mapping error of ACTUAL (Barnard 1999 §5.7): the diagonal map ``(w_C T) / (e T)`` of the
    true white ``e`` in the space sharpened by ``transform``.

    Arguments:
        source: ``(S, 3)`` database under the scene light.
        target: ``(S, 3)`` database under the canonical light.
        transform: sharpening ``T``.
        truth: ``(3,)`` camera RGB of white under the scene light.
        canonical_white: ``(3,)`` camera RGB of white under the canonical light.

    Returns:
        The RMS error (a scalar).
    """
    sharp_map = matmul(canonical_white, transform) / matmul(truth, transform)
    return mapping_error(source, target, transform, sharp_map)


@jax.jit
def _sharpness_kernel(sensors, reflectances, target, spectra):
    def one(spectrum):
        source = matmul(reflectances * spectrum, sensors)
        return best_linear_error(source, target), diagonal_error(source, target, jnp.eye(3, dtype=target.dtype))

    return jax.lax.map(one, spectra)


def sharpness(world: World, spectra: Float[Array, "J 101"] | None = None) -> dict[str, float]:
    """Sharpness of the camera (Barnard 1999 §5.7): RMS over illuminants of BEST-LINEAR's error
    divided by that of BEST-DIAGONAL without sharpening (<= 1; 1 for delta-function sensors).

    Arguments:
        world: the world; its camera is measured.
        spectra: illuminants to average over (default: the world's test illuminants).

    Returns:
        ``{"best_linear", "best_diagonal", "ratio"}``, errors in thesis units (white = 255).
    """
    spectra = jnp.asarray(world.test_illuminants if spectra is None else spectra)
    count = spectra.shape[0]
    # Pad the light axis to a multiple of 64 so worlds of similar size share one compilation.
    padded = jnp.concatenate([spectra, jnp.repeat(spectra[:1], -count % 64, axis=0)])
    linear, diagonal = _sharpness_kernel(world.camera.sensors, world.reflectances, world.canonical_rgb, padded)
    linear, diagonal = linear[:count], diagonal[:count]
    rms_linear = float(jnp.sqrt(jnp.mean(linear**2))) * THESIS_SCALE
    rms_diagonal = float(jnp.sqrt(jnp.mean(diagonal**2))) * THESIS_SCALE
    return {"best_linear": rms_linear, "best_diagonal": rms_diagonal, "ratio": rms_linear / rms_diagonal}


def normalise_transform(transform: np.ndarray) -> np.ndarray:
    """The thesis' gauge for a sharpening transform (Barnard 1999 §5.2).

    Columns are scaled to unit length; then, greedily, the largest remaining ``|T_rc|`` (over rows
    and columns not yet placed) puts column ``c`` at position ``r``, negated if that entry is
    negative — so the diagonal is as large and positive as possible, which keeps sharpened
    responses positive more often. Errors using ``T ... T^-1`` do not change.

    Arguments:
        transform: ``(3, 3)`` invertible ``T``.

    Returns:
        ``(3, 3)`` NumPy float64 ``T`` in the gauge.
    """
    transform = np.asarray(transform, dtype=np.float64)
    columns = transform / np.linalg.norm(transform, axis=0, keepdims=True)
    out = np.empty_like(columns)
    rows, cols = set(range(3)), set(range(3))
    for _ in range(3):
        r, c = max(((r, c) for r in rows for c in cols), key=lambda rc: abs(columns[rc]))
        out[:, r] = columns[:, c] * np.sign(columns[r, c] or 1.0)
        rows.remove(r)
        cols.remove(c)
    return out


def database_sharpening(source, target) -> np.ndarray:
    """Database sharpening (Barnard 1999 §5.1): ``T`` = eigenvectors of the best linear map ``M``
    from ``source`` to ``target``, normalised and ordered by :func:`normalise_transform`.

    Complex eigenvectors: the thesis zeroes their imaginary parts, but a conjugate pair
    ``a +- i b`` then gives two equal columns ``a`` and a singular ``T``. We use the real block
    form instead: the pair is replaced by ``a`` and ``b``, which span the same invariant plane of
    ``M`` and are linearly independent whenever the eigenvectors are (so ``T`` stays invertible).
    ``M`` is then block diagonal (not diagonal) in that basis; the diagonal map used there is the
    best one (:func:`best_diagonal_map`), as for any other ``T``.

    Arguments:
        source: ``(S, 3)`` database under the source light.
        target: ``(S, 3)`` database under the canonical light.

    Returns:
        ``(3, 3)`` NumPy float64 ``T``.
    """
    source = np.asarray(source, dtype=np.float64)
    target = np.asarray(target, dtype=np.float64)
    linear = np.linalg.lstsq(source, target, rcond=None)[0]
    values, vectors = np.linalg.eig(linear)
    columns, used = [], set()
    for k in range(3):
        if k in used:
            continue
        if abs(values[k].imag) <= 1e-12 * abs(values[k]):
            columns.append(np.real(vectors[:, k]))
            used.add(k)
        else:
            partner = next(j for j in range(3) if j != k and j not in used)
            columns += [np.real(vectors[:, k]), np.imag(vectors[:, k])]
            used |= {k, partner}
    return normalise_transform(np.stack(columns, axis=1))


def average_sharpening(world: World) -> np.ndarray:
    """ "ave" sharpening (Barnard 1999 §5.2): database sharpening for the mean normalised
    training illuminant.

    Arguments:
        world: training illuminants, reflectances, canonical light.

    Returns:
        ``(3, 3)`` NumPy float64 ``T``.
    """
    mean_light = jnp.mean(world.train_illuminants, axis=0)
    return database_sharpening(database_responses(world, mean_light), world.canonical_rgb)


def optimal_sharpening(world: World, spectra: Float[Array, "J 101"] | None = None) -> np.ndarray:
    """ "opt" sharpening (Barnard 1999 §5.2): one database sharpening per illuminant (the
    scene's true light).

    Arguments:
        world: reflectances, canonical light.
        spectra: ``(J, 101)`` lights (default: the world's test illuminants).

    Returns:
        ``(J, 3, 3)`` transforms.
    """
    spectra = world.test_illuminants if spectra is None else spectra
    sources = np.asarray(database_responses(world, spectra))
    target = np.asarray(world.canonical_rgb)
    return np.stack([database_sharpening(source, target) for source in sources])
