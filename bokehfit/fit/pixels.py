"""Fit discs' pixels with a kernel: shape, angle, size, centre, levels, edge blur and the lens's features.

Notes
-----
The model of a disc's crop is

    I(x) = b + (p − b) · (G_σ ⊗ K)(x),

with K the light of the aperture on each pixel (``bokehfit.kernels.exact``:
exact coverage, weighted by the ``rim`` profile where the aperture has one,
clipped by the ``vignetting`` at the disc's place in the frame) at centre c
and equal-area diameter d, and G_σ a Gaussian edge blur (sensor,
demosaicing, JPEG). Least squares (trust-region reflective, bounded) fits c,
d, σ and the aperture's own :attr:`~bokehfit.apertures.Aperture.parameters`
(the angle, the slit's aspect, the roundness, ...), solving for b and p at
every step (they enter linearly: variable projection).

**Clipped pixels are censored, not lost.** A pixel clipped in the source (any
channel at the file's top value) says only that the light there was at least
what was recorded, so its residual is min(model − data, 0): the model may pass
above it, never below. A saturated disc's plateau p is then unknown above the
clip and becomes a fitted parameter; its outline still fixes the shape.

**Many discs, one aperture.** :func:`fit_discs` fits several discs at once:
each disc its own centre, size, blur and levels, all of them the shared
aperture parameters (and the vignetting, which only the discs' spread over the
frame can tell). The Jacobian is block-sparse (a disc's residuals depend on
its own parameters and the shared ones), so finite differences cost a few
renders of every disc, not one per parameter. Each disc's residuals are
divided by its own noise level (from its single-disc fit), so a bright disc
does not outvote the others.

Each disc is fitted on its crop (:mod:`bokehfit.fit.crop`: reduced where wide, the light that is
not the disc's left out). Uncertainties are from the Jacobian at the optimum:
cov = (JᵀJ)⁻¹ · RSS / (n − k).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.optimize import least_squares

from bokehfit.apertures import Aperture, ParameterSpec, image_to_aperture
from bokehfit.discs import Disc
from bokehfit.fit.crop import DiscCrop, crop_disc
from bokehfit.fit.families import Family
from bokehfit.kernels.exact import coverage, rim_coverage

__all__ = [
    "JointFit",
    "PixelFit",
    "disc_profile",
    "fit_disc_pixels",
    "fit_discs",
    "model_window",
    "render_disc_model",
]

#: Most function evaluations per fit.
MAX_EVALUATIONS = 200
#: Relative change of the cost and of the parameters at which a fit stops (scipy's ftol and xtol):
#: 1e-6 of an angle of 30° is 3e-5°, far below what the discs can tell.
TOLERANCE = 1e-6
#: Widest slit fitted: at aspect 1 the slit is the square, which has a model of its own.
MAX_SLIT_ASPECT = 0.8
#: Edge-blur bounds, crop pixels.
BLUR_RANGE = (0.05, 6.0)
#: The parameters of every disc, first in the fit's vector (crop units; the centre in crop pixel coordinates).
DISC_NAMES = ("cx", "cy", "diameter_px", "blur_px")
#: Fit bounds narrower than :attr:`ParameterSpec.bounds`, by parameter name.
FIT_BOUNDS = {"aspect": (0.01, MAX_SLIT_ASPECT), "vignetting_radius": (1.0, 4.0), "vignetting_shift": (-4.0, 4.0),
              "squeeze": (0.25, 4.0)}
#: Parameters searched within a factor of 2 of their start (scale factors, not offsets).
RELATIVE_PARAMETERS = ("aspect", "squeeze")
#: Sub-pixels a side for the rim profile in the fit (the edge blur hides finer detail).
RIM_FIT_SUPERSAMPLE = 3
#: Bytes of coverages a fit keeps for its next steps (:func:`disc_profile`'s ``covers``): a
#: Jacobian's blur column comes a few steps after the point it is taken at.
COVERS_BYTES = 32 << 20
#: A saturated disc's plateau is searched up to this many times the clip level.
MAX_PLATEAU_OVER_CLIP = 50.0


@dataclass(frozen=True)
class PixelFit:
    """One family fitted to one disc's pixels."""

    family: Family
    aperture: Aperture  #: the fitted aperture, its angle in [0, symmetry)
    center_xy: tuple[float, float]  #: full-resolution (column, row)
    diameter_px: float
    plateau: float
    background: float
    blur_px: float
    rss: float  #: residual sum of squares over the crop
    pixels: int
    uncertainty: dict  #: one standard deviation of each parameter (full-resolution units)
    evaluations: int
    success: bool
    censored: int = 0  #: pixels fitted as lower bounds (clipped in the source)
    field_position: tuple[float, float] | None = None  #: where the disc lies in the frame (design.md §3b)

    @property
    def angle_deg(self) -> float | None:
        """The fitted angle in [0, symmetry); None where the aperture has none."""
        return self.aperture.angle_deg if self.aperture.has_angle else None

    @property
    def aspect(self) -> float | None:
        """The fitted slit aspect; None for other shapes."""
        return self.aperture.aspect

    @property
    def parameter_count(self) -> int:
        """Parameters counted for the BIC: the family's, and the features switched on beyond them (roundness, rim, ...)."""
        return self.family.parameters + len(self.aperture.parameters) - len(self.family.aperture.parameters)

    @property
    def noise(self) -> float:
        """The residuals' RMS: the disc's noise level under this model."""
        return math.sqrt(max(self.rss, 1e-300) / self.pixels)

    @property
    def bic(self) -> float:
        """Bayesian information criterion: n·ln(RSS/n) + k·ln(n)."""
        n = self.pixels
        return n * math.log(max(self.rss, 1e-300) / n) + self.parameter_count * math.log(n)


