"""The fit's Jacobian: the exact coverage's slopes, and the columns built from them, against finite differences.

The slopes are checked against central differences of :func:`coverage` itself (a different
computation: the area at two nearby places), on outlines of every kind of piece: straight
sides, arcs, rounded blades, a star's reflex corners, the squeeze, a vignetting cut; a ``rim``
profile's slopes against central differences of :func:`rim_coverage`, on the fine grids it
integrates by their crossed sub-pixels. The fit's columns are checked against central
differences of the residuals the fit minimises, on discs with censored (clipped) pixels, a
fitted plateau, light left out and a rim, far and near.
"""

from __future__ import annotations

import numpy as np
import pytest

from bokehfit.apertures import make_aperture
from bokehfit.discs import find_discs
from bokehfit.fit.crop import crop_disc
import dataclasses

from bokehfit.fit.disc_model import RIM, RIM_FIT_SUPERSAMPLE, SLOPED, TURN
from bokehfit.fit.objective import jacobian, weighted_residuals
from bokehfit.fit.vector import fit_vector
from bokehfit.kernels.exact import coverage, coverage_slopes
from bokehfit.kernels.rim import rim_coverage, rim_coverage_slopes
from bokehfit.synthetic import SyntheticDisc, render_discs

APERTURES = {
    "circle": (make_aperture("circle", 0.0), None),
    "hexagon": (make_aperture("hexagon", 13.0), None),
    "rounded 9-gon": (make_aperture("ngon(9)", 7.0, roundness=0.4), None),
    "star": (make_aperture("star", 5.0), None),
    "squeezed hexagon": (make_aperture("hexagon", 10.0, squeeze=1.6), None),
    "cat-eye circle": (make_aperture("circle", 0.0, vignetting={"radius": 1.3, "shift": 0.9}), (0.8, -0.5)),
}


def central(function, at: float, h: float = 1e-6) -> np.ndarray:
    return (function(at + h) - function(at - h)) / (2.0 * h)


@pytest.mark.parametrize("name", APERTURES)
@pytest.mark.parametrize("scale, offset", [(11.3, (0.37, -0.81)), (4.2, (-1.25, 0.5))])
def test_coverage_slopes_are_the_coverages_derivatives(name, scale, offset):
    aperture, where = APERTURES[name]
    size = 36
    slopes = coverage_slopes(aperture, scale, size, offset, where)
    assert np.array_equal(slopes.cover, coverage(aperture, scale, size, offset_xy=offset, field_position=where))
    by_x = central(lambda v: coverage(aperture, scale, size, offset_xy=(v, offset[1]), field_position=where), offset[0])
    by_y = central(lambda v: coverage(aperture, scale, size, offset_xy=(offset[0], v), field_position=where), offset[1])
    by_s = central(lambda v: coverage(aperture, v, size, offset_xy=offset, field_position=where), scale)
    for exact, numeric in ((slopes.by_offset_x, by_x), (slopes.by_offset_y, by_y), (slopes.by_scale, by_s)):
        assert np.abs(numeric).max() > 0.1  # the check has something to check
        np.testing.assert_allclose(exact, numeric, atol=2e-6)


@pytest.mark.parametrize("name", APERTURES)
def test_coverage_slopes_keep_the_light_and_grow_it_with_the_area(name):
    """Moving a shape inside the frame keeps its light; growing it by ds adds 2·area·ds/s."""
    aperture, where = APERTURES[name]
    scale = 9.0
    slopes = coverage_slopes(aperture, scale, 36, (0.3, -0.2), where)
    area = slopes.cover.sum()
    assert abs(slopes.by_offset_x.sum()) < 1e-9 and abs(slopes.by_offset_y.sum()) < 1e-9
    assert slopes.by_scale.sum() == pytest.approx(2.0 * area / scale, rel=1e-9)


@pytest.mark.parametrize("name", APERTURES)
def test_coverage_slopes_on_a_large_grid_are_the_whole_grids(name, monkeypatch):
    """On a grid that the outline crosses in few pixels (the rim's fine grids) only those are
    integrated: the others keep their coverage and their slopes are 0, as over the whole grid."""
    from bokehfit.kernels import exact

    aperture, where = APERTURES[name]
    flow = np.array([[0.0, -1.0], [1.0, 0.0]]) * (np.pi / 180.0) if aperture.has_angle else None  # a turn
    args = (aperture, 40.0, 120, (0.37, -0.81), where, flow)
    crossed = coverage_slopes(*args)
    monkeypatch.setattr(exact, "_EDGE_ONLY_MIN_WORK", 10**12)  # every pixel integrated
    whole = coverage_slopes(*args)
    for field in ("cover", "by_offset_x", "by_offset_y", "by_scale", *(("by_flow",) if flow is not None else ())):
        assert np.abs(getattr(whole, field)).max() > 0.01
        np.testing.assert_allclose(getattr(crossed, field), getattr(whole, field), atol=1e-9, err_msg=field)


