"""The one aperture model: the shapes of design.md §3 and the real-lens features of §3b.

A shape is named (``circle``, ``square``, ``slit``, ``triangle``, ``pentagon``,
``hexagon``, ``star``, ``ngon``); an :class:`Aperture` is a shape with its
parameters (angle, blade count, slit aspect) and features (``roundness``,
``squeeze``, ``vignetting``, ``rim``, ``chromatic``). It owns everything about
itself: the exact :meth:`~Aperture.outline` and :meth:`~Aperture.area`, the
symmetry, the near disc (:meth:`~Aperture.near`), the fit parameters
(:attr:`~Aperture.parameters`, :meth:`~Aperture.replace`), and sampling with
its pdf and inverse (:meth:`~Aperture.sample`, :meth:`~Aperture.pdf`,
:meth:`~Aperture.invert`; the WGSL twin is ``sample_aperture_params``). At
scale 1 every unclipped aperture has area exactly 1. Adding a shape is one
:class:`ShapeSpec` entry in ``SHAPES``; what each sampler family does at angle
0 (sampler, pdf and inverse, outline, corners) is its class in
:mod:`bokehfit.apertures.behaviours`, and the Aperture applies the rotation,
squeeze, vignetting and colour to every family alike. The custom ``mask``
shape of §3b is tabulated (:class:`~bokehfit.apertures.mask.MaskTable`): its
density is the transmission, its outline the 50 % transmission contour.

The shape registry and the parser of names are in :mod:`bokehfit.apertures.registry`,
the features' value types in :mod:`bokehfit.apertures.parameters` and their records (what a
fit and a report know of each) in :mod:`bokehfit.apertures.features`, and the one
conversion from image offsets to the aperture frame (design.md §2) in
:mod:`bokehfit.apertures.frames`; their names are importable from here too.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from bokehfit.apertures import samplers
from bokehfit.apertures.behaviours import MASK_OUTLINE_LEVEL  # noqa: F401  (the docs cite it here)
from bokehfit.apertures.behaviours import ShapeBehaviour, behaviour_of
from bokehfit.apertures.features import FEATURE_SPECS, FEATURES
from bokehfit.apertures.frames import aperture_rows_to_image, aperture_to_image, image_to_aperture
from bokehfit.apertures.mask import MaskTable, load_mask
from bokehfit.apertures.outline import Outline, Segment, clip_by_circle
from bokehfit.apertures.parameters import (
    APERTURE_PARAM_FIELDS, CHANNELS, VERTICES_MAX_ERROR, Chromatic, ParameterSpec, Vignetting, pair_members,
)
from bokehfit.apertures.registry import (
    DEFAULT_SLIT_ASPECT, MAX_BLADES, SHADER_FAMILIES, SHAPES, SLIT_ASPECT_RANGE, ShapeSpec, canonical_angle, parse_shape,
)
from bokehfit.errors import InputError, check_finite
from bokehfit.validate import RANGES, check

__all__ = [
    "APERTURE_PARAM_FIELDS",
    "Aperture",
    "CHANNELS",
    "Chromatic",
    "FEATURES",
    "ParameterSpec",
    "ShapeSpec",
    "SHAPES",
    "SHADER_FAMILIES",
    "Vignetting",
    "aperture_rows_to_image",
    "aperture_to_image",
    "canonical_angle",
    "image_to_aperture",
    "make_aperture",
    "parse_shape",
]


@dataclass(frozen=True)
class Aperture:
    """A shape with its parameters and real-lens features, at unit area. Build it with :func:`make_aperture`.

    The geometry is: the shape at angle 0 (design.md §3, with rounded blades),
    rotated by ``angle_deg``, squeezed (x/√squeeze, y·√squeeze), then clipped
    by the vignetting circle at a field position; ``rim`` weights the light
    across it and ``chromatic`` scales the red and blue discs (design.md §3b).
    ``features`` names the §3b features switched on for fitting even at their
    neutral values (see :attr:`parameters`).
    """

    shape: str
    angle_deg: float = 0.0
    blades: int | None = None
    aspect: float | None = None
    roundness: float = 0.0
    squeeze: float = 1.0
    vignetting: Vignetting | None = None
    rim: float = 0.0
    chromatic: Chromatic | None = None
    features: frozenset = frozenset()
    mask: MaskTable | None = None  #: the transmission image of shape ``mask`` (design.md §3b)

    @property
    def spec(self) -> ShapeSpec:
        return SHAPES[self.shape]

    @property
    def _behaviour(self) -> ShapeBehaviour:
        """What the shape does at angle 0 (:mod:`bokehfit.apertures.behaviours`), for its family and parameters."""
        return behaviour_of(self.spec.family, blades=self.blades, aspect=self.aspect, roundness=self.roundness, mask=self.mask)

    @property
    def symmetry_deg(self) -> float | None:
        """Period of ``angle_deg``: the smallest rotation mapping the shape onto itself; None for the circle.

        The squeeze and the vignetting act after the rotation, so they do not change it.
        """
        return self.spec.symmetry_deg(self.blades)

    @property
    def odd_symmetry(self) -> bool:
        """True where a near disc shows a visible rotation: 180° is not a multiple of the symmetry (design.md §2)."""
        symmetry = self.symmetry_deg
        return symmetry is not None and not math.isclose(math.remainder(180.0, symmetry), 0.0, abs_tol=1e-9)

    @property
    def has_angle(self) -> bool:
        """Whether ``angle_deg`` means anything: False for the circle, whose rotations are all alike."""
        return self.symmetry_deg is not None

    @property
    def is_circle(self) -> bool:
        """Whether the outline is the plain circle of radius 1/√π: no corners to draw or sample (unsqueezed)."""
        return not self.has_angle and self.squeeze == 1.0

    @property
    def turns_alike(self) -> bool:
        """Whether a disc shows the outline alike at every rotation: the plain circle, no vignetting to cut it."""
        return self.is_circle and self.vignetting is None

    @property
    def label(self) -> str:
        """The shape's name as ``compare --shapes`` takes it: ``hexagon``, ``ngon(9)`` (see :func:`parse_shape`)."""
        return f"ngon({self.blades})" if self.spec.takes_blades else self.shape

    @property
    def display_name(self) -> str:
        """The shape's name for people: ``hexagon``, ``9-blade polygon``, ``rounded 9-blade polygon``."""
        name = f"{self.blades}-blade polygon" if self.spec.takes_blades else self.shape
        return f"rounded {name}" if self.has_roundness else name

    def is_named(self, text: str) -> bool:
        """Whether ``text`` names this aperture's shape (see :func:`parse_shape`).

        A registry name matches apertures of that name (a bare ``ngon``, every
        blade count); ``ngon(N)`` matches every n-gon of N blades, so
        ``ngon(6)`` names the hexagon too. Raises InputError for an unknown name.

        Examples
        --------
        >>> make_aperture("hexagon").is_named("ngon(6)"), make_aperture("ngon(9)").is_named("ngon")
        (True, True)
        """
        shape, blades = parse_shape(text)
        if blades is None:
            return shape == self.shape
        return SHAPES[shape].family == self.spec.family and blades == self.blades

    @property
    def canonical_angle_deg(self) -> float | None:
        """The angle reduced to [0, symmetry); None for the circle."""
        return canonical_angle(self.angle_deg, self.symmetry_deg)

    @property
    def has_aspect(self) -> bool:
        """Whether the shape has an aspect of its own (the slit's width over height), one of :attr:`parameters`."""
        return self.spec.takes_aspect

    @property
    def has_roundness(self) -> bool:
        """Whether the blades' roundness is on, one of :attr:`parameters` (n-gons only)."""
        return FEATURE_SPECS["roundness"].is_on(self)

    @property
    def enabled_features(self) -> tuple[str, ...]:
        """The §3b features that are on: switched on by :meth:`with_features` or away from their neutral value."""
        return tuple(name for name, feature in FEATURE_SPECS.items() if feature.is_on(self))

    @property
    def parameters(self) -> dict[str, ParameterSpec]:
        """What a fit may vary, in order: name → :class:`ParameterSpec` (names are :meth:`replace` keywords).

        ``angle_deg`` (periodic with the symmetry; absent for the circle),
        ``aspect`` for the slit; then each §3b feature only where it is on
        (:attr:`enabled_features`): ``roundness`` (n-gons), ``squeeze``,
        ``rim``, ``vignetting_radius`` and ``vignetting_shift``,
        ``chromatic_red`` and ``chromatic_blue``. Bounds are those of
        ``bokehfit.validate.RANGES``.
        """
        found: dict[str, ParameterSpec] = {}

        def add(name, quantity, unit="", periodic=None, bounds=None):
            rule = RANGES[quantity]
            found[name] = ParameterSpec(name, bounds or (rule.low, rule.high), unit, periodic)

        if self.symmetry_deg is not None:
            add("angle_deg", "angle_deg", "°", self.symmetry_deg, (0.0, self.symmetry_deg))
        if self.has_aspect:
            add("aspect", "aspect")
        for feature in FEATURE_SPECS.values():
            if feature.is_on(self):
                for name, quantity in zip(feature.parameters, feature.quantities):
                    add(name, quantity)
        return found

    @property
    def values(self) -> dict[str, float]:
        """The current value of each of :attr:`parameters`, by name: the fit's parameter vector, named.

        ``aperture.replace(**aperture.values)`` is the aperture again.
        """
        pairs = {name: (f.name, member) for f in FEATURE_SPECS.values() for name, member in zip(f.parameters, f.members)}
        found = {}
        for name in self.parameters:
            if name in pairs:
                feature, member = pairs[name]
                found[name] = float(getattr(getattr(self.with_features(feature), feature), member))
            else:
                found[name] = float(getattr(self, name))
        return found

    @classmethod
    def from_json(cls, data: Mapping) -> Aperture:
        """The aperture of a JSON ``aperture`` object (``compare --json``, design.md §7); null values are defaults.

        Examples
        --------
        >>> Aperture.from_json({"shape": "ngon", "blades": 9, "angle_deg": 10.0}).describe()
        'ngon(9) 10°'
        """
        if not isinstance(data, Mapping) or "shape" not in data:
            raise InputError(f"aperture must be a mapping with a 'shape' key (got {data!r})")
        keys = ("blades", "aspect", "roundness", "squeeze", "vignetting", "rim", "chromatic")
        given = {key: data[key] for key in (*keys, "mask") if data.get(key) is not None}
        return make_aperture(data["shape"], data.get("angle_deg") or 0.0, **given)

    def with_features(self, *names: str) -> Aperture:
        """A copy with the §3b features ``names`` switched on at their neutral values (kept where set).

        Vignetting starts as a barrel that cuts nothing (radius covering the
        aperture, shift 0), colour as ``Chromatic(0, 0)``.
        """
        unknown = [n for n in names if n not in FEATURES]
        if unknown:
            raise InputError(f"features must be among {', '.join(FEATURES)} (got {', '.join(map(repr, unknown))})")
        if "roundness" in names and not self.spec.rounds:
            raise InputError(f"roundness applies only to n-gons (got shape {self.shape!r})")
        values = {}
        if "vignetting" in names and self.vignetting is None:
            values["vignetting"] = Vignetting(max(1.0, math.ceil(self.extent() / samplers.CIRCLE_RADIUS * 1e6) / 1e6), 0.0)
        if "chromatic" in names and self.chromatic is None:
            values["chromatic"] = Chromatic(0.0, 0.0)
        return dataclasses.replace(self, features=self.features | frozenset(names), **values)

    def replace(self, **values) -> Aperture:
        """A validated copy with ``values`` changed: any field, or a name of :attr:`parameters`.

        ``vignetting_radius``/``vignetting_shift`` and ``chromatic_red``/``chromatic_blue``
        change one member of the pair (the feature must be on).
        """
        if values.keys() == {"angle_deg"}:  # a turn: the shape and every other field as validated when made
            return dataclasses.replace(self, angle_deg=check("angle_deg", values["angle_deg"]))
        fields = {
            "angle_deg": self.angle_deg,
            "blades": self.blades if self.spec.takes_blades else None,
            "aspect": self.aspect,
            "roundness": self.roundness,
            "squeeze": self.squeeze,
            "vignetting": self.vignetting,
            "rim": self.rim,
            "chromatic": self.chromatic,
            "mask": self.mask,
        }
        shape = values.pop("shape", self.shape)
        for pair, keys in ((f.name, f.members) for f in FEATURE_SPECS.values() if f.members):
            given = {key: values.pop(f"{pair}_{key}") for key in keys if f"{pair}_{key}" in values}
            if given:
                current = fields[pair] if fields[pair] is not None else getattr(self.with_features(pair), pair)
                fields[pair] = dataclasses.replace(current, **given)
        unknown = set(values) - set(fields)
        if unknown:
            raise InputError(f"replace() takes fields or parameters of the aperture (got {', '.join(sorted(unknown))})")
        fields.update(values)
        rebuilt = make_aperture(shape, **fields)
        features = self.features if rebuilt.spec.rounds else self.features - {"roundness"}
        return dataclasses.replace(rebuilt, features=features)

    def near(self) -> Aperture:
        """The aperture as a near disc shows it (design.md §2, §3b).

        The far disc turned by 180°, the vignetting cut included (its centre
        −shift·R0·q: the shift changes sign); ``rim`` and ``chromatic`` change sign.
        """
        vignetting = None if self.vignetting is None else Vignetting(self.vignetting.radius, -self.vignetting.shift)
        chromatic = None if self.chromatic is None else Chromatic(-self.chromatic.red, -self.chromatic.blue)
        return dataclasses.replace(
            self, angle_deg=self.angle_deg + 180.0, rim=-self.rim, vignetting=vignetting, chromatic=chromatic
        )

    # --- geometry ---------------------------------------------------------------------

    def rotation(self) -> np.ndarray:
        """2×2 matrix R(angle): p' = R·p (design.md §3)."""
        a = math.radians(self.angle_deg)
        return np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])

    def squeeze_matrix(self) -> np.ndarray:
        """diag(1/√squeeze, √squeeze): the squeeze at unit area (:func:`samplers.apply_squeeze`)."""
        root = math.sqrt(self.squeeze)
        return np.array([[1.0 / root, 0.0], [0.0, root]])

    def outline(self, field_position=None) -> Outline:
        """The exact outline at unit area (rotated, squeezed), clipped by the vignetting at ``field_position``.

        ``field_position`` q is the disc's position from the image centre in
        half-diagonals, y up (design.md §3b); it matters only with vignetting
        (None: the unclipped outline). The clipped outline keeps the scale of
        the unclipped one: its area is the light that passes.
        """
        outline = self._behaviour.outline_at_zero().transformed(self.rotation())
        if self.squeeze != 1.0:
            outline = outline.transformed(self.squeeze_matrix())
        if self.vignetting is None or field_position is None:
            return outline
        q = _field_position(field_position)
        centre = self.vignetting.shift * samplers.CIRCLE_RADIUS * q
        return clip_by_circle(outline, centre, self.vignetting.radius * samplers.CIRCLE_RADIUS)

    def area(self, field_position=None) -> float:
        """Area of :meth:`outline`: 1 unclipped, the light that passes (< 1) where the barrel cuts it.

        A mask's transmitted area is 1 by construction (its outline, the 50 % contour, is only a drawing).
        """
        if self.mask is not None:
            return 1.0
        return self.outline(field_position).area()

    def vertices(self) -> np.ndarray | None:
        """Counter-clockwise outline vertices at unit area, rotated and squeezed; None for the plain circle.

        Straight-edged shapes give their exact corners; shapes with arcs (rounded
        blades, a squeezed circle) a dense polygon within :data:`VERTICES_MAX_ERROR`.
        """
        if self.is_circle:
            return None
        outline = self.outline()
        if all(isinstance(piece, Segment) for piece in outline.pieces):
            return np.array([piece.start for piece in outline.pieces])
        return outline.polyline(VERTICES_MAX_ERROR)

    def extent(self) -> float:
        """Largest distance of the unit-area (unclipped) outline from the centre (a mask: of its transmitting cells)."""
        if self.mask is not None:
            half = self.mask.extent()
            corners = np.array([[half, half], [half, -half], [-half, half], [-half, -half]])
            corners = corners @ (self.squeeze_matrix() @ self.rotation()).T
            return float(np.max(np.hypot(corners[:, 0], corners[:, 1])))
        if self.squeeze == 1.0:
            known = self._behaviour.extent_at_zero()  # the circle's radius, rounded blades' circumradius
            if known is not None:
                return known
        verts = self.vertices()
        return float(np.max(np.hypot(verts[:, 0], verts[:, 1])))

    # --- sampling ---------------------------------------------------------------------

    def _radial_fraction_at_zero(self, p: np.ndarray) -> np.ndarray:
        """|p| over the outline's distance in p's direction, for p of the shape at angle 0."""
        return self._behaviour.radial_fraction_at_zero(p)

    def outline_radius(self, theta: np.ndarray) -> np.ndarray:
        """Distance from the centre to the outline at angle 0 (unit area) in the directions ``theta`` (radians).

        Exact for every shape the centre sees whole (star-shaped about it): the
        circle, the polygons and the rounded n-gons, the slit, the star.
        """
        theta = np.asarray(theta, dtype=np.float64)
        directions = np.stack([np.cos(theta), np.sin(theta)], axis=-1)
        if self.squeeze != 1.0:  # a point t·d of the squeezed outline is S·p0 with p0 on the unsqueezed one
            directions = directions @ np.linalg.inv(self.squeeze_matrix()).T
        return 1.0 / self._radial_fraction_at_zero(directions)

    def _sample_at_zero(self, u: np.ndarray) -> np.ndarray:
        return self._behaviour.sample_at_zero(u, self.rim)

    def sample(self, u: np.ndarray, field_position=None, channel: str | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Points of the aperture and their weights, from ``u`` in [0, 1)² (shape (..., 2)).

        The points follow the density :meth:`pdf` (uniform, or the rim profile);
        their weights are 1, or 0 for points the vignetting barrel stops at
        ``field_position`` (the light loss). ``channel`` ``"red"`` or ``"blue"``
        scales the points by (1 + red) or (1 + blue) (design.md §3b); None or
        ``"green"`` is the reference. With every feature at its default the
        points are today's ``sample_<shape>`` rotated, bit for bit.
        """
        p = self._sample_at_zero(u) @ self.rotation().T
        if self.squeeze != 1.0:
            p = samplers.apply_squeeze(p, self.squeeze)
        if self.vignetting is None:
            weights = np.ones(p.shape[:-1])
        else:
            q = _field_position((0.0, 0.0) if field_position is None else field_position)
            weights = samplers.vignetting_weight(p, q, self.vignetting.radius, self.vignetting.shift)
        return p * self._channel_scale(channel), weights

    def _channel_scale(self, channel: str | None) -> float:
        if channel is not None and channel not in CHANNELS:
            raise InputError(f"channel must be one of {', '.join(CHANNELS)} or None (got {channel!r})")
        if self.chromatic is None or channel in (None, "green"):
            return 1.0
        return 1.0 + (self.chromatic.red if channel == "red" else self.chromatic.blue)

    def _to_zero(self, p: np.ndarray, channel: str | None) -> tuple[np.ndarray, float]:
        """p in the frame of the shape at angle 0 (undo colour scale, squeeze, rotation) and the Jacobian."""
        scale = self._channel_scale(channel)
        p = np.asarray(p, dtype=np.float64) / scale
        if self.squeeze != 1.0:
            p = samplers.apply_squeeze(p, 1.0 / self.squeeze)
        return p @ self.rotation(), 1.0 / (scale * scale)

    def radial_fraction(self, p: np.ndarray, channel: str | None = None) -> np.ndarray:
        """ρ of design.md §3b at points ``p`` (unit-area units, the aperture's frame): |p| over the
        distance to the unclipped outline in p's direction (0 at the centre, 1 on the outline, past 1
        outside), exact for every shape the centre sees whole; the rim profile is a function of it."""
        return self._radial_fraction_at_zero(self._to_zero(p, channel)[0])

    def pdf(self, p: np.ndarray, channel: str | None = None) -> np.ndarray:
        """Density of the points of :meth:`sample` (the weights carry the vignetting): the rim profile inside, 0 outside."""
        p0, jacobian = self._to_zero(p, channel)
        return self._behaviour.pdf_at_zero(p0, self.rim) * jacobian

    def invert(self, p: np.ndarray, channel: str | None = None) -> np.ndarray:
        """The ``u`` that :meth:`sample` maps to ``p``, for every shape (the sampler's inverse, p inside)."""
        return self._behaviour.invert_at_zero(self._to_zero(p, channel)[0], self.rim)

    def shader_params(self, field_position=None) -> dict:
        """Values of the WGSL ``ApertureParams`` (:data:`APERTURE_PARAM_FIELDS`) for this aperture."""
        a = math.radians(self.angle_deg)
        q = _field_position((0.0, 0.0) if field_position is None else field_position)
        return {
            "shape": self.spec.shader_id,
            "blades": self.blades or 0,
            "aspect": float(self.aspect or 1.0),
            "roundness": self.roundness,
            "cos_angle": math.cos(a),
            "sin_angle": math.sin(a),
            "squeeze": self.squeeze,
            "rim": self.rim,
            "vignetting_radius": 0.0 if self.vignetting is None else self.vignetting.radius,
            "vignetting_shift": 0.0 if self.vignetting is None else self.vignetting.shift,
            "field_position": (float(q[0]), float(q[1])),
            "chromatic_red": 0.0 if self.chromatic is None else self.chromatic.red,
            "chromatic_blue": 0.0 if self.chromatic is None else self.chromatic.blue,
            "mask_width": 0 if self.mask is None else self.mask.shape[1],
            "mask_height": 0 if self.mask is None else self.mask.shape[0],
            "mask_cell": 0.0 if self.mask is None else self.mask.cell,
        }

    def describe(self) -> str:
        """Short human name, e.g. ``hexagon 20°``, ``ngon(9) 3.5° roundness 0.4``."""
        name = f"ngon({self.blades})" if self.spec.takes_blades else self.shape
        if self.mask is not None:
            name = self.mask.describe()
        if self.spec.takes_aspect:
            name += f"(aspect {self.aspect:g})"
        angle = self.canonical_angle_deg
        text = name if angle is None else f"{name} {round(angle, 2):g}°"
        for feature in ("roundness", "squeeze", "rim"):
            if feature in self.enabled_features:
                text += f" {feature} {getattr(self, feature):g}"
        if self.vignetting is not None:
            text += f" vignetting {self.vignetting.radius:g}/{self.vignetting.shift:g}"
        if self.chromatic is not None:
            text += f" chromatic {self.chromatic.red:+g}/{self.chromatic.blue:+g}"
        return text


def _field_position(value) -> np.ndarray:
    """A field position q as a float (2,) array; InputError naming ``field_position`` otherwise."""
    q = np.asarray(value, dtype=object)
    if q.shape != (2,):
        raise InputError(f"field_position must be a pair (x, y) in half-diagonals, y up (got {value!r})")
    return np.array([check("field_position", v) for v in q], dtype=np.float64)


def make_aperture(
    shape: str,
    angle_deg: float = 0.0,
    *,
    blades: int | None = None,
    aspect: float | None = None,
    roundness: float = 0.0,
    squeeze: float = 1.0,
    vignetting: Vignetting | Mapping | None = None,
    rim: float = 0.0,
    chromatic: Chromatic | Mapping | None = None,
    mask=None,
) -> Aperture:
    """Validate parameters and build an :class:`Aperture`.

    Parameters
    ----------
    shape : str
        One of ``SHAPES`` (circle, square, slit, triangle, pentagon, hexagon, star, ngon),
        or ``ngon(N)`` (see :func:`parse_shape`).
    angle_deg : float
        Counter-clockwise rotation from +x, degrees, within ±1e9 (``bokehfit.validate.RANGES``).
    blades : int, optional
        Blade count: required for ``ngon`` (3 to 64); for triangle, pentagon,
        hexagon and square it may be given only with the shape's own count.
    aspect : float, optional
        Width over height of a ``slit`` (default 0.3).
    roundness : float
        Blade curvature R/ρ in [0, 1] (design.md §3b), n-gons only (triangle,
        square, pentagon, hexagon, ngon); refused for circle, slit and star.
    squeeze : float
        Anamorphic squeeze in [0.001, 1000]; > 1 makes discs taller than wide.
    vignetting : Vignetting or mapping {radius, shift}, optional
        The barrel's cut: radius in [1, 1000], shift in [−1000, 1000] (units of R0 = 1/√π).
    rim : float
        Intensity profile in [−1, 1]: > 0 bright rim, < 0 bright centre.
    chromatic : Chromatic or mapping {red, blue}, optional
        Red and blue disc diameters over green's minus 1, each in [−0.5, 0.5].
    mask : MaskTable, path or 2-D array, optional
        The transmission image of shape ``mask`` (required there, refused
        elsewhere): a :class:`~bokehfit.apertures.mask.MaskTable`, a PNG path
        (:func:`~bokehfit.apertures.mask.load_mask`) or an array in [0, 1].
        A mask takes squeeze and chromatic; rim and vignetting are refused
        (no outline to measure ρ or to clip).

    Raises
    ------
    ValueError
        Naming the parameter and what was expected.

    Examples
    --------
    >>> make_aperture("hexagon", 20).describe()
    'hexagon 20°'
    """
    shape, named_blades = parse_shape(shape)
    if named_blades is not None:
        if blades is not None and blades != named_blades:
            raise InputError(f"blades must be {named_blades} or omitted for shape 'ngon({named_blades})' (got {blades!r})")
        blades = named_blades
    spec = SHAPES[shape]
    angle_deg = check("angle_deg", angle_deg)
    if spec.takes_blades:
        if isinstance(blades, bool) or not isinstance(blades, (int, np.integer)) or not 3 <= blades <= MAX_BLADES:
            raise InputError(f"blades must be an integer from 3 to {MAX_BLADES} for shape 'ngon' (got {blades!r})")
        blades = int(blades)
    elif blades is not None and blades != spec.fixed_blades:
        expected = f"{spec.fixed_blades} or omitted" if spec.fixed_blades else "omitted"
        raise InputError(f"blades must be {expected} for shape {shape!r} (got {blades!r})")
    else:
        blades = spec.fixed_blades
    if spec.takes_aspect:
        aspect = DEFAULT_SLIT_ASPECT if aspect is None else check_finite("aspect", aspect)
        low, high = SLIT_ASPECT_RANGE
        if not low <= aspect <= high:
            raise InputError(f"aspect must be between {low:g} and {high:g} (got {aspect!r})")
    elif aspect is not None:
        raise InputError(f"aspect applies only to shape 'slit' (got aspect={aspect!r} for {shape!r})")
    roundness = check("roundness", roundness)
    if roundness != 0.0 and not spec.rounds:
        raise InputError(
            f"roundness applies only to n-gons (triangle, square, pentagon, hexagon, ngon), "
            f"not to shape {shape!r} (got roundness={roundness!r})"
        )
    squeeze = check("squeeze", squeeze)
    rim = check("rim", rim)
    if vignetting is not None:
        radius, shift = pair_members(vignetting, Vignetting, ("radius", "shift"), "vignetting")
        vignetting = Vignetting(check("vignetting_radius", radius, name="vignetting.radius"),
                                check("vignetting_shift", shift, name="vignetting.shift"))
    if chromatic is not None:
        red, blue = pair_members(chromatic, Chromatic, ("red", "blue"), "chromatic")
        chromatic = Chromatic(check("chromatic", red, name="chromatic.red"), check("chromatic", blue, name="chromatic.blue"))
    if spec.tabulated:
        if mask is None:
            raise InputError(f"mask is required for shape {shape!r}: a PNG path or a 2-D array of transmission in [0, 1]")
        if not isinstance(mask, MaskTable):
            mask = load_mask(mask) if isinstance(mask, (str, os.PathLike)) else MaskTable.from_array(mask)
        if rim != 0.0 or vignetting is not None:
            raise InputError(f"{'rim' if rim != 0.0 else 'vignetting'} does not apply to shape {shape!r} (a mask has no outline to measure it on)")
    elif mask is not None:
        raise InputError(f"mask applies only to shape 'mask' (got a mask for {shape!r})")
    return Aperture(shape, angle_deg, blades, aspect, roundness, squeeze, vignetting, rim, chromatic, mask=mask)

