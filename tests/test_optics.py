"""Defocus geometry (design.md §4): circle of confusion, f-stop, size conventions.

The expected values are worked out by hand from the formulas of design.md §4,
not from bokehfit's code:

thin lens   c = (f/N) · f · |d − d_f| / (d · (d_f − f)),  d → ∞:  c = f² / (N (d_f − f))
pinhole     c = (f/N) · f · |d − d_f| / (d · d_f)          (the renderer's camera)

All lengths in mm inside the formulas; the functions take distances in metres.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from bokehfit.apertures import make_aperture
from bokehfit.errors import InputError
from bokehfit.optics import circumscribed_fstop, coc_mm, fstop_from_coc, light_distance_from_coc, pixel_pitch_mm

#: Circumradius of each unit-area shape at scale 1 (design.md §3 table).
CIRCUMRADIUS = {
    "circle": 1 / math.sqrt(math.pi),  # 0.5641896
    "square": math.sqrt(2) / 2,  # half the diagonal of the unit square
    "triangle": 0.8773827,
    "pentagon": 0.6485252,
    "hexagon": 0.6204032,
    "star": 0.7884710,
}
#: Relative agreement asked of float32 arithmetic against float64 (float32 ε = 6e-8; a few operations).
FLOAT32_RTOL = 1e-6


# --------------------------------------------------------------------------------------
# Hand-computed values: 50 mm at f/2 focused at 2 m (d_f − f = 1950 mm)
# --------------------------------------------------------------------------------------

HAND = [
    # light_m, lens, c_mm: the arithmetic, f/N = 25 mm
    (10.0, "thin", 25 * 50 * 8000 / (10000 * 1950)),  # 0.5128205 mm
    (10.0, "pinhole", 25 * 50 * 8000 / (10000 * 2000)),  # 0.5 mm
    (1.5, "thin", 25 * 50 * 500 / (1500 * 1950)),  # 0.2136752 mm (light in front of the focus plane)
    (1.5, "pinhole", 25 * 50 * 500 / (1500 * 2000)),  # 0.2083333 mm
    (math.inf, "thin", 2500 / (2 * 1950)),  # 0.6410256 mm
    (math.inf, "pinhole", 2500 / (2 * 2000)),  # 0.625 mm
]


@pytest.mark.parametrize("light_m,lens,expected", HAND, ids=[f"{d}m-{lens}" for d, lens, _ in HAND])
def test_coc_matches_hand_computed_value(light_m, lens, expected):
    assert coc_mm(2.0, 50.0, 2.0, light_m, lens_model=lens) == pytest.approx(expected, rel=1e-12)


def test_coc_literal_values():
    """The same hand results written as decimals, so a slip in the arithmetic above would show."""
    assert coc_mm(2.0, 50.0, 2.0, 10.0) == pytest.approx(0.5128205128, rel=1e-9)
    assert coc_mm(2.0, 50.0, 2.0, 10.0, lens_model="pinhole") == pytest.approx(0.5, rel=1e-12)
    assert coc_mm(2.0, 50.0, 2.0, math.inf) == pytest.approx(0.6410256410, rel=1e-9)


def test_default_photo_disc_size():
    """examples/make_default_photo.py: 85 mm, f/2, focus 3 m, 36 mm sensor, 1600 px wide.

    c = 85² / (2 · 2915) = 1.2392796 mm; × 1600 / 36 = 55.079 px (the "far discs 55.1 px").
    """
    c = coc_mm(2.0, 85.0, 3.0, math.inf)
    assert c == pytest.approx(7225 / 5830, rel=1e-12)
    assert c / pixel_pitch_mm(36.0, 1600, 1067) == pytest.approx(55.0790, abs=1e-3)


def test_pinhole_differs_from_thin_lens_by_one_minus_f_over_df():
    for light in (0.5, 1.5, 10.0, math.inf):
        thin = coc_mm(2.8, 85.0, 3.0, light, lens_model="thin")
        pinhole = coc_mm(2.8, 85.0, 3.0, light, lens_model="pinhole")
        assert pinhole / thin == pytest.approx(1 - 85.0 / 3000.0, rel=1e-12)


def test_coc_approaches_the_infinity_formula():
    far = coc_mm(4.0, 35.0, 1.2, 1e9)
    assert far == pytest.approx(coc_mm(4.0, 35.0, 1.2, math.inf), rel=1e-6)


def test_pixel_pitch_uses_the_long_side():
    assert pixel_pitch_mm(36.0, 6000, 4000) == pytest.approx(0.006)
    assert pixel_pitch_mm(36.0, 4000, 6000) == pytest.approx(0.006)  # portrait


# --------------------------------------------------------------------------------------
# f-stop: the inverse of the CoC, for both lens models
# --------------------------------------------------------------------------------------

FSTOPS = (0.95, 1.4, 2.0, 5.6, 16.0)
GEOMETRIES = [
    # focal mm, focus m, light m
    (50.0, 2.0, 10.0),
    (85.0, 3.0, math.inf),
    (24.0, 0.5, 0.3),  # light in front of the focus plane
    (200.0, 10.0, 1000.0),
    (100.0, 0.2, 0.25),  # macro: focus only twice the focal length
]


@pytest.mark.parametrize("lens", ["thin", "pinhole"])
@pytest.mark.parametrize("geometry", GEOMETRIES, ids=lambda g: f"f{g[0]:g}-df{g[1]:g}-d{g[2]:g}")
def test_fstop_round_trip(lens, geometry):
    focal, focus, light = geometry
    for n in FSTOPS:
        c = coc_mm(n, focal, focus, light, lens_model=lens)
        assert c > 0
        assert fstop_from_coc(c, focal, focus, light, lens_model=lens) == pytest.approx(n, rel=1e-12)


@pytest.mark.parametrize("lens", ["thin", "pinhole"])
@pytest.mark.parametrize(
    "geometry", [g for g in GEOMETRIES if math.isfinite(g[2])], ids=lambda g: f"f{g[0]:g}-df{g[1]:g}-d{g[2]:g}"
)
def test_light_distance_round_trip(lens, geometry):
    """The light distance that makes a disc at EXIF's f-stop: the inverse of coc_mm in d, on either side.

    (A light at infinity has no finite round trip: the next test covers it as the bound.)
    """
    focal, focus, light = geometry
    side = "far" if light > focus else "near"
    for n in FSTOPS:
        c = coc_mm(n, focal, focus, light, lens_model=lens)
        assert light_distance_from_coc(c, n, focal, focus, side, lens_model=lens) == pytest.approx(light, rel=1e-9)


def test_no_light_behind_the_focus_plane_makes_a_disc_larger_than_infinity_does():
    """f² / (N (d_f − f)) is the far side's largest disc: c = (f/N)·f·(1 − d_f/d)/(d_f − f) < it for every d."""
    at_infinity = 85.0**2 / (1.8 * (7270.0 - 85.0))  # 0.5586 mm
    assert coc_mm(1.8, 85.0, 7.27, math.inf) == pytest.approx(at_infinity, rel=1e-12)
    assert light_distance_from_coc(at_infinity * 1.001, 1.8, 85.0, 7.27, "far") is None
    assert light_distance_from_coc(at_infinity * 0.5, 1.8, 85.0, 7.27, "far") == pytest.approx(2 * 7.27, rel=1e-12)
    assert light_distance_from_coc(at_infinity, 1.8, 85.0, 7.27, "near") == pytest.approx(7.27 / 2, rel=1e-12)


