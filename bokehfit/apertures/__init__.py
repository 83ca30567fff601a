"""Aperture shapes (design.md §3), their real-lens features (§3b) and their samplers.

The samplers ``sample_<shape>(u)`` are the NumPy twins of the WGSL functions
of the same names in ``shaders/apertures.wgsl``. The :class:`Aperture`
(``shapes``) is the one model; ``registry`` names the shapes, ``behaviours``
holds what each sampler family does at angle 0, ``parameters`` the features'
value types, ``features`` the features' records (what a fit and a report know of
each), ``frames`` the image ↔ aperture conversion.
"""

from bokehfit.apertures.samplers import (
    CIRCLE_RADIUS,
    STAR_INNER_RADIUS,
    STAR_OUTER_RADIUS,
    invert_uniform_triangle_sample,
    ngon_circumradius,
    sample_circle,
    sample_hexagon,
    sample_ngon,
    sample_pentagon,
    sample_slit,
    sample_square,
    sample_star,
    sample_triangle,
    sample_uniform_triangle,
    uniform_triangle_pdf,
    ROUNDNESS_POLYGON,
    apply_squeeze,
    invert_rounded_ngon_sample,
    rim_radius,
    rounded_ngon_pdf,
    sample_rounded_ngon,
    vignetting_weight,
)
from bokehfit.apertures.mask import MaskTable, invert_mask_sample, load_mask, mask_pdf, sample_mask
from bokehfit.apertures.outline import Arc, Outline, Segment
from bokehfit.apertures.frames import aperture_rows_to_image, aperture_to_image, image_to_aperture
from bokehfit.apertures.parameters import APERTURE_PARAM_FIELDS, CHANNELS, Chromatic, ParameterSpec, Vignetting
from bokehfit.apertures.features import FEATURE_SPECS, FEATURES, FeatureEvidence, FeatureSpec
from bokehfit.apertures.registry import SHADER_FAMILIES, SHAPES, ShapeSpec, canonical_angle, parse_shape
from bokehfit.apertures.shapes import Aperture, make_aperture

__all__ = [
    "APERTURE_PARAM_FIELDS",
    "Arc",
    "CHANNELS",
    "Chromatic",
    "FEATURES",
    "FEATURE_SPECS",
    "FeatureEvidence",
    "FeatureSpec",
    "MaskTable",
    "Outline",
    "ParameterSpec",
    "ROUNDNESS_POLYGON",
    "Segment",
    "Vignetting",
    "aperture_rows_to_image",
    "aperture_to_image",
    "apply_squeeze",
    "image_to_aperture",
    "invert_mask_sample",
    "load_mask",
    "mask_pdf",
    "sample_mask",
    "invert_rounded_ngon_sample",
    "rim_radius",
    "rounded_ngon_pdf",
    "sample_rounded_ngon",
    "vignetting_weight",
    "Aperture",
    "CIRCLE_RADIUS",
    "SHADER_FAMILIES",
    "SHAPES",
    "STAR_INNER_RADIUS",
    "STAR_OUTER_RADIUS",
    "ShapeSpec",
    "canonical_angle",
    "invert_uniform_triangle_sample",
    "make_aperture",
    "ngon_circumradius",
    "parse_shape",
    "sample_circle",
    "sample_hexagon",
    "sample_ngon",
    "sample_pentagon",
    "sample_slit",
    "sample_square",
    "sample_star",
    "sample_triangle",
    "sample_uniform_triangle",
    "uniform_triangle_pdf",
]
