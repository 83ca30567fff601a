"""Transfer curves and luminance weights: from encoded pixel values to linear light.

A photo's pixel values are encoded with a transfer curve (sRGB's piecewise
curve, Adobe RGB's gamma 563/256, ...) in some RGB space. bokehfit measures
light, so the loader decodes each channel to linear light and takes the
luminance ``Y = w_r R + w_g G + w_b B`` with the weights of that space (the Y
row of its RGB→XYZ matrix). Which space a file uses is read, in this order,
from:

1. the embedded ICC profile: its description names a known space (sRGB,
   Adobe RGB (1998), Display P3, ProPhoto RGB), else its own tone curves and
   colorants are used when it is a matrix/TRC profile;
2. a PNG ``sRGB`` chunk, else a PNG ``gAMA`` chunk (a pure power curve);
3. EXIF ``ColorSpace`` = 1 (sRGB), else EXIF ``InteropIndex`` "R03" (Adobe RGB,
   the DCF option file), else an XMP ``photoshop:ICCProfile`` name;
4. otherwise sRGB is assumed, and the description says so.

A profile's tone curve is used only if it is a usable decoding curve: finite,
non-decreasing (within :data:`CURVE_MONOTONIC_TOLERANCE`) and rising over
[0, 1] (a parametric curve's gamma positive, its ``a`` non-zero). A degenerate
curve (gamma 0, a division by zero, a curve that falls) makes the profile
unusable: sRGB is assumed and a note says why.

The known spaces' curves and luminance weights are written here from their
standards (:data:`_KNOWN`), the same definitions colour-science gives
(``colour.RGB_COLOURSPACES[name]``: its ``cctf_decoding`` and the Y row of its
``matrix_RGB_to_XYZ``; the tests hold them to it within 1e-12). colour-science
is not imported to read a photo: its import pulls in matplotlib and costs
about a second. An :class:`Encoding` tabulates its curves once per bit depth,
on itself, so decoding an 8- or 16-bit image is a table look-up.

References
----------
ICC.1:2001-04 (v2) and ICC.1:2022 (v4) profile formats: header, tag table,
``desc``/``mluc``, ``curv``, ``para`` and ``XYZ`` tag types.
IEC 61966-2-1:1999 (sRGB); Adobe RGB (1998) Color Image Encoding, 2005;
ISO 22028-2:2013 (ROMM RGB, which ProPhoto RGB is); Apple, Display P3 (2019:
the DCI-P3 primaries with the D65 white); SMPTE RP 177-1993 (the normalised
primary matrix).
"""

from __future__ import annotations

import math
import struct
import warnings
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

__all__ = [
    "Encoding",
    "KNOWN_SPACES",
    "detect_encoding",
    "icc_description",
    "known_space_from_name",
    "luminance_weights",
    "named_encoding",
    "linear_encoding",
    "srgb_decode",
    "srgb_display_lut",
    "srgb_encode",
]

#: Colour spaces recognised by name, as colour-science names them, with the
#: transfer curve each uses (for people).
KNOWN_SPACES = {
    "sRGB": "sRGB piecewise curve (IEC 61966-2-1)",
    "Adobe RGB (1998)": "gamma 563/256",
    "Display P3": "sRGB piecewise curve",
    "ProPhoto RGB": "ROMM RGB curve (gamma 1.8, linear toe)",
}

Curve = Callable[[np.ndarray], np.ndarray]

#: A sampled ICC tone curve may fall by this much (of full scale) between samples and still be
#: taken as non-decreasing: 16-bit tables of real profiles carry rounding noise.
CURVE_MONOTONIC_TOLERANCE = 1e-3
#: A tone curve must rise at least this much (of full scale) from code 0 to code 1.
CURVE_MIN_RISE = 0.01
#: Samples at which a profile's tone curve is checked (evenly spaced on [0, 1]).
CURVE_CHECK_SAMPLES = 1025


