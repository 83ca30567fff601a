"""Aperture shapes (design.md §3) and their uniform samplers.

The samplers ``sample_<shape>(u)`` are the NumPy twins of the WGSL functions
of the same names in ``shaders/apertures.wgsl``.
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
)
from bokehfit.apertures.shapes import SHADER_FAMILIES, SHAPES, Aperture, ShapeSpec, canonical_angle, make_aperture

__all__ = [
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
