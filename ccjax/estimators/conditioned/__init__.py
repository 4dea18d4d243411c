"""A camera-conditioned estimator, ``any-camera``: trained once on several cameras' labelled
photographs, it serves any camera of :func:`ccjax.cameras` given only the camera's curves.

Every camera is expressed in one camera-independent space through its curves
(:mod:`._space`: a 3x3 to a fixed reference camera, the mean of the embedded cameras' curves,
fitted on the SFU reflectances under a bank of Planckian, daylight, fluorescent and LED lights);
one FFCC model (log-chroma histograms of pixels and edges, learned filters and bias) is trained in
that space on every training image mapped there by its own camera's map, its histogram's window
set on every plausible light (:func:`window_lights`), not only the training cameras' (:mod:`._fitting`); at
inference the camera's image is mapped in, FFCC's posterior combined with shades of grey's
observation of the light (:class:`GreyObservation`: FFCC's filters learn the training scenes, and
on unlike scenes a statistic of the image's own pixels corrects them), and the light mapped back
(:mod:`._model`).
The camera's *fingerprint* (its whites under the bank) names its twins, which leave-one-camera-out
keeps out of a fold. Camera augmentation (each training image also mapped into other cameras,
real and sampled, through the per-light maps of :mod:`ccjax.transfer`) is built in
:mod:`ccjax.runs.augmented`.
"""

from ccjax.estimators.conditioned._fitting import to_reference, train
from ccjax.estimators.conditioned._grey import GreyObservation, fit_grey_observation, no_grey_observation
from ccjax.estimators.conditioned._model import AnyCamera
from ccjax.estimators.conditioned._space import (
    TWIN_DEGREES,
    WHITE_WEIGHT,
    fingerprint,
    fingerprint_distance,
    light_bank,
    model_name,
    reference_matrix,
    reference_sensors,
    twins,
    window_lights,
)
from ccjax.estimators.registry import register

__all__ = [
    "TWIN_DEGREES",
    "WHITE_WEIGHT",
    "AnyCamera",
    "GreyObservation",
    "fingerprint",
    "fingerprint_distance",
    "fit_grey_observation",
    "init_any_camera",
    "light_bank",
    "model_name",
    "no_grey_observation",
    "reference_matrix",
    "reference_sensors",
    "to_reference",
    "train",
    "twins",
    "window_lights",
]

LABEL = "any-camera"


def init_any_camera() -> AnyCamera:
    """An untrained, unbound :class:`AnyCamera` (an untrained FFCC, the identity map).

    Returns:
        The model.
    """
    import jax.numpy as jnp

    from ccjax.estimators.ffcc import init_ffcc

    return AnyCamera(core=init_ffcc(), grey=no_grey_observation(), matrix=jnp.eye(3, dtype=jnp.float32))


@register(
    r"any-camera",
    example="any-camera",
    description="one model for every camera, bound by its curves (untrained until ccjax train --method any-camera)",
    input_kind="image",
    untrained=True,
)
def _build_any_camera(world, match, **options):
    return init_any_camera()