@pytest.mark.parametrize("light_m", [7.5, 10.0, 30.0, 1e3, 1e6])
def test_lights_at_infinity_give_an_upper_bound_on_the_fstop(light_m):
    """A disc read for lights at infinity gives the largest f-stop any light behind the focus plane allows."""
    c = 0.3
    bound = fstop_from_coc(c, 85.0, 7.27, math.inf)
    assert fstop_from_coc(c, 85.0, 7.27, light_m) < bound
    assert fstop_from_coc(c, 85.0, 7.27, light_m) == pytest.approx(bound * (1 - 7.27 / light_m), rel=1e-12)


def test_light_distance_refuses_a_bad_side():
    with pytest.raises(InputError, match="side must be one of far, near"):
        light_distance_from_coc(0.1, 2.0, 50.0, 2.0, "behind")


def test_same_disc_gives_a_smaller_fstop_under_the_pinhole_model():
    """A measured disc read with the pinhole formula: N_pinhole = N_thin · (1 − f/d_f)."""
    c = coc_mm(2.0, 85.0, 3.0, math.inf)
    assert fstop_from_coc(c, 85.0, 3.0, math.inf, lens_model="pinhole") == pytest.approx(2.0 * (1 - 85 / 3000), rel=1e-12)


def test_light_at_infinity_accepts_inf_in_every_spelling():
    for infinity in (math.inf, float("inf"), np.inf):
        assert coc_mm(2.0, 50.0, 2.0, infinity) == pytest.approx(2500 / 3900, rel=1e-12)
        assert fstop_from_coc(2500 / 3900, 50.0, 2.0, infinity) == pytest.approx(2.0, rel=1e-12)