def crops_of(discs, width, height, clip=None):
    """The fit's crops of the discs the finder sees in a synthetic photo (clipped above ``clip``)."""
    luminance = render_discs(width, height, discs, noise_sigma=0.01, seed=4)
    if clip is not None:
        luminance = np.minimum(luminance, clip)
    clipped = luminance >= (1.0 if clip is None else clip)
    found = [d for d in find_discs(luminance, clipped).discs if d.usable]
    assert len(found) == len(discs)
    return [crop_disc(luminance, disc, clipped, found) for disc in found]


def numeric_jacobian(crops, vector, noise, x, step=1e-3):
    residuals = weighted_residuals(crops, vector, noise, {})
    columns = []
    for j in range(x.size):
        h = step * max(1.0, abs(x[j]))  # the model is float32 inside: a larger step than 1e-6
        up, down = x.copy(), x.copy()
        up[j] += h
        down[j] -= h
        columns.append((residuals(up) - residuals(down)) / (2.0 * h))
    return np.stack(columns, axis=1)


HEXAGON = make_aperture("hexagon", 20.0)


@pytest.mark.parametrize("case", ["one disc", "three discs, one overlapping", "saturated", "rim", "rim, near"])
def test_the_fits_jacobian_is_that_of_its_residuals(case):
    """Away from the start (so the levels are not at their best), every column of the model's own
    Jacobian is the central difference of the residuals: the centres', sizes', the angle's and the
    rim's (the slopes; a near disc shows the rim with its sign turned) to 1e-3 of the column, the
    others (forward differences themselves: the blur, the plateau) to their step's order."""
    aperture, free = HEXAGON, ("angle_deg",)
    if case.startswith("rim"):
        aperture, free = HEXAGON.with_features("rim").replace(rim=0.45), ("angle_deg", "rim")
        crops = crops_of([SyntheticDisc((40.3, 41.6), 30.0, aperture, brightness=0.6),
                          SyntheticDisc((110.5, 44.7), 26.0, aperture, brightness=0.7)], 150, 85)
        if case == "rim, near":
            crops = [dataclasses.replace(crops[0], turned=True), crops[1]]
    elif case == "one disc":
        crops = crops_of([SyntheticDisc((40.3, 41.6), 30.0, HEXAGON, brightness=0.6)], 80, 80)
    elif case == "saturated":
        crops = crops_of([SyntheticDisc((40.3, 41.6), 28.0, HEXAGON, brightness=2.0)], 80, 80, clip=1.0)
        assert crops[0].censored is not None and crops[0].clip_level is not None
    else:
        crops = crops_of([SyntheticDisc((40.3, 45.6), 30.0, HEXAGON, brightness=0.6),
                          SyntheticDisc((62.1, 50.2), 30.0, HEXAGON, brightness=0.5),
                          SyntheticDisc((130.5, 44.7), 24.0, HEXAGON, brightness=0.7)], 170, 90)
        assert any(c.ignored is not None for c in crops), "the overlapping pair leaves light out"
    vector = fit_vector(crops, aperture, free)
    noise = np.linspace(0.02, 0.03, len(crops))
    x = np.array(vector.start) + np.random.default_rng(2).uniform(-0.3, 0.3, vector.size)
    x = np.clip(x, np.array(vector.lower) + 1e-3, np.array(vector.upper) - 1e-3)
    jac = jacobian(crops, vector, noise, {}, sparse=len(crops) > 1)(x)
    exact = jac.toarray() if hasattr(jac, "toarray") else jac
    # A rim's light is tabulated on sub-pixels: its slopes jump where the edge crosses their borders, so
    # the central difference's own error is of its step's order, and a smaller step is taken.
    numeric = numeric_jacobian(crops, vector, noise, x, step=3e-4 if case.startswith("rim") else 1e-3)
    assert exact.shape == numeric.shape
    names = [*vector.free, *(name for block in vector.discs for name in block.names)]
    for j, name in enumerate(names):
        scale = np.linalg.norm(numeric[:, j])
        assert scale > 0
        error = np.linalg.norm(exact[:, j] - numeric[:, j]) / scale
        sloped = name in (*SLOPED, TURN, RIM)  # the model's own slopes
        assert error < (1e-3 if sloped else 2e-2), (name, error)
    # A disc's rows hang on the shared parameters and its own alone.
    rows = np.cumsum([0, *(c.data.size for c in crops)])
    for i, block in enumerate(vector.discs):
        own = np.zeros(vector.size, dtype=bool)
        own[: len(vector.free)] = True
        own[block.at : block.at + len(block.names)] = True
        assert not exact[rows[i] : rows[i + 1], ~own].any()


