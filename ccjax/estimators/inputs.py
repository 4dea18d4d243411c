"""Input checks at the Python boundary: whether an estimator takes the kind of input a caller has
(:func:`require_kind`; the kind itself is :func:`ccjax.estimators.base.input_kind_of`), and surface
lists and images checked before they reach a model (:func:`validate_scene`, :func:`validate_image`,
:func:`validate_input`), each raising a ``ValueError`` that names the argument and what was wrong."""

import numpy as np

from ccjax import limits
from ccjax.estimators.base import DESCRIBED, KINDS, SHAPES, AbstractEstimator, input_kind_of

__all__ = ["require_kind", "validate_image", "validate_input", "validate_scene"]


def require_kind(model: AbstractEstimator, kind: str, what: str) -> None:
    """Raise a ``ValueError`` unless ``model`` takes input of ``kind``.

    For callers that accept one kind only, e.g. synthetic sweeps over surface lists
    (``require_kind(model, "surfaces", "methods")``), which cannot run image estimators.

    Arguments:
        model: a fitted estimator.
        kind: ``"surfaces"`` or ``"image"``.
        what: the caller's argument name, quoted first in the message.
    """
    if kind not in KINDS:
        raise ValueError(f"kind: expected one of {KINDS}, got {kind!r}")
    actual = input_kind_of(model)
    if actual == kind:
        return
    name = type(model).__name__
    if actual == "image":
        advice = (
            "run it on images: ccjax.estimate(model, image) or the image pipeline (ccjax.preprocessing.estimate_image)"
        )
    else:
        advice = (
            "images reach surface estimators through the image pipeline "
            "(ccjax.preprocessing.estimate_image), which makes surface lists"
        )
    raise ValueError(
        f"{what}: {name} is {DESCRIBED[actual]} ({SHAPES[actual]}), but this needs "
        f"{DESCRIBED[kind]} ({SHAPES[kind]}); {advice}"
    )


def _checked_values(x, name: str, shapes: tuple[str, str], ndims: tuple[int, int]) -> np.ndarray:
    """``x`` as float32 after the checks common to every input kind; ``ndims`` are the ranks of
    one scene and of a batch (their difference is 1, the pixel axes are ``ndims[0] - 1``)."""
    array = np.asarray(x)
    if array.dtype == object or not (np.issubdtype(array.dtype, np.floating) or np.issubdtype(array.dtype, np.integer)):
        raise ValueError(f"{name}: expected a real numeric array, got dtype {array.dtype}")
    if array.ndim not in ndims or array.shape[-1] != 3:
        raise ValueError(f"{name}: expected shape {' or '.join(shapes)}, got {array.shape}")
    if 0 in array.shape[-ndims[0] : -1]:
        raise ValueError(f"{name}: has no pixels (shape {array.shape}); pass a mask to mark missing data instead")
    array = array.astype(np.float32)
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    if np.any(array < 0):
        raise ValueError(f"{name}: contains negative values (linear camera RGB is non-negative)")
    if array.size and array.max() > limits.VALUE.value:
        raise ValueError(f"{name}: {array.max():g} is over the limit of {limits.VALUE.value:g} ({limits.VALUE.what})")
    return array


def _checked_mask(mask, shape: tuple[int, ...]) -> np.ndarray:
    if mask is None:
        return np.ones(shape, bool)
    mask_array = np.asarray(mask)
    if mask_array.dtype != bool:
        raise ValueError(f"mask: expected a boolean array, got dtype {mask_array.dtype}")
    if mask_array.shape != shape:
        raise ValueError(f"mask: expected shape {shape}, got {mask_array.shape}")
    return mask_array


def validate_scene(rgb, mask, *, name: str = "rgb") -> tuple[np.ndarray, np.ndarray]:
    """Check surface-list input at the Python boundary; raise ``ValueError`` naming the argument.

    Arguments:
        rgb: ``(P, 3)`` or ``(B, P, 3)`` non-negative finite floats.
        mask: ``None`` (all valid) or booleans of shape ``rgb.shape[:-1]``.
        name: the argument's name in the error messages.

    Returns:
        ``(rgb, mask)`` as NumPy float32 / bool arrays.
    """
    array = _checked_values(rgb, name, ("(P, 3)", "(B, P, 3)"), (2, 3))
    return array, _checked_mask(mask, array.shape[:-1])


def validate_image(image, mask, *, name: str = "image") -> tuple[np.ndarray, np.ndarray]:
    """Check image input at the Python boundary; raise ``ValueError`` naming the argument.

    Arguments:
        image: ``(H, W, 3)`` or ``(B, H, W, 3)`` non-negative finite floats.
        mask: ``None`` (all valid) or booleans of shape ``image.shape[:-1]``.
        name: the argument's name in the error messages.

    Returns:
        ``(image, mask)`` as NumPy float32 / bool arrays.
    """
    array = _checked_values(image, name, ("(H, W, 3)", "(B, H, W, 3)"), (3, 4))
    return array, _checked_mask(mask, array.shape[:-1])


def validate_input(model: AbstractEstimator, x, mask, *, name: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Check ``x`` against what ``model`` takes (its input kind); raise ``ValueError`` naming the
    argument, the estimator, its kind and what to pass.

    Arguments:
        model: a fitted estimator.
        x: one surface list ``(P, 3)`` for surface estimators (a 3-D array is refused: an image
            ``(H, W, 3)`` and a batch ``(B, P, 3)`` look alike); ``(H, W, 3)`` / ``(B, H, W, 3)``
            for image estimators.
        mask: ``None`` or booleans of shape ``x.shape[:-1]``.
        name: the argument's name in messages (default ``"rgb"`` for surface estimators,
            ``"image"`` for image estimators).

    Returns:
        ``(x, mask)`` as NumPy float32 / bool arrays.
    """
    kind = input_kind_of(model)
    name = name or ("rgb" if kind == "surfaces" else "image")
    ndim = np.ndim(x)
    if kind == "image" and ndim == 2:
        raise ValueError(
            f"{name}: {type(model).__name__} is an image estimator and takes {SHAPES['image']} "
            f"(or a batch (B, H, W, 3)); got a surface list of shape {np.shape(x)}. Pass the image itself, "
            "or use a surface estimator for surface lists"
        )
    if kind == "surfaces" and ndim in (3, 4):
        # An image (H, W, 3) has the shape of a batch of H surface lists: estimating it would give one
        # light per image row, so the caller says which it is.
        raise ValueError(
            f"{name}: {type(model).__name__} is a surface estimator and takes one surface list "
            f"{SHAPES['surfaces']}; got shape {np.shape(x)}. For an image, estimate it as one scene "
            "through the image pipeline (ccjax.preprocessing.estimate_image) or pass "
            f"{name}.reshape(-1, 3) with mask.reshape(-1); for a batch of surface lists (B, P, 3) use "
            "ccjax.estimate_batch(model, rgb, mask)"
        )
    if kind == "image":
        return validate_image(x, mask, name=name)
    return validate_scene(x, mask, name=name)