def test_light_at_focus_distance_makes_no_disc():
    assert coc_mm(2.0, 50.0, 2.0, 2.0) == 0.0
    with pytest.raises(InputError, match="focus distance"):
        fstop_from_coc(0.5, 50.0, 2.0, 2.0)
    with pytest.raises(InputError, match="focus distance"):
        fstop_from_coc(0.5, 50.0, 2.0, 2.0, lens_model="pinhole")


@pytest.mark.parametrize("focus_m", [0.05, 0.03], ids=["equal", "shorter"])
def test_focus_not_beyond_focal_length_is_refused(focus_m):
    with pytest.raises(InputError, match="focal length"):
        coc_mm(2.0, 50.0, focus_m, math.inf)
    with pytest.raises(InputError, match="focal length"):
        fstop_from_coc(0.5, 50.0, focus_m, 10.0)


@pytest.mark.parametrize(
    "call,needle",
    [
        (lambda: coc_mm(0.0, 50.0, 2.0, 10.0), "fstop"),
        (lambda: coc_mm(-2.0, 50.0, 2.0, 10.0), "fstop"),
        (lambda: coc_mm(2.0, 0.0, 2.0, 10.0), "focal_length_mm"),
        (lambda: coc_mm(2.0, 50.0, math.nan, 10.0), "focus_distance_m"),
        (lambda: coc_mm(2.0, 50.0, 2.0, 0.0), "light_distance_m"),
        (lambda: coc_mm(2.0, 50.0, 2.0, math.nan), "light_distance_m"),
        (lambda: coc_mm(2.0, 50.0, 2.0, 10.0, lens_model="fisheye"), "lens_model"),
        (lambda: fstop_from_coc(0.0, 50.0, 2.0, 10.0), "coc"),
        (lambda: fstop_from_coc(math.inf, 50.0, 2.0, 10.0), "coc"),
    ],
    ids=["fstop-0", "fstop-neg", "focal-0", "focus-nan", "light-0", "light-nan", "lens-model", "coc-0", "coc-inf"],
)
def test_bad_parameters_name_themselves(call, needle):
    with pytest.raises(InputError, match=needle):
        call()


# --------------------------------------------------------------------------------------
# Size conventions
# --------------------------------------------------------------------------------------


def test_circumscribed_leaves_the_circle_unchanged():
    assert circumscribed_fstop(2.0, make_aperture("circle")) == pytest.approx(2.0, rel=1e-12)


def test_circumscribed_hexagon():
    """N_circ = N_eq / (R·√π), R = 0.6204032: f/2 equal-area is f/1.8188 circumscribed."""
    expected = 2.0 / (0.6204032 * math.sqrt(math.pi))
    assert expected == pytest.approx(1.81878, abs=1e-5)
    for angle in (0.0, 15.0, 47.0):
        assert circumscribed_fstop(2.0, make_aperture("hexagon", angle)) == pytest.approx(expected, rel=1e-6)