@pytest.mark.parametrize("name", [n for n in APERTURES if APERTURES[n][1] is None and APERTURES[n][0].has_angle])
def test_a_turn_of_the_angle_is_the_coverages_derivative(name):
    """The outline turns (then is squeezed) with the angle: the flow's slope is the coverage's
    derivative by the angle, in degrees."""
    aperture, _ = APERTURES[name]
    squeeze = aperture.squeeze_matrix()
    flow = squeeze @ np.array([[0.0, -1.0], [1.0, 0.0]]) @ np.linalg.inv(squeeze) * (np.pi / 180.0)
    scale, size, offset = 11.3, 36, (0.37, -0.81)
    slopes = coverage_slopes(aperture, scale, size, offset, flow=flow)
    numeric = central(lambda a: coverage(aperture.replace(angle_deg=a), scale, size, offset_xy=offset),
                      aperture.angle_deg, h=1e-5)
    assert np.abs(numeric).max() > 0.01
    np.testing.assert_allclose(slopes.by_flow, numeric, atol=1e-7)
    # The scale is the flow I/s: the same column two ways.
    np.testing.assert_allclose(coverage_slopes(aperture, scale, size, offset, flow=np.eye(2) / scale).by_flow,
                               slopes.by_scale, atol=1e-12)


RIM_APERTURES = {
    "circle": (make_aperture("circle", 0.0, rim=0.6), None),
    "hexagon, rim below 0": (make_aperture("hexagon", 13.0, rim=-0.5), None),
    "rounded 9-gon": (make_aperture("ngon(9)", 7.0, roundness=0.4, rim=0.7), None),
    "squeezed hexagon": (make_aperture("hexagon", 10.0, squeeze=1.6, rim=0.4), None),
    "cat-eye circle": (make_aperture("circle", 0.0, rim=0.5, vignetting={"radius": 1.3, "shift": 0.9}), (0.8, -0.5)),
}


@pytest.mark.parametrize("name", RIM_APERTURES)
def test_a_rim_profiles_slopes_are_its_tabulated_lights_derivatives(name):
    """The rim's light moves with the shape as the sub-pixels' coverage does and its weight with them: the
    slopes by the offset, the scale, a turn and the rim are the central differences of :func:`rim_coverage`
    (the fine grid, 108 px a side, integrated by its crossed sub-pixels), and its light is rim_coverage's."""
    aperture, where = RIM_APERTURES[name]
    scale, size, offset, supersample = 9.3, 36, (0.37, -0.81), RIM_FIT_SUPERSAMPLE
    turns = aperture.has_angle and aperture.vignetting is None
    squeeze = aperture.squeeze_matrix()
    flow = squeeze @ np.array([[0.0, -1.0], [1.0, 0.0]]) @ np.linalg.inv(squeeze) * (np.pi / 180.0) if turns else None
    slopes = rim_coverage_slopes(aperture, scale, size, offset, where, flow, supersample)

    def light(a=aperture, s=scale, o=offset):
        return rim_coverage(a, s, size, field_position=where, supersample=supersample, offset_xy=o)[0]

    np.testing.assert_allclose(slopes.cover, light(), atol=1e-12)
    numeric = {"by_offset_x": central(lambda v: light(o=(v, offset[1])), offset[0], 1e-4),
               "by_offset_y": central(lambda v: light(o=(offset[0], v)), offset[1], 1e-4),
               "by_scale": central(lambda v: light(s=v), scale, 1e-4),
               "by_rim": central(lambda v: light(a=aperture.replace(rim=v)), aperture.rim, 1e-4)}
    if turns:
        numeric["by_flow"] = central(lambda v: light(a=aperture.replace(angle_deg=v)), aperture.angle_deg, 1e-3)
    for field, expected in numeric.items():
        assert np.abs(expected).max() > 0.01  # the check has something to check
        np.testing.assert_allclose(getattr(slopes, field), expected, atol=1e-4 * np.abs(expected).max(), err_msg=field)