def disc_profile(
    aperture: Aperture,
    disc: Mapping[str, float],
    size: int,
    field_position: Sequence[float] | None = None,
    covers: dict | None = None,
) -> np.ndarray:
    """The blurred unit-contrast disc (size × size) of ``aperture``; ``disc`` holds the :data:`DISC_NAMES`
    in crop units, the centre in crop pixel coordinates. ``field_position`` places a vignetted aperture.

    ``covers``, where given, is the caller's memo of the unblurred coverages by their geometry
    (aperture, size, centre, diameter, field position): a fit's steps that change only the blur
    or the levels (a Jacobian's blur column, a plateau's) reuse the coverage instead of
    integrating it again. It keeps the latest, about ``COVERS_BYTES`` in all."""
    centre = (size - 1) / 2.0
    where = None if aperture.vignetting is None else field_position
    key = (aperture, size, disc["cx"], disc["cy"], disc["diameter_px"], None if where is None else tuple(where))
    cover = None if covers is None else covers.get(key)
    if cover is None:
        scale = max(disc["diameter_px"], 1e-3) * math.sqrt(math.pi) / 2.0
        (offset_xy,) = image_to_aperture([[disc["cy"] - centre, disc["cx"] - centre]])
        if aperture.rim != 0.0:
            cover, _ = rim_coverage(aperture, scale, size, field_position=where, supersample=RIM_FIT_SUPERSAMPLE,
                                    max_chord_error=1e-4, offset_xy=tuple(offset_xy))
        else:
            cover = coverage(_outline(aperture, where, covers), scale, size, offset_xy=tuple(offset_xy))
        cover = cover.astype(np.float32)
        if covers is not None:
            covers[key] = cover
            while (len(covers) - (_OUTLINES in covers)) * cover.nbytes > COVERS_BYTES and len(covers) > 2:
                del covers[next(k for k in covers if k != _OUTLINES)]  # the oldest
    return cv2.GaussianBlur(cover, (0, 0), max(disc["blur_px"], BLUR_RANGE[0]), borderType=cv2.BORDER_REPLICATE)


#: Key of :func:`disc_profile`'s ``covers`` under which the outlines of the latest apertures are kept.
_OUTLINES = "outlines"
#: Outlines kept there: a fit's steps that move only a disc (its centre, size or blur) reuse the
#: aperture's outline, which for a vignetted one (the shape clipped by the barrel) costs more
#: than the coverage.
OUTLINES_KEPT = 32