@pytest.mark.parametrize("shape", sorted(CIRCUMRADIUS))
def test_circumscribed_circle_has_diameter_f_over_n(shape):
    """Scaled by (f/N_eq)·√π/2, the shape's circumscribed circle has diameter f/N_circ."""
    focal, n_eq = 50.0, 2.8
    n_circ = circumscribed_fstop(n_eq, make_aperture(shape, 10.0))
    scale = (focal / n_eq) * math.sqrt(math.pi) / 2
    assert 2 * CIRCUMRADIUS[shape] * scale == pytest.approx(focal / n_circ, rel=1e-6)
    assert n_circ <= n_eq * (1 + 1e-9)  # a polygon's circumscribed circle is larger than its equal-area circle


def test_circumscribed_ngon_follows_its_circumradius_formula():
    for n in (7, 9, 12, 32):
        radius = math.sqrt(2 / (n * math.sin(2 * math.pi / n)))
        got = circumscribed_fstop(4.0, make_aperture("ngon", 0.0, blades=n))
        assert got == pytest.approx(4.0 / (radius * math.sqrt(math.pi)), rel=1e-6)


# --------------------------------------------------------------------------------------
# Precision
# --------------------------------------------------------------------------------------


def _thin_lens(n, f, focus_mm, light_mm, dtype):
    """The thin-lens formula evaluated entirely in ``dtype`` (as a float32 shader would)."""
    n, f, focus_mm, light_mm = (dtype(v) for v in (n, f, focus_mm, light_mm))
    return (f / n) * f * np.abs(light_mm - focus_mm) / (light_mm * (focus_mm - f))


@pytest.mark.parametrize("geometry", GEOMETRIES[:4], ids=lambda g: f"f{g[0]:g}-df{g[1]:g}-d{g[2]:g}")
def test_thin_lens_float32_agrees_with_float64(geometry):
    focal, focus, light = geometry
    if math.isinf(light):
        light = 1e6  # finite: the float32 formula has no ∞ branch
    for n in FSTOPS:
        reference = coc_mm(n, focal, focus, light)
        single = _thin_lens(n, focal, focus * 1000, light * 1000, np.float32)
        double = _thin_lens(n, focal, focus * 1000, light * 1000, np.float64)
        assert double == pytest.approx(reference, rel=1e-12)
        assert single.dtype == np.float32
        assert float(single) == pytest.approx(reference, rel=FLOAT32_RTOL)
        # float32 arguments to the package's own function change nothing beyond float32 rounding
        from_f32 = coc_mm(np.float32(n), np.float32(focal), np.float32(focus), np.float32(light))
        assert from_f32 == pytest.approx(reference, rel=FLOAT32_RTOL)


def test_inverse_in_float32_agrees_with_float64():
    for (focal, focus, light), n in itertools.product(GEOMETRIES[:4], FSTOPS):
        c = np.float32(coc_mm(n, focal, focus, light))
        assert fstop_from_coc(c, focal, focus, light) == pytest.approx(n, rel=FLOAT32_RTOL)


@pytest.mark.parametrize(
    "call,needle",
    [
        (lambda: coc_mm(2.0, 1e-300, 2.0, 10.0), r"^focal_length_mm must be a finite number in \[1, 10000\] mm"),
        (lambda: coc_mm(2.0, 50.0, 2.0, -3.0), r"^light_distance_m must be a number in \(0, .*\] m or inf"),
        (lambda: coc_mm(1e-300, 50.0, 2.0, 10.0), r"^fstop must be a finite number in \[0.1, 10000\]"),
        (lambda: fstop_from_coc(1e308, 50.0, 2.0, 10.0), r"^coc must be a finite number in \(0, 1000\] mm"),
        (lambda: pixel_pitch_mm(1e308, 6000, 4000), r"^sensor_width_mm must be a finite number in \[1, 300\] mm"),
    ],
    ids=["focal-1e-300", "light-minus-3", "fstop-1e-300", "coc-1e308", "sensor-1e308"],
)
def test_absurd_geometry_is_refused_with_the_physical_range(call, needle):
    """Issue: focal length 1e-300 mm or a 1e308 mm sensor gave nonsense with no error."""
    with pytest.raises(InputError, match=needle):
        call()