def colour_science():
    """The ``colour`` package (colour-science), imported on call: the reference the tests hold
    the curves of :data:`_KNOWN` to (it takes about a second to import, matplotlib with it).

    colour-science warns at import about optional packages it can't find
    (matplotlib, …) that bokehfit does not use; those warnings are dropped here.
    """
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=r".*related API features are not available")
        import colour
    return colour


def srgb_decode(encoded) -> np.ndarray:
    """Linear light of sRGB-encoded values in [0, 1] (IEC 61966-2-1: the piecewise curve), float64.

    The linear segment ends where the encoding's does, at the code of linear 0.0031308
    (0.0404499…, as colour-science's ``eotf_sRGB`` takes it).
    """
    v = np.asarray(encoded, dtype=np.float64)
    knee = 1.055 * 0.0031308 ** (1.0 / 2.4) - 0.055
    return np.where(v <= knee, v / 12.92, np.maximum((v + 0.055) / 1.055, 0.0) ** 2.4)


def srgb_encode(linear) -> np.ndarray:
    """sRGB encoding in [0, 1] of linear values in [0, 1] (IEC 61966-2-1), float64 (WGSL twin: ``shaders/tonemap.wgsl``)."""
    x = np.asarray(linear, dtype=np.float64)
    return np.where(x <= 0.0031308, x * 12.92, 1.055 * np.maximum(x, 0.0) ** (1.0 / 2.4) - 0.055)


def _adobe_rgb_decode(encoded) -> np.ndarray:
    """Adobe RGB (1998): a pure power curve, gamma 563/256 (sign kept below 0)."""
    v = np.asarray(encoded, dtype=np.float64)
    return np.sign(v) * np.abs(v) ** (563.0 / 256.0)


def _romm_rgb_decode(encoded) -> np.ndarray:
    """ROMM RGB (ProPhoto RGB), ISO 22028-2: linear below 16·E_t = 1/32, else the power 1.8.

    E_t = 16^(1.8 / (1 − 1.8)) = 1/512 is where the two pieces meet.
    """
    v = np.asarray(encoded, dtype=np.float64)
    threshold = 16.0 * 16.0 ** (1.8 / (1.0 - 1.8))
    return np.where(v < threshold, v / 16.0, np.sign(v) * np.abs(v) ** 1.8)


def _normalised_primary_matrix(primaries, white) -> np.ndarray:
    """RGB → XYZ of primaries (x, y) × 3 and a white (x, y), white at Y = 1 (SMPTE RP 177-1993)."""
    xy = np.asarray(primaries, dtype=np.float64)
    xyz = np.stack([xy[:, 0] / xy[:, 1], np.ones(3), (1.0 - xy[:, 0] - xy[:, 1]) / xy[:, 1]])  # columns: X, Y, Z at Y = 1
    wx, wy = white
    white_xyz = np.array([wx / wy, 1.0, (1.0 - wx - wy) / wy])
    return xyz * np.linalg.solve(xyz, white_xyz)


#: The known spaces: (decoding curve, luminance weights = the Y row of RGB → XYZ). sRGB, Adobe
#: RGB and ROMM RGB give their matrices in their standards (rounded as there); Display P3 is
#: the DCI-P3 primaries with the D65 white (0.3127, 0.3290), its matrix derived from them.
_KNOWN = {
    "sRGB": (srgb_decode, (0.2126, 0.7152, 0.0722)),
    "Adobe RGB (1998)": (_adobe_rgb_decode, (0.29734, 0.62736, 0.07529)),
    "Display P3": (srgb_decode, tuple(float(w) for w in _normalised_primary_matrix(
        [(0.680, 0.320), (0.265, 0.690), (0.150, 0.060)], (0.3127, 0.3290))[1])),
    "ProPhoto RGB": (_romm_rgb_decode, (0.2880, 0.7119, 0.0001)),
}


def luminance_weights(name: str) -> tuple[float, float, float]:
    """The Y row of the RGB→XYZ matrix of the colour space ``name`` (one of :data:`KNOWN_SPACES`).

    Examples
    --------
    >>> [round(w, 4) for w in luminance_weights("sRGB")]
    [0.2126, 0.7152, 0.0722]
    """
    if name not in _KNOWN:
        raise ValueError(f"colour space must be one of {', '.join(KNOWN_SPACES)} (got {name!r})")
    return _KNOWN[name][1]


