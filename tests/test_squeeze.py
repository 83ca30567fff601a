"""Anamorphic squeeze (design.md §3b) found by the fit on discs drawn from geometry.

The discs are filled polygons and ellipses sampled 4×4 per pixel, blurred and
noised here, not rendered with bokehfit's kernels: an anamorphic lens's round
aperture makes axis-aligned ellipses, its hexagon a hexagon stretched along the
frame's axes. Discs stretched askew, or only some of them, are not a squeeze.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from bokehfit.discs import find_discs
from bokehfit.fit import fit_aperture
from bokehfit.metrics import angle_error

WIDTH, HEIGHT, SUB = 400, 300, 4
CENTRES = [(70, 80), (200, 80), (330, 80), (70, 220), (200, 220), (330, 220)]
#: |fitted − true| squeeze allowed, and angle error (degrees).
SQUEEZE_TOL, ANGLE_TOL_DEG = 0.01, 0.3


def photo(polygons: list[np.ndarray]) -> np.ndarray:
    """Linear luminance of filled polygons given in image pixel coordinates (x right, y down)."""
    fine = np.zeros((HEIGHT * SUB, WIDTH * SUB), np.float32)
    for points in polygons:
        scaled = ((points + 0.5) * SUB - 0.5) * 16  # pixel centres at integers, 4 fractional bits
        cv2.fillPoly(fine, [np.round(scaled).astype(np.int32)], 1.0, lineType=cv2.LINE_8, shift=4)
    image = 0.02 + 0.5 * fine.reshape(HEIGHT, SUB, WIDTH, SUB).mean(axis=(1, 3))
    image = cv2.GaussianBlur(image.astype(np.float32), (0, 0), 0.8)
    return image + np.random.default_rng(1).normal(0, 0.002, image.shape).astype(np.float32)


def stretched(centre, corners_xy_up: np.ndarray, squeeze: float, tilt_deg: float = 0.0) -> np.ndarray:
    """An outline (y up, about 0) squeezed as §3b says (x/√s, y·√s), tilted, placed at ``centre`` (y down)."""
    x, y = corners_xy_up[:, 0] / math.sqrt(squeeze), corners_xy_up[:, 1] * math.sqrt(squeeze)
    t = math.radians(tilt_deg)
    x, y = x * math.cos(t) - y * math.sin(t), x * math.sin(t) + y * math.cos(t)
    return np.column_stack([centre[0] + x, centre[1] - y])


def circle(radius: float) -> np.ndarray:
    t = np.linspace(0, 2 * np.pi, 720, endpoint=False)
    return np.column_stack([radius * np.cos(t), radius * np.sin(t)])


def hexagon(radius: float, angle_deg: float) -> np.ndarray:
    t = np.radians(angle_deg + 60.0 * np.arange(6))
    return np.column_stack([radius * np.cos(t), radius * np.sin(t)])


def fit(image: np.ndarray):
    return fit_aperture(image, find_discs(image).discs)


@pytest.mark.parametrize("squeeze", [1.33, 0.75])
def test_ellipses_are_a_squeezed_circle_not_a_slit(squeeze):
    found = fit(photo([stretched(c, circle(20.0), squeeze) for c in CENTRES]))
    assert found.aperture.is_circle or found.aperture.shape == "circle", found.message
    assert found.aperture.aspect is None, "never a slit"
    assert found.aperture.squeeze == pytest.approx(squeeze, abs=SQUEEZE_TOL), found.message
    assert found.parameters["squeeze"].value == pytest.approx(found.aperture.squeeze)
    assert "squeeze" in found.message


def test_a_squeezed_hexagon_keeps_its_blades_and_angle():
    found = fit(photo([stretched(c, hexagon(22.0, 20.0), 1.25) for c in CENTRES]))
    assert found.aperture.blades == 6, found.message
    assert found.aperture.squeeze == pytest.approx(1.25, abs=SQUEEZE_TOL)
    assert angle_error(found.aperture.angle_deg, 20.0, 60.0) < ANGLE_TOL_DEG


def test_round_discs_get_no_squeeze():
    found = fit(photo([stretched(c, circle(20.0), 1.0) for c in CENTRES]))
    assert found.aperture.squeeze == 1.0 and "squeeze" not in found.feature_tests, found.message


@pytest.mark.parametrize("tilt_deg", [30.0, 45.0])
def test_discs_stretched_askew_are_not_a_squeeze(tilt_deg):
    """An anamorphic lens squeezes along the frame's axes; ellipses tilted alike are something else."""
    found = fit(photo([stretched(c, circle(20.0), 1.33, tilt_deg) for c in CENTRES]))
    assert "squeeze" not in found.feature_tests and found.aperture.squeeze == 1.0, found.message


def test_only_the_edge_discs_stretched_is_not_a_squeeze():
    """Lemons at the left and right edges (cat-eye) beside round central discs: no shared squeeze."""
    polygons = [stretched(c, circle(20.0), 1.33 if c[0] != 200 else 1.0) for c in CENTRES]
    found = fit(photo(polygons))
    assert "squeeze" not in found.feature_tests, found.message


def test_fit_ellipse_reads_aspect_and_axis():
    from bokehfit.fit.signature import fit_ellipse

    outline = stretched((100.0, 100.0), circle(20.0), 1.44, 30.0)  # y up: the long axis (y) turned by 30°
    ellipse = fit_ellipse(outline)
    assert ellipse.aspect == pytest.approx(1 / 1.44, abs=0.005)
    # y up turned by 30° counter-clockwise is 120° from x with y up, 60° with y down.
    assert angle_error(ellipse.axis_deg, 60.0, 180.0) < 0.5 and ellipse.misfit < 0.002
    assert fit_ellipse(outline[:5]) is None


def test_lemons_at_the_edge_are_a_cat_eye_a_lone_stretched_blob_is_not():
    """Discs stretched square to the line from the frame's centre, at its edge, are the cat-eye's cut
    and are fitted; one disc stretched along that line (no lens cuts a disc so) is set aside."""
    width, height = WIDTH, HEIGHT
    centre = np.array([(width - 1) / 2, (height - 1) / 2])
    polygons, tangential = [], []
    for x, y in CENTRES:
        if x == 200:
            polygons.append(stretched((x, y), circle(20.0), 1.0))
            continue
        radial = math.degrees(math.atan2(-(y - centre[1]), x - centre[0]))  # y up
        along = radial + 90.0 if (x, y) != CENTRES[0] else radial  # the first one stretched along the radius
        # ``stretched`` puts the long axis on y (up) for squeeze > 1: turn it onto ``along``.
        polygons.append(stretched((x, y), circle(20.0), 1.3, along - 90.0))
        tangential.append((x, y) != CENTRES[0])
    image = photo(polygons)
    found = fit(image)
    assert found, found.reason
    used = {tuple(np.round(item.disc.center_xy)) for item in found.disc_fits}
    near = lambda point: any(math.dist(point, u) < 2.0 for u in used)  # noqa: E731
    assert not near(CENTRES[0]), f"the disc stretched along the radius was used: {found.rejected}"
    assert all(near(c) for c in CENTRES[1:]), (used, found.rejected)
    assert any("cat-eye" in reason for reason in found.rejected.values()), found.rejected
