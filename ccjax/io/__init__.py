"""Image files: reading linear camera data, writing linear images and sRGB previews, ground truth.

The pipeline's first and last steps (Barnard 1999 §4.6): :func:`read_image` gives a
:class:`LinearImage` on the unit scale with its clipped pixels marked; :func:`write_linear` writes
a corrected image as 16-bit PNG/TIFF and :func:`write_preview` an 8-bit sRGB preview; ground
truth is a CSV ``image,r,g,b[,fold]`` (:func:`read_ground_truth_file`); :func:`read_mask` reads a pixel mask
file (nonzero = usable). :func:`probe_image` validates a file from its header alone, so every
input can be checked before any work and decoded once.
"""

from ccjax.io.files import write_figure, write_file
from ccjax.io.ground_truth import (
    GroundTruth,
    match_ground_truth,
    read_ground_truth,
    read_ground_truth_file,
    unlisted_images,
    write_ground_truth,
)
from ccjax.io.outputs import path_key
from ccjax.io.png import PngHeader, png_header, read_png, write_png
from ccjax.io.preview import (
    encode_srgb,
    preview_matrix,
    preview_matrix_cached,
    srgb_preview,
    srgb_preview_rows,
    write_preview,
)
from ccjax.io.reading import (
    CLIP_FRACTION,
    IMAGE_SUFFIXES,
    RAW_SUFFIXES,
    ImageInfo,
    LinearImage,
    list_images,
    probe_image,
    read_image,
    read_mask,
)
from ccjax.io.writing import encoded_codes, file_run, quantise, write_codes, write_dataset, write_linear

__all__ = [
    "CLIP_FRACTION",
    "IMAGE_SUFFIXES",
    "RAW_SUFFIXES",
    "GroundTruth",
    "ImageInfo",
    "LinearImage",
    "PngHeader",
    "encode_srgb",
    "encoded_codes",
    "file_run",
    "list_images",
    "match_ground_truth",
    "path_key",
    "png_header",
    "preview_matrix",
    "preview_matrix_cached",
    "probe_image",
    "quantise",
    "read_ground_truth",
    "read_ground_truth_file",
    "read_image",
    "read_mask",
    "read_png",
    "srgb_preview",
    "srgb_preview_rows",
    "unlisted_images",
    "write_codes",
    "write_dataset",
    "write_figure",
    "write_file",
    "write_ground_truth",
    "write_linear",
    "write_png",
    "write_preview",
]
