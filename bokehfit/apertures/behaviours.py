"""What each sampler family does at angle 0: one small class per family, looked up by name.

A behaviour is the shape of design.md §3 (with the rounded blades of §3b) at
angle 0 and unit area, before the rotation, squeeze, vignetting and colour
that :class:`~bokehfit.apertures.shapes.Aperture` applies to every shape
alike. It holds the sampler triplet (:meth:`~ShapeBehaviour.sample_at_zero`,
:meth:`~ShapeBehaviour.pdf_at_zero`, :meth:`~ShapeBehaviour.invert_at_zero`,
each with the ``rim`` profile), the radial fraction ρ, the exact outline, the
straight-edged corners and whether the angle and the roundness apply.
:func:`behaviour_of` builds the one for a family (``ShapeSpec.family``) and
the aperture's parameters; :data:`BEHAVIOURS` is the registry by family name.

The rim weights the light by ρ (design.md §3b) in one of two ways: the fans
(n-gons, rounded or not, and the star) draw ρ² as ``u₁``, so the rim remaps
``u₁``; the circle and the rectangles move each uniform point along its ray.
"""

from __future__ import annotations

import math

import numpy as np

from bokehfit.apertures import samplers
from bokehfit.apertures.mask import MaskTable, invert_mask_sample, mask_pdf, sample_mask
from bokehfit.apertures.outline import Arc, Outline, Segment
from bokehfit.errors import InputError

__all__ = [
    "BEHAVIOURS",
    "MASK_OUTLINE_LEVEL",
    "CircleShape",
    "MaskShape",
    "NgonShape",
    "RectangleShape",
    "RoundedSquareShape",
    "ShapeBehaviour",
    "SlitShape",
    "SquareShape",
    "StarShape",
    "behaviour_of",
]

#: Transmission level of a mask's drawn outline (design.md §3b), as a share of its largest transmission.
MASK_OUTLINE_LEVEL = 0.5


class ShapeBehaviour:
    """One family's shape at angle 0 and unit area: sampling, ρ, outline (the base of every family).

    ``rim`` is the intensity profile of design.md §3b (0: uniform).
    """

    #: Whether ``roundness`` applies: the blade edges of n-gons (design.md §3b).
    rounds = False
    #: Whether the angle means anything (False for the circle, whose rotations are all alike).
    has_angle = True

    @classmethod
    def build(cls, *, blades: int | None, aspect: float | None, roundness: float, mask: MaskTable | None) -> ShapeBehaviour:
        """The behaviour of this family for an aperture's parameters."""
        raise NotImplementedError

    def radial_fraction_at_zero(self, p: np.ndarray) -> np.ndarray:
        """|p| over the outline's distance in p's direction."""
        raise NotImplementedError

    def sample_at_zero(self, u: np.ndarray, rim: float) -> np.ndarray:
        """Points of the shape from ``u`` in [0, 1)², with the density of :meth:`pdf_at_zero`."""
        raise NotImplementedError

    def invert_at_zero(self, p0: np.ndarray, rim: float) -> np.ndarray:
        """The ``u`` that :meth:`sample_at_zero` maps to ``p0`` (p0 inside)."""
        raise NotImplementedError

    def pdf_at_zero(self, p0: np.ndarray, rim: float) -> np.ndarray:
        """Density of :meth:`sample_at_zero`: the rim profile inside, 0 outside."""
        fraction = self.radial_fraction_at_zero(p0)
        return np.where(fraction <= 1.0 + 1e-12, samplers.rim_weight(fraction, rim), 0.0)

    def base_vertices(self) -> np.ndarray:
        """Counter-clockwise corners of the straight-edged shape."""
        raise NotImplementedError(f"{type(self).__name__} has no corners")

    def outline_at_zero(self) -> Outline:
        """The exact outline: here the polygon of :meth:`base_vertices`."""
        corners = self.base_vertices()
        return Outline((tuple(Segment(tuple(a), tuple(b)) for a, b in zip(corners, np.roll(corners, -1, axis=0))),))

    def extent_at_zero(self) -> float | None:
        """Largest distance of the outline from the centre where known without its vertices, else None."""
        return None


