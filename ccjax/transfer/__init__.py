"""Camera-to-camera maps fitted from spectra (Barnard 1999 §3–§4).

A response is the integral of light x reflectance x sensor, so one scene seen by camera A and by
camera B is related through their curves. Rendering a world's reflectances under its lights through
both cameras gives pairs of responses from which a map A -> B is fitted by least squares; the map
is applied to a labelled image and to its ground truth alike, so photographs of one camera become
training data for another.

* :mod:`ccjax.transfer._maps`: :class:`AbstractCameraMap` and its final forms, :class:`GlobalMap`
  (one 3x3) and :class:`PerLightMap` (a 3x3 per world light, interpolated in chromaticity);
* :mod:`ccjax.transfer._fit`: :func:`fit_camera_map`, the least squares (white-preserving per
  light), :func:`held_back_surfaces`, :func:`paired_responses`; :func:`locus_lights`, the
  smooth lights (blackbody and daylight) to fit a per-light map on instead of a world's;
* :mod:`ccjax.transfer._accuracy`: :func:`map_accuracy` (and :func:`map_errors`, item by item), angular
  errors on held-back surfaces and on whites.

Example::

    from ccjax import World
    from ccjax.transfer import fit_camera_map, held_back_surfaces, map_accuracy

    world = World.default(camera="Canon EOS 600D")
    held = held_back_surfaces(world)
    camera_map = fit_camera_map("Canon EOS 600D", "Canon EOS-1Ds Mark III", world=world, surfaces=~held)
    mapped_image = camera_map.map_rgb(image, truth)  # image (H, W, 3), truth (3,): 600D raw RGB
    mapped_truth = camera_map.map_light(truth)  # the same matrix, largest channel 1
"""

from ccjax.transfer._accuracy import AngularStatistics, MapAccuracy, MapErrors, map_accuracy, map_errors
from ccjax.transfer._fit import SurfaceSelection, fit_camera_map, held_back_surfaces, paired_responses
from ccjax.transfer._lights import BLACKBODY_KELVIN, DAYLIGHT_KELVIN, locus_lights
from ccjax.transfer._maps import AbstractCameraMap, GlobalMap, PerLightMap

__all__ = [
    "BLACKBODY_KELVIN",
    "DAYLIGHT_KELVIN",
    "AbstractCameraMap",
    "AngularStatistics",
    "GlobalMap",
    "MapAccuracy",
    "MapErrors",
    "PerLightMap",
    "SurfaceSelection",
    "fit_camera_map",
    "held_back_surfaces",
    "locus_lights",
    "map_accuracy",
    "map_errors",
    "paired_responses",
]