def _named_curve(name: str) -> Curve:
    return _KNOWN[name][0]


@dataclass(frozen=True, eq=False)
class Encoding:
    """How a file's pixel values map to linear light.

    Attributes
    ----------
    colour_space : str
        ``"sRGB"``, ``"Adobe RGB (1998)"``, ``"Display P3"``, ``"ProPhoto RGB"``,
        ``"ICC 'name'"`` for another matrix/TRC profile, or ``"linear"``.
    transfer : str
        The decoding curve, for people (``"gamma 563/256"``).
    source : str
        Where the colour space came from (``"embedded ICC profile 'Adobe RGB (1998)'"``),
        or why it was assumed.
    weights : tuple of 3 float
        Luminance weights of R, G, B.
    curves : tuple of 3 callables
        Per-channel decoding, encoded values in [0, 1] to linear (float64 arrays).
    assumed : bool
        True when the file states no usable colour space.
    notes : tuple of str
        Anything else a person should know (conflicting metadata).
    """

    colour_space: str
    transfer: str
    source: str
    weights: tuple[float, float, float]
    curves: tuple[Curve, Curve, Curve]
    assumed: bool = False
    notes: tuple[str, ...] = ()
    _luts: dict = field(default_factory=dict, repr=False, compare=False)

    def lut(self, bits: int) -> np.ndarray:
        """Linear value of every ``bits``-bit code, per channel: float32 of shape (2**bits, 3)."""
        if bits not in self._luts:
            codes = np.arange(2**bits, dtype=np.float64) / (2**bits - 1)
            table = np.stack([np.asarray(curve(codes), dtype=np.float64) for curve in self.curves], axis=-1)
            table = np.clip(np.nan_to_num(table, nan=0.0), 0.0, None)
            self._luts[bits] = np.ascontiguousarray(table, dtype=np.float32)
        return self._luts[bits]

    def weighted_lut(self, bits: int) -> np.ndarray:
        """:meth:`lut` times the luminance weights: summing its three columns gives Y."""
        key = ("weighted", bits)
        if key not in self._luts:
            weights = np.asarray(self.weights, dtype=np.float64)
            self._luts[key] = np.ascontiguousarray(self.lut(bits) * weights, dtype=np.float32)
        return self._luts[key]

    def with_note(self, note: str) -> "Encoding":
        """A copy with ``note`` added."""
        return Encoding(
            self.colour_space, self.transfer, self.source, self.weights, self.curves, self.assumed, self.notes + (note,)
        )

    def describe(self) -> str:
        """One line for ``Photo.linearisation``.

        ``"Adobe RGB (1998) from embedded ICC profile 'Adobe RGB (1998)': gamma 563/256"``, or
        ``"sRGB transfer (assumed: the file states no colour space)"``.
        """
        if self.assumed:
            text = f"{self.colour_space} transfer (assumed: {self.source})"
        else:
            text = f"{self.colour_space} from {self.source}: {self.transfer}"
        return "; ".join((text,) + self.notes)


def named_encoding(name: str, source: str, *, assumed: bool = False) -> Encoding:
    """The encoding of one of :data:`KNOWN_SPACES`."""
    if name not in KNOWN_SPACES:
        raise ValueError(f"colour space must be one of {', '.join(KNOWN_SPACES)} (got {name!r})")
    curve = _named_curve(name)
    return Encoding(name, KNOWN_SPACES[name], source, luminance_weights(name), (curve, curve, curve), assumed)


def linear_encoding(source: str) -> Encoding:
    """Linear values with sRGB (Rec. 709) primaries, e.g. a float TIFF."""

    def identity(x: np.ndarray) -> np.ndarray:
        return np.asarray(x, dtype=np.float64)

    return Encoding("linear", "none (linear)", source, luminance_weights("sRGB"), (identity,) * 3)


def _gamma_curve(exponent: float) -> Curve:
    def decode(x: np.ndarray) -> np.ndarray:
        return np.power(np.clip(np.asarray(x, dtype=np.float64), 0.0, None), exponent)

    return decode