def _outline(aperture: Aperture, where: tuple[float, float] | None, covers: dict | None):
    """``aperture.outline(where)``, from the memo in ``covers`` where there is one."""
    if covers is None:
        return aperture.outline(where)
    outlines = covers.setdefault(_OUTLINES, {})
    key = (aperture, None if where is None else tuple(where))
    outline = outlines.get(key)
    if outline is None:
        outline = outlines[key] = aperture.outline(where)
        if len(outlines) > OUTLINES_KEPT:
            del outlines[next(iter(outlines))]  # the oldest
    return outline


def _search_bounds(parameter: ParameterSpec, start: float) -> tuple[float, float, float]:
    """(start, lower, upper) of one aperture parameter for the fit.

    A periodic parameter (the angle) is searched half a period either side of
    its start; the others within their bounds (:data:`FIT_BOUNDS` where the fit
    asks for less), scale factors only within a factor of 2 of the start.
    """
    if parameter.periodic is not None:
        return start, start - 0.5 * parameter.periodic, start + 0.5 * parameter.periodic
    low, high = FIT_BOUNDS.get(parameter.name, parameter.bounds)
    start = min(max(start, low), high)
    if parameter.name in RELATIVE_PARAMETERS:
        low, high = max(low, 0.5 * start), min(high, 2.0 * start)
    return start, low, high


def _levels(profile: np.ndarray, data: np.ndarray) -> tuple[float, float]:
    """Background and plateau that fit ``data`` best for this profile (2×2 linear least squares)."""
    ones = 1.0 - profile
    a11, a12, a22 = float(ones @ ones), float(ones @ profile), float(profile @ profile)
    r1, r2 = float(ones @ data), float(profile @ data)
    det = a11 * a22 - a12 * a12
    if abs(det) < 1e-12:
        return float(data.mean()), float(data.mean())
    return (a22 * r1 - a12 * r2) / det, (a11 * r2 - a12 * r1) / det


def _background(profile: np.ndarray, data: np.ndarray, plateau: float) -> float:
    """The background that fits ``data`` best for this profile and a given plateau."""
    ones = 1.0 - profile
    weight = float(ones @ ones)
    return float(ones @ (data - plateau * profile)) / weight if weight > 1e-12 else float(data.min())


def render_disc_model(
    aperture: Aperture,
    disc: Mapping[str, float],
    size: int,
    data: np.ndarray,
    field_position: Sequence[float] | None = None,
    censored: np.ndarray | None = None,
    ignored: np.ndarray | None = None,
    covers: dict | None = None,
) -> tuple[np.ndarray, float, float]:
    """Model crop (flattened) with its levels for ``data``: (model, background, plateau).

    The levels are solved for (least squares over the pixels neither censored nor ignored);
    a ``disc`` that holds ``"plateau"`` (a saturated disc) fixes the plateau
    and only the background is solved for. ``covers``: see :func:`disc_profile`.
    """
    profile = disc_profile(aperture, disc, size, field_position, covers).ravel().astype(np.float64)
    seen = slice(None)
    if censored is not None or ignored is not None:
        seen = ~(_or(censored, ignored))
    if "plateau" in disc:
        plateau = disc["plateau"]
        background = _background(profile[seen], data[seen], plateau)
    else:
        background, plateau = _levels(profile[seen], data[seen])
    return background + (plateau - background) * profile, background, plateau


def _residuals(model: np.ndarray, crop: DiscCrop) -> np.ndarray:
    """model − data; where the source is clipped only a model below the recorded value is an error;
    where the light is not the disc's, none."""
    residual = model - crop.data
    if crop.censored is not None:
        residual[crop.censored] = np.minimum(residual[crop.censored], 0.0)
    if crop.ignored is not None:
        residual[crop.ignored] = 0.0
    return residual


def _or(a: np.ndarray | None, b: np.ndarray | None) -> np.ndarray:
    """``a | b`` of two optional masks (one of them given)."""
    return b if a is None else a if b is None else a | b


