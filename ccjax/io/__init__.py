"""Image files: reading linear camera data, writing linear images and sRGB previews, ground truth.

The pipeline's first and last steps (Barnard 1999 §4.6): :func:`read_image` gives a
:class:`LinearImage` on the unit scale with its clipped pixels marked; :func:`write_linear` writes
a corrected image as 16-bit PNG/TIFF and :func:`write_preview` an 8-bit sRGB preview; ground
truth is a CSV ``image,r,g,b[,fold]`` (:func:`read_ground_truth_file`); :func:`read_mask` reads a pixel mask
file (nonzero = usable). :func:`probe_image` validates a file from its header alone, so every
input can be checked before any work and decoded once.
"""

from ccjax.io.ground_truth import GroundTruth as GroundTruth
from ccjax.io.ground_truth import match_ground_truth as match_ground_truth
from ccjax.io.ground_truth import read_ground_truth as read_ground_truth
from ccjax.io.ground_truth import read_ground_truth_file as read_ground_truth_file
from ccjax.io.ground_truth import write_ground_truth as write_ground_truth
from ccjax.io.png import PngHeader as PngHeader
from ccjax.io.png import png_header as png_header
from ccjax.io.png import read_png as read_png
from ccjax.io.png import write_png as write_png
from ccjax.io.preview import preview_matrix as preview_matrix
from ccjax.io.preview import preview_matrix_cached as preview_matrix_cached
from ccjax.io.preview import srgb_preview as srgb_preview
from ccjax.io.preview import srgb_preview_rows as srgb_preview_rows
from ccjax.io.preview import write_preview as write_preview
from ccjax.io.reading import CLIP_FRACTION as CLIP_FRACTION
from ccjax.io.reading import IMAGE_SUFFIXES as IMAGE_SUFFIXES
from ccjax.io.reading import RAW_SUFFIXES as RAW_SUFFIXES
from ccjax.io.reading import ImageInfo as ImageInfo
from ccjax.io.reading import LinearImage as LinearImage
from ccjax.io.reading import list_images as list_images
from ccjax.io.reading import probe_image as probe_image
from ccjax.io.reading import read_image as read_image
from ccjax.io.reading import read_mask as read_mask
from ccjax.io.writing import quantise as quantise
from ccjax.io.writing import write_codes as write_codes
from ccjax.io.writing import write_dataset as write_dataset
from ccjax.io.writing import write_linear as write_linear
