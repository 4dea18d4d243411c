"""Materials beyond matte reflectances (Barnard 1999 ch. 7–8): metal specular spectra from optical
constants (:mod:`ccjax.materials.metals`) and synthetic fluorescent surfaces with the thesis'
measurement-based characterisation (:mod:`ccjax.materials.fluorescence`).
"""

from ccjax.materials.fluorescence import FLUORESCENT_PROBABILITY as FLUORESCENT_PROBABILITY
from ccjax.materials.fluorescence import FLUORESCENT_SURFACES as FLUORESCENT_SURFACES
from ccjax.materials.fluorescence import FLUORESCENT_TRAINING_MULTIPLIER as FLUORESCENT_TRAINING_MULTIPLIER
from ccjax.materials.fluorescence import Characterisation as Characterisation
from ccjax.materials.fluorescence import FluorescentParameters as FluorescentParameters
from ccjax.materials.fluorescence import FluorescentSurfaces as FluorescentSurfaces
from ccjax.materials.fluorescence import FluorescentWeights as FluorescentWeights
from ccjax.materials.fluorescence import PredictionError as PredictionError
from ccjax.materials.fluorescence import characterise as characterise
from ccjax.materials.fluorescence import fluorescent_surface as fluorescent_surface
from ccjax.materials.fluorescence import fluorescent_weights as fluorescent_weights
from ccjax.materials.fluorescence import lab_lights as lab_lights
from ccjax.materials.fluorescence import nnls_weights as nnls_weights
from ccjax.materials.fluorescence import prediction_error as prediction_error
from ccjax.materials.fluorescence import synthetic_fluorescent_surfaces as synthetic_fluorescent_surfaces
from ccjax.materials.metals import COLOURED_METALS as COLOURED_METALS
from ccjax.materials.metals import GREY_METALS as GREY_METALS
from ccjax.materials.metals import MET_MULTIPLIER as MET_MULTIPLIER
from ccjax.materials.metals import METAL_MAX_AMOUNT as METAL_MAX_AMOUNT
from ccjax.materials.metals import METAL_PROBABILITY as METAL_PROBABILITY
from ccjax.materials.metals import METALS as METALS
from ccjax.materials.metals import THESIS_CLIP as THESIS_CLIP
from ccjax.materials.metals import OpticalConstants as OpticalConstants
from ccjax.materials.metals import fresnel_reflectance as fresnel_reflectance
from ccjax.materials.metals import metal_reflectance as metal_reflectance
from ccjax.materials.metals import metal_spectra as metal_spectra
from ccjax.materials.metals import optical_constants as optical_constants
from ccjax.materials.metals import scene_metal_spectra as scene_metal_spectra