def _disc_vector(crop: DiscCrop) -> tuple[list[str], list[float], list[float], list[float]]:
    """One disc's names, start, lower and upper bounds (crop units)."""
    start = crop.start
    names = list(DISC_NAMES)
    x0 = [start[n] for n in DISC_NAMES]
    lower = [start["cx"] - 3, start["cy"] - 3, 0.5 * start["diameter_px"], BLUR_RANGE[0]]
    upper = [start["cx"] + 3, start["cy"] + 3, 1.5 * start["diameter_px"], BLUR_RANGE[1]]
    clip = crop.clip_level
    if clip is not None:  # a saturated disc: its plateau is somewhere above the clip
        names.append("plateau")
        x0.append(max(crop.disc.plateau, clip) * 1.5)
        lower.append(clip)
        upper.append(clip * MAX_PLATEAU_OVER_CLIP)
    return names, x0, lower, upper


def _shared_vector(start: Aperture, free: Sequence[str]) -> tuple[list[float], list[float], list[float]]:
    parameters = start.parameters
    values = start.values
    x0, lower, upper = [], [], []
    for name in free:
        first, low, high = _search_bounds(parameters[name], values[name])
        x0.append(first)
        lower.append(low)
        upper.append(high)
    return x0, lower, upper


def _wrapped(aperture: Aperture, values: Mapping[str, float]) -> Aperture:
    """``aperture`` with ``values`` set, periodic ones (the angle) reduced to [0, period)."""
    parameters = aperture.parameters
    wrapped = {n: (v % parameters[n].periodic if parameters[n].periodic is not None else v) for n, v in values.items()}
    return aperture.replace(**wrapped) if wrapped else aperture


@dataclass(frozen=True)
class JointFit:
    """Several discs fitted with one aperture: the aperture, each disc's fit, and the evidence."""

    aperture: Aperture
    fits: list[PixelFit]
    uncertainty: dict  #: one standard deviation of each shared parameter
    rss: float  #: weighted: each disc's residuals over its noise level
    pixels: int
    parameters: int
    evaluations: int

    @property
    def bic(self) -> float:
        n = self.pixels
        return n * math.log(max(self.rss, 1e-300) / n) + self.parameters * math.log(n)