def known_space_from_name(name: str | None) -> str | None:
    """The known colour space a profile name or description refers to, or None.

    Examples
    --------
    >>> known_space_from_name("Compatible with Adobe RGB (1998)")
    'Adobe RGB (1998)'
    >>> known_space_from_name("sRGB IEC61966-2.1")
    'sRGB'
    """
    if not name:
        return None
    text = name.lower().replace("_", " ")
    compact = text.replace(" ", "")
    if "adobergb" in compact:
        return "Adobe RGB (1998)"
    if "prophoto" in compact or "rommrgb" in compact:
        return "ProPhoto RGB"
    if "displayp3" in compact:
        return "Display P3"
    if "srgb" in compact or "61966-2" in compact:
        return "sRGB"
    return None


# --------------------------------------------------------------------------------------
# ICC profiles
# --------------------------------------------------------------------------------------


def _icc_tags(icc: bytes) -> dict[bytes, bytes]:
    """Tag signature -> tag data of an ICC profile; ValueError if it is malformed."""
    if len(icc) < 132 or icc[36:40] != b"acsp":
        raise ValueError("not an ICC profile (no 'acsp' signature)")
    (count,) = struct.unpack(">I", icc[128:132])
    if 132 + 12 * count > len(icc):
        raise ValueError("ICC tag table runs past the end of the profile")
    tags = {}
    for i in range(count):
        signature, offset, size = struct.unpack(">4sII", icc[132 + 12 * i : 144 + 12 * i])
        if offset + size <= len(icc):
            tags[signature] = icc[offset : offset + size]
    return tags


def _text_tag(data: bytes) -> str | None:
    kind = data[:4]
    if kind == b"desc" and len(data) >= 12:  # v2 textDescriptionType: ASCII part
        (length,) = struct.unpack(">I", data[8:12])
        return data[12 : 12 + length].split(b"\x00")[0].decode("latin-1").strip() or None
    if kind == b"mluc" and len(data) >= 16:  # v4 multiLocalizedUnicodeType: first record
        count, record_size = struct.unpack(">II", data[8:16])
        if count and record_size >= 12 and len(data) >= 28:
            length, offset = struct.unpack(">II", data[20:28])
            return data[offset : offset + length].decode("utf-16-be", "replace").strip("\x00 ") or None
    if kind == b"text":
        return data[8:].split(b"\x00")[0].decode("latin-1").strip() or None
    return None


def icc_description(icc: bytes) -> str | None:
    """The profile description (``desc`` tag) of an ICC profile, or None if unreadable."""
    try:
        tags = _icc_tags(icc)
    except (ValueError, struct.error):
        return None
    return _text_tag(tags[b"desc"]) if b"desc" in tags else None


def _s15f16(data: bytes, count: int, offset: int = 8) -> tuple[float, ...]:
    return tuple(v / 65536.0 for v in struct.unpack(f">{count}i", data[offset : offset + 4 * count]))