class _ScaledRim(ShapeBehaviour):
    """A family sampled uniformly, the rim moving each point along its ray (circle, rectangles)."""

    def _sample_uniform(self, u: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def _invert_uniform(self, p0: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def sample_at_zero(self, u: np.ndarray, rim: float) -> np.ndarray:
        p = self._sample_uniform(u)
        if rim == 0.0:
            return p
        fraction = self.radial_fraction_at_zero(p)  # its square is uniform over a star-shaped area
        safe = np.where(fraction > 0.0, fraction, 1.0)
        scale = np.where(fraction > 0.0, samplers.rim_radius(fraction * fraction, rim) / safe, 0.0)
        return p * scale[..., None]

    def invert_at_zero(self, p0: np.ndarray, rim: float) -> np.ndarray:
        if rim != 0.0:
            fraction = self.radial_fraction_at_zero(p0)
            x = fraction * fraction
            original = np.sqrt((1.0 - rim) * x + rim * x * x)
            safe = np.where(fraction > 0.0, fraction, 1.0)
            p0 = p0 * np.where(fraction > 0.0, original / safe, 0.0)[..., None]
        return self._invert_uniform(p0)


class _FanRim(ShapeBehaviour):
    """A fan of triangles or blades about the centre: ``u₁`` is ρ², so the rim remaps ``u₁`` (n-gons, star)."""

    def _sample_fan(self, u: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def _invert_fan(self, p0: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def sample_at_zero(self, u: np.ndarray, rim: float) -> np.ndarray:
        if rim != 0.0:
            u = np.asarray(u, dtype=np.float64)
            u = np.stack([u[..., 0], samplers.rim_radius(u[..., 1], rim) ** 2], axis=-1)
        return self._sample_fan(u)

    def invert_at_zero(self, p0: np.ndarray, rim: float) -> np.ndarray:
        u = self._invert_fan(p0)
        if rim != 0.0:
            x = u[..., 1]  # the squared radial fraction; u₁ is its CDF
            u = np.stack([u[..., 0], (1.0 - rim) * x + rim * x * x], axis=-1)
        return u


class CircleShape(_ScaledRim):
    """The disc of radius 1/√π; no angle."""

    has_angle = False

    @classmethod
    def build(cls, *, blades, aspect, roundness, mask) -> CircleShape:
        return cls()

    def radial_fraction_at_zero(self, p: np.ndarray) -> np.ndarray:
        return np.hypot(p[..., 0], p[..., 1]) / samplers.CIRCLE_RADIUS

    def _sample_uniform(self, u: np.ndarray) -> np.ndarray:
        return samplers.sample_circle(u)

    def _invert_uniform(self, p0: np.ndarray) -> np.ndarray:
        return samplers.invert_circle_sample(p0)

    def outline_at_zero(self) -> Outline:
        return Outline(((Arc((0.0, 0.0), (samplers.CIRCLE_RADIUS,) * 2, 0.0, 2.0 * math.pi),),))

    def extent_at_zero(self) -> float:
        return samplers.CIRCLE_RADIUS


class RectangleShape(_ScaledRim):
    """An axis-aligned rectangle ``2·half_width`` by ``2·half_height`` (the square and the slit)."""

    def __init__(self, half_width: float, half_height: float):
        self.half_width, self.half_height = half_width, half_height

    def radial_fraction_at_zero(self, p: np.ndarray) -> np.ndarray:
        return np.maximum(np.abs(p[..., 0]) / self.half_width, np.abs(p[..., 1]) / self.half_height)

    def _invert_uniform(self, p0: np.ndarray) -> np.ndarray:
        w, h = self.half_width, self.half_height
        return np.stack([p0[..., 0] / (2.0 * w) + 0.5, p0[..., 1] / (2.0 * h) + 0.5], axis=-1)

    def base_vertices(self) -> np.ndarray:
        w, h = self.half_width, self.half_height
        return np.array([[w, -h], [w, h], [-w, h], [-w, -h]])


class SquareShape(RectangleShape):
    """The square of side 1 (``sample_square``); with rounded blades it is :class:`RoundedSquareShape`."""

    rounds = True

    def __init__(self):
        super().__init__(0.5, 0.5)

    @classmethod
    def build(cls, *, blades, aspect, roundness, mask) -> ShapeBehaviour:
        return cls() if roundness == 0.0 else RoundedSquareShape(roundness)

    def _sample_uniform(self, u: np.ndarray) -> np.ndarray:
        return samplers.sample_square(u)


class SlitShape(RectangleShape):
    """The rectangle ``aspect`` wide by ``1/aspect`` tall (``sample_slit``)."""

    def __init__(self, aspect: float):
        super().__init__(0.5 * aspect, 0.5 / aspect)
        self.aspect = aspect

    @classmethod
    def build(cls, *, blades, aspect, roundness, mask) -> SlitShape:
        return cls(aspect)

    def _sample_uniform(self, u: np.ndarray) -> np.ndarray:
        return samplers.sample_slit(u, self.aspect)


def _fan_vertices(radii: np.ndarray) -> np.ndarray:
    """Vertices at the ``radii``, evenly spaced in angle from +x."""
    angles = 2.0 * np.pi * np.arange(len(radii)) / len(radii)
    return np.stack([radii * np.cos(angles), radii * np.sin(angles)], axis=-1)


def _turn(p: np.ndarray, angle_rad: float) -> np.ndarray:
    """Points turned counter-clockwise by ``angle_rad``."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.stack([c * p[..., 0] - s * p[..., 1], s * p[..., 0] + c * p[..., 1]], axis=-1)


class NgonShape(_FanRim):
    """The regular n-gon with a vertex on +x, its blades rounded by ``roundness`` (0: straight)."""

    rounds = True
    #: Radians the rounded n-gon is turned by (the rounded square is the ngon 4 turned by 45°).
    turn = 0.0

    def __init__(self, blades: int, roundness: float):
        self.blades, self.roundness = blades, roundness

    @classmethod
    def build(cls, *, blades, aspect, roundness, mask) -> NgonShape:
        return cls(blades, roundness)

    def radial_fraction_at_zero(self, p: np.ndarray) -> np.ndarray:
        return samplers._rounded_ngon_polar(_turn(p, -self.turn), self.blades, self.roundness)[2]

    def _sample_fan(self, u: np.ndarray) -> np.ndarray:
        p = samplers.sample_rounded_ngon(u, self.blades, self.roundness)
        return p if self.turn == 0.0 else _turn(p, self.turn)

    def _invert_fan(self, p0: np.ndarray) -> np.ndarray:
        return samplers.invert_rounded_ngon_sample(_turn(p0, -self.turn), self.blades, self.roundness)

    def base_vertices(self) -> np.ndarray:
        return _fan_vertices(np.full(self.blades, samplers.ngon_circumradius(self.blades)))

    def outline_at_zero(self) -> Outline:
        """The blades' arcs; the polygon of :meth:`base_vertices` where the roundness is below ``ROUNDNESS_POLYGON``."""
        if self.roundness < samplers.ROUNDNESS_POLYGON:
            return super().outline_at_zero()
        geometry = samplers.RoundedNgon(self.blades, self.roundness)
        c, rho, alpha = geometry.centre_offset, geometry.arc_radius, geometry.half_angle
        arcs = []
        for k in range(self.blades):
            phi = float(geometry.mid_angle(k)) + self.turn
            arcs.append(Arc((c * math.cos(phi), c * math.sin(phi)), (rho, rho), phi - alpha, phi + alpha))
        return Outline((tuple(arcs),))

    def extent_at_zero(self) -> float | None:
        if self.roundness < samplers.ROUNDNESS_POLYGON:
            return None
        return samplers.RoundedNgon(self.blades, self.roundness).circumradius  # arcs lie inside the circumcircle


class RoundedSquareShape(NgonShape):
    """The square with rounded blades: sampled as the rounded ngon 4 turned by 45° (design.md §3)."""

    turn = math.pi / 4.0

    def __init__(self, roundness: float):
        super().__init__(4, roundness)

    def base_vertices(self) -> np.ndarray:
        return SquareShape().base_vertices()


class StarShape(_FanRim):
    """The star: a regular pentagon with an equilateral triangle flush on each side, an outer point on +x."""

    @classmethod
    def build(cls, *, blades, aspect, roundness, mask) -> StarShape:
        return cls()

    def radial_fraction_at_zero(self, p: np.ndarray) -> np.ndarray:
        corners = self.base_vertices()  # the fan triangle's outer edge
        n = len(corners)
        theta = np.mod(np.arctan2(p[..., 1], p[..., 0]), 2.0 * np.pi)
        k = np.minimum(np.floor(theta * n / (2.0 * np.pi)), n - 1).astype(np.int64)
        a, b = corners[k], corners[(k + 1) % n]
        normal = np.stack([b[..., 1] - a[..., 1], a[..., 0] - b[..., 0]], axis=-1)
        return np.sum(p * normal, axis=-1) / np.sum(a * normal, axis=-1)

    def _sample_fan(self, u: np.ndarray) -> np.ndarray:
        return samplers.sample_star(u)

    def _invert_fan(self, p0: np.ndarray) -> np.ndarray:
        return samplers.invert_star_sample(p0)

    def base_vertices(self) -> np.ndarray:
        return _fan_vertices(np.tile([samplers.STAR_OUTER_RADIUS, samplers.STAR_INNER_RADIUS], 5))


class MaskShape(ShapeBehaviour):
    """A tabulated transmission image (design.md §3b): its density is the transmission; no rim, no ρ."""

    def __init__(self, mask: MaskTable):
        self.mask = mask

    @classmethod
    def build(cls, *, blades, aspect, roundness, mask) -> MaskShape:
        return cls(mask)

    def radial_fraction_at_zero(self, p: np.ndarray) -> np.ndarray:
        raise InputError("the radial fraction does not apply to shape 'mask' (a mask has no outline to measure it on)")

    def sample_at_zero(self, u: np.ndarray, rim: float) -> np.ndarray:
        return sample_mask(u, self.mask)

    def invert_at_zero(self, p0: np.ndarray, rim: float) -> np.ndarray:
        return invert_mask_sample(p0, self.mask)

    def pdf_at_zero(self, p0: np.ndarray, rim: float) -> np.ndarray:
        return mask_pdf(p0, self.mask)

    def outline_at_zero(self) -> Outline:
        """The contour at MASK_OUTLINE_LEVEL of the largest transmission.

        Marching squares (scikit-image ``find_contours``) on the image padded with
        zeros, so every loop closes; vertices lie on lines between cell centres.
        Loops run counter-clockwise around transmitting parts.
        """
        from skimage.measure import find_contours

        mask = self.mask
        image = np.pad(mask.transmission, 1)
        h, w = mask.shape
        loops = []
        for contour in find_contours(image, MASK_OUTLINE_LEVEL * float(image.max())):
            xy = np.stack([(contour[:, 1] - 0.5 - 0.5 * w) * mask.cell, (0.5 * h - contour[:, 0] + 0.5) * mask.cell], axis=-1)
            if np.allclose(xy[0], xy[-1]):
                xy = xy[:-1]
            if len(xy) >= 3:
                loops.append(xy)
        # find_contours keeps the high values on one side; make the outer loops counter-clockwise.
        signed = sum(0.5 * float(np.sum(xy[:, 0] * np.roll(xy[:, 1], -1) - np.roll(xy[:, 0], -1) * xy[:, 1])) for xy in loops)
        if signed < 0.0:
            loops = [xy[::-1] for xy in loops]
        return Outline(tuple(tuple(Segment(tuple(a), tuple(b)) for a, b in zip(xy, np.roll(xy, -1, axis=0))) for xy in loops))


#: The behaviour of each sampler family (``ShapeSpec.family``), by name. Its order is that of the
#: shaders' ``SHAPE_*`` ids (``registry.SHADER_FAMILIES`` is its keys): a new family goes last.
BEHAVIOURS: dict[str, type[ShapeBehaviour]] = {
    "circle": CircleShape,
    "square": SquareShape,
    "slit": SlitShape,
    "ngon": NgonShape,
    "star": StarShape,
    "mask": MaskShape,
}


def behaviour_of(family: str, *, blades: int | None, aspect: float | None, roundness: float,
                 mask: MaskTable | None) -> ShapeBehaviour:
    """The behaviour of sampler family ``family`` for an aperture's blades, aspect, roundness and mask."""
    return BEHAVIOURS[family].build(blades=blades, aspect=aspect, roundness=roundness, mask=mask)