def fit_discs(
    crops: Sequence[DiscCrop],
    family: Family,
    start: Aperture,
    free: Sequence[str] | None = None,
    noise: Sequence[float] | None = None,
    disc_starts: Sequence[Mapping[str, float]] | None = None,
) -> JointFit:
    """Least-squares fit of ``crops`` sharing one aperture.

    The vector fitted is the shared aperture parameters ``free`` (default: all
    of ``start``'s :attr:`~bokehfit.apertures.Aperture.parameters`), then each
    disc's :data:`DISC_NAMES` (and plateau where it is saturated). ``noise``
    (one per crop, default 1) divides each disc's residuals. ``disc_starts``
    (crop units) replace the outline's starting values where given.
    """
    free = tuple(start.parameters) if free is None else tuple(free)
    noise = np.ones(len(crops)) if noise is None else np.maximum(np.asarray(noise, dtype=np.float64), 1e-12)
    x0, lower, upper = _shared_vector(start, free)
    blocks = []
    for i, crop in enumerate(crops):
        names, d0, dlow, dhigh = _disc_vector(crop)
        if disc_starts is not None and disc_starts[i] is not None:
            d0 = [min(max(disc_starts[i].get(n, v), lo), hi) for n, v, lo, hi in zip(names, d0, dlow, dhigh)]
        blocks.append((len(x0), names))
        x0 += d0
        lower += dlow
        upper += dhigh
    shared = len(free)

    def split(vector):
        aperture = start.replace(**dict(zip(free, (float(v) for v in vector[:shared])))) if shared else start
        discs = [dict(zip(names, (float(v) for v in vector[at : at + len(names)]))) for at, names in blocks]
        return aperture, discs

    covers: dict = {}  # the coverages of the last steps (disc_profile)

    def residuals(vector):
        aperture, discs = split(vector)
        turned = aperture.near() if any(c.turned for c in crops) else aperture
        parts = [
            _residuals(render_disc_model(turned if c.turned else aperture, d, c.size, c.data, c.field_position,
                                         c.censored, c.ignored, covers)[0], c) / s
            for c, d, s in zip(crops, discs, noise)
        ]
        return np.concatenate(parts)

    rows = [c.data.size for c in crops]
    sparsity = None
    if len(crops) > 1:
        sparsity = np.zeros((sum(rows), len(x0)), dtype=bool)
        row = 0
        for (at, names), count in zip(blocks, rows):
            sparsity[row : row + count, :shared] = True
            sparsity[row : row + count, at : at + len(names)] = True
            row += count
    result = least_squares(
        residuals,
        np.array(x0, dtype=np.float64),
        bounds=(lower, upper),
        method="trf",
        x_scale="jac",
        max_nfev=MAX_EVALUATIONS,
        diff_step=1e-4,
        ftol=TOLERANCE,
        xtol=TOLERANCE,
        jac_sparsity=sparsity,
        tr_solver="exact" if sparsity is None else "lsmr",
    )
    _, discs = split(result.x)
    aperture = _wrapped(start, {name: float(v) for name, v in zip(free, result.x[:shared])})
    jacobian = result.jac.toarray() if hasattr(result.jac, "toarray") else result.jac
    # The levels solved for at every step count too: two per disc, one where the plateau is fitted.
    n, k = sum(c.pixels for c in crops), len(x0) + sum(1 if "plateau" in names else 2 for _, names in blocks)
    total = float(np.sum(result.fun**2))
    sigma = np.full(len(x0), np.nan)
    try:
        covariance = np.linalg.pinv(jacobian.T @ jacobian) * total / max(n - k, 1)
        sigma = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
    except np.linalg.LinAlgError:
        pass
    fits, row = [], 0
    for crop, values, (at, names), count, scale in zip(crops, discs, blocks, rows, noise):
        shown = aperture.near() if crop.turned else aperture
        model, background, plateau = render_disc_model(shown, values, crop.size, crop.data, crop.field_position,
                                                       crop.censored, crop.ignored)
        rss = float(np.sum(_residuals(model, crop) ** 2))
        full = crop.to_full(values)
        in_full = {"cx": crop.factor, "cy": crop.factor, "diameter_px": crop.factor, "blur_px": crop.factor}
        uncertainty = {name: float(s * in_full.get(name, 1.0)) for name, s in zip(names, sigma[at : at + len(names)])}
        uncertainty.update({name: float(s) for name, s in zip(free, sigma[:shared])})
        fits.append(PixelFit(
            family=family,
            aperture=shown,
            center_xy=full.center_xy,
            diameter_px=full.diameter_px,
            plateau=float(plateau),
            background=float(background),
            blur_px=full.blur_px,
            rss=rss,
            pixels=crop.pixels,
            uncertainty=uncertainty,
            evaluations=int(result.nfev),
            success=bool(result.success),
            censored=0 if crop.censored is None else int(crop.censored.sum()),
            field_position=crop.field_position,
        ))
        row += count
    return JointFit(
        aperture=aperture,
        fits=fits,
        uncertainty={name: float(s) for name, s in zip(free, sigma[:shared])},
        rss=total,
        pixels=n,
        parameters=k,
        evaluations=int(result.nfev),
    )


def fit_disc_pixels(
    luminance: np.ndarray,
    disc: Disc,
    family: Family,
    start: Aperture,
    clipped: np.ndarray | None = None,
) -> PixelFit:
    """Least-squares fit of ``family`` to one disc's pixels, starting at the aperture ``start`` (the screen's).

    The vector fitted is the disc's :data:`DISC_NAMES` (and its plateau where
    ``clipped`` marks some of its pixels), then ``start``'s
    :attr:`~bokehfit.apertures.Aperture.parameters` by name (bounds from
    :func:`_search_bounds`); the fitted aperture keeps its angle in [0, symmetry).
    """
    return fit_discs([crop_disc(luminance, disc, clipped)], family, start).fits[0]


def model_window(fit: PixelFit, left: int, top: int, size: int) -> np.ndarray:
    """The fitted model of a disc on a full-resolution window (size × size, top-left at (left, top))."""
    disc = {"cx": fit.center_xy[0] - left, "cy": fit.center_xy[1] - top, "diameter_px": fit.diameter_px,
            "blur_px": fit.blur_px}
    profile = disc_profile(fit.aperture, disc, size, fit.field_position)
    return (fit.background + (fit.plateau - fit.background) * profile).astype(np.float32)