def _icc_curve(data: bytes) -> tuple[Curve, str]:
    """Decoding curve of an ICC ``curv`` or ``para`` tag, and its description."""
    kind = data[:4]
    if kind == b"curv":
        (count,) = struct.unpack(">I", data[8:12])
        if count == 0:
            return _gamma_curve(1.0), "linear"
        if count == 1:
            (raw,) = struct.unpack(">H", data[12:14])
            return _gamma_curve(raw / 256.0), f"gamma {raw}/256"
        table = np.frombuffer(data[12 : 12 + 2 * count], dtype=">u2").astype(np.float64) / 65535.0
        if table.size != count:
            raise ValueError("truncated curv tag")
        grid = np.linspace(0.0, 1.0, count)

        def sampled(x: np.ndarray) -> np.ndarray:
            return np.interp(np.asarray(x, dtype=np.float64), grid, table)

        return sampled, f"{count}-point tone curve"
    if kind == b"para":
        (function,) = struct.unpack(">H", data[8:10])
        n_params = {0: 1, 1: 3, 2: 4, 3: 5, 4: 7}.get(function)
        if n_params is None:
            raise ValueError(f"unknown parametric curve type {function}")
        if len(data) < 12 + 4 * n_params:
            raise ValueError(f"truncated parametric curve type {function}")
        p = _s15f16(data, n_params, 12) + (0.0,) * (7 - n_params)
        g, a, b, c, d, e, f = p
        if not g > 0:
            raise ValueError(f"parametric curve type {function} has gamma {g:g}; it must be above 0")
        if function in (1, 2) and a == 0:
            raise ValueError(f"parametric curve type {function} has a = 0 (its threshold -b/a divides by zero)")

        def parametric(x: np.ndarray) -> np.ndarray:
            x = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)
            if function == 0:
                return x**g
            if function == 1:  # Y = (aX + b)^g for X >= -b/a, else 0
                return np.where(x >= -b / a, np.clip(a * x + b, 0.0, None) ** g, 0.0)
            if function == 2:  # Y = (aX + b)^g + c for X >= -b/a, else c
                return np.where(x >= -b / a, np.clip(a * x + b, 0.0, None) ** g + c, c)
            if function == 3:  # Y = (aX + b)^g for X >= d, else cX
                return np.where(x >= d, np.clip(a * x + b, 0.0, None) ** g, c * x)
            return np.where(x >= d, np.clip(a * x + b, 0.0, None) ** g + e, c * x + f)

        return parametric, f"parametric curve type {function}, gamma {g:.4g}"
    raise ValueError(f"unsupported tone curve type {kind!r}")


def _checked_curve(data: bytes) -> tuple[Curve, str]:
    """:func:`_icc_curve`, refused with ``ValueError`` unless it is a usable decoding curve."""
    curve, text = _icc_curve(data)
    points = np.linspace(0.0, 1.0, CURVE_CHECK_SAMPLES)
    with np.errstate(all="ignore"):
        values = np.asarray(curve(points), dtype=np.float64)
    if values.shape != points.shape or not np.isfinite(values).all():
        raise ValueError(f"its {text} is not finite on [0, 1]")
    if np.diff(values).min() < -CURVE_MONOTONIC_TOLERANCE:
        raise ValueError(f"its {text} falls somewhere on [0, 1] (a decoding curve must not)")
    if values[-1] - values[0] < CURVE_MIN_RISE:
        raise ValueError(f"its {text} is flat (it goes from {values[0]:.3g} to {values[-1]:.3g})")
    return curve, text


def _encoding_from_icc(icc: bytes) -> tuple[Encoding | None, str | None]:
    """The encoding an ICC profile describes, and why not when it is None."""
    try:
        tags = _icc_tags(icc)
    except (ValueError, struct.error) as error:
        return None, f"embedded ICC profile ignored: {error}"
    description = _text_tag(tags[b"desc"]) if b"desc" in tags else None
    label = f"'{description}'" if description else "(no description)"
    source = f"embedded ICC profile {label}"
    known = known_space_from_name(description)
    if known:
        return named_encoding(known, source), None
    data_space = icc[16:20]
    try:
        if data_space == b"GRAY" and b"kTRC" in tags:
            curve, text = _checked_curve(tags[b"kTRC"])
            return Encoding(f"ICC {label}", text, source, (0.0, 1.0, 0.0), (curve,) * 3), None
        if data_space == b"RGB " and all(t in tags for t in (b"rTRC", b"gTRC", b"bTRC", b"rXYZ", b"gXYZ", b"bXYZ")):
            parsed = [_checked_curve(tags[t]) for t in (b"rTRC", b"gTRC", b"bTRC")]
            # Colorant Y values (D50-adapted) are the luminance weights; they sum to 1.
            ys = [_s15f16(tags[t], 3)[1] for t in (b"rXYZ", b"gXYZ", b"bXYZ")]
            total = sum(ys)
            if not (math.isfinite(total) and total > 0 and min(ys) >= 0):
                raise ValueError("colorants have no luminance")
            texts = sorted({text for _, text in parsed})
            transfer = texts[0] if len(texts) == 1 else "per-channel tone curves: " + ", ".join(texts)
            encoding = Encoding(
                f"ICC {label}",
                transfer + " (from the profile)",
                source + " (not a known space: its own tone curves and colorants)",
                tuple(y / total for y in ys),
                tuple(curve for curve, _ in parsed),
            )
            return encoding, None
    except (ValueError, struct.error, ZeroDivisionError) as error:
        return None, f"embedded ICC profile {label} not usable ({error})"
    return None, f"embedded ICC profile {label} is not a known space nor a matrix/TRC profile"


def detect_encoding(
    *,
    icc: bytes | None = None,
    png_srgb: bool = False,
    png_gamma: float | None = None,
    exif_colour_space: int | None = None,
    interop_index: str | None = None,
    xmp_icc_name: str | None = None,
) -> Encoding:
    """The encoding of an 8- or 16-bit file from what its headers say (module docstring, steps 1–4).

    Parameters
    ----------
    icc : bytes or None
        Embedded ICC profile.
    png_srgb : bool
        The PNG has an ``sRGB`` chunk.
    png_gamma : float or None
        The PNG ``gAMA`` value (the encoding exponent, e.g. 0.45455).
    exif_colour_space : int or None
        EXIF ``ColorSpace`` (1 sRGB, 0xFFFF uncalibrated).
    interop_index : str or None
        EXIF ``InteroperabilityIndex`` ("R98" sRGB, "R03" Adobe RGB).
    xmp_icc_name : str or None
        XMP ``photoshop:ICCProfile``: the profile name an editor recorded.

    Returns
    -------
    Encoding
        ``assumed`` is True when nothing usable was found (sRGB is assumed).
    """
    notes: list[str] = []
    encoding = None
    if icc:
        encoding, why_not = _encoding_from_icc(icc)
        if why_not:
            notes.append(why_not)
        if (
            encoding is not None
            and xmp_icc_name
            and known_space_from_name(xmp_icc_name) != known_space_from_name(encoding.colour_space)
        ):
            notes.append(f"XMP photoshop:ICCProfile names '{xmp_icc_name}', but the embedded profile wins")
    if encoding is None and png_srgb:
        encoding = named_encoding("sRGB", "PNG sRGB chunk")
    if encoding is None and png_gamma is not None and png_gamma > 0:
        exponent = 1.0 / png_gamma
        encoding = Encoding(
            "PNG gAMA",
            f"gamma {exponent:.4g}",
            f"PNG gAMA chunk {png_gamma:g} (primaries assumed sRGB)",
            luminance_weights("sRGB"),
            (_gamma_curve(exponent),) * 3,
        )
    if encoding is None and exif_colour_space == 1:
        encoding = named_encoding("sRGB", "EXIF ColorSpace 1 (sRGB)")
    if encoding is None and interop_index and interop_index.strip("\x00 ").upper() == "R03":
        encoding = named_encoding("Adobe RGB (1998)", "EXIF InteropIndex R03 (DCF option file)")
    if encoding is None and known_space_from_name(xmp_icc_name):
        encoding = named_encoding(
            known_space_from_name(xmp_icc_name), f"XMP photoshop:ICCProfile '{xmp_icc_name}' (no embedded profile)"
        )
    if encoding is None:
        if exif_colour_space == 0xFFFF:
            reason = "EXIF ColorSpace says Uncalibrated and the file names no profile"
        elif icc:
            reason = "the embedded ICC profile could not be used"
        else:
            reason = "the file states no colour space"
        encoding = named_encoding("sRGB", reason, assumed=True)
    for note in notes:
        encoding = encoding.with_note(note)
    return encoding


def srgb_display_lut() -> np.ndarray:
    """uint8 sRGB code of every linear 16-bit value (index ``round(v · 65535)``): shape (65536,)."""
    linear = np.arange(65536, dtype=np.float64) / 65535.0
    table = np.round(np.clip(srgb_encode(linear), 0.0, 1.0) * 255.0).astype(np.uint8)
    table.setflags(write=False)
    return table
