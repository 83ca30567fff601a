"""A small table of common camera bodies: sensor width and native image width.

The loader needs the sensor's width in mm to turn a circle of confusion into
pixels (design.md §4: ``c_px = c · width_px / sensor_width_mm``). EXIF rarely
states it. Its ``FocalPlaneXResolution`` tag describes the camera's native
frame, so it is wrong for every downscaled copy of a photo; a table keyed by
the EXIF ``Model`` string is the reliable source for the bodies it lists.

Values are the makers' published "approx. W × H mm" sensor sizes and the
largest image width each body records. Phones are left out on purpose: one
model string covers several camera modules (wide, ultra-wide, tele) with
different sensors, and phones write a per-module ``FocalLengthIn35mmFilm``,
which the 35 mm-equivalent rule in :mod:`bokehfit.io.exif` uses instead.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

__all__ = ["CameraSpec", "CAMERAS", "lookup_camera", "normalise_model"]


@dataclass(frozen=True)
class CameraSpec:
    """One camera body.

    Attributes
    ----------
    name : str
        Name for people, e.g. ``"Sony A7 III (ILCE-7M3)"``.
    sensor_width_mm : float
        Width of the sensor's long side in mm.
    width_px : int
        Width of the body's full-resolution image in pixels (long side).
    """

    name: str
    sensor_width_mm: float
    width_px: int

    @property
    def pixel_pitch_um(self) -> float:
        """Photosite pitch in µm (sensor width over native pixel width)."""
        return self.sensor_width_mm / self.width_px * 1000.0


def normalise_model(model: str) -> str:
    """``model`` without NULs, case or repeated spaces: the table's key form."""
    return re.sub(r"\s+", " ", model.replace("\x00", " ")).strip().lower()


# EXIF Model string -> (name, sensor width mm, native width px).
_TABLE = {
    # Canon: full frame
    "Canon EOS 5D Mark II": ("Canon EOS 5D Mark II", 36.0, 5616),
    "Canon EOS 5D Mark III": ("Canon EOS 5D Mark III", 36.0, 5760),
    "Canon EOS 5D Mark IV": ("Canon EOS 5D Mark IV", 36.0, 6720),
    "Canon EOS 6D": ("Canon EOS 6D", 35.8, 5472),
    "Canon EOS 6D Mark II": ("Canon EOS 6D Mark II", 35.9, 6240),
    "Canon EOS R5": ("Canon EOS R5", 36.0, 8192),
    "Canon EOS R6": ("Canon EOS R6", 35.9, 5472),
    "Canon EOS R": ("Canon EOS R", 36.0, 6720),
    # Canon: APS-C (1.6x)
    "Canon EOS 90D": ("Canon EOS 90D", 22.3, 6960),
    "Canon EOS 80D": ("Canon EOS 80D", 22.3, 6000),
    "Canon EOS 7D Mark II": ("Canon EOS 7D Mark II", 22.4, 5472),
    "Canon EOS M50": ("Canon EOS M50", 22.3, 6000),
    # Nikon: full frame
    "NIKON D750": ("Nikon D750", 35.9, 6016),
    "NIKON D850": ("Nikon D850", 35.9, 8256),
    "NIKON D810": ("Nikon D810", 35.9, 7360),
    "NIKON Z 6": ("Nikon Z 6", 35.9, 6048),
    "NIKON Z 7": ("Nikon Z 7", 35.9, 8256),
    "NIKON Z 6_2": ("Nikon Z 6II", 35.9, 6048),
    # Nikon: DX
    "NIKON D7500": ("Nikon D7500", 23.5, 5568),
    "NIKON D5600": ("Nikon D5600", 23.5, 6000),
    # Sony: full frame
    "ILCE-7M2": ("Sony A7 II (ILCE-7M2)", 35.8, 6000),
    "ILCE-7M3": ("Sony A7 III (ILCE-7M3)", 35.6, 6000),
    "ILCE-7M4": ("Sony A7 IV (ILCE-7M4)", 35.9, 7008),
    "ILCE-7RM3": ("Sony A7R III (ILCE-7RM3)", 35.9, 7952),
    "ILCE-7RM4": ("Sony A7R IV (ILCE-7RM4)", 35.7, 9504),
    "ILCE-7SM3": ("Sony A7S III (ILCE-7SM3)", 35.6, 4240),
    # Sony: APS-C
    "ILCE-6000": ("Sony A6000 (ILCE-6000)", 23.5, 6000),
    "ILCE-6400": ("Sony A6400 (ILCE-6400)", 23.5, 6000),
    "ILCE-6600": ("Sony A6600 (ILCE-6600)", 23.5, 6000),
    # Fujifilm: APS-C
    "X-T3": ("Fujifilm X-T3", 23.5, 6240),
    "X-T4": ("Fujifilm X-T4", 23.5, 6240),
    "X-T30": ("Fujifilm X-T30", 23.5, 6240),
    "X-H2": ("Fujifilm X-H2", 23.5, 7728),
    # Olympus / OM System: Four Thirds
    "E-M1MarkII": ("Olympus OM-D E-M1 Mark II", 17.4, 5184),
    "E-M5MarkIII": ("Olympus OM-D E-M5 Mark III", 17.4, 5184),
    # Panasonic
    "DC-GH5": ("Panasonic Lumix GH5", 17.3, 5184),
    "DC-S5": ("Panasonic Lumix S5", 35.6, 6000),
    # Leica
    "LEICA Q2": ("Leica Q2", 36.0, 8368),
}

#: Camera bodies by normalised EXIF ``Model`` (see :func:`normalise_model`).
CAMERAS: dict[str, CameraSpec] = {normalise_model(model): CameraSpec(*spec) for model, spec in _TABLE.items()}


def lookup_camera(model: str | None, make: str | None = None) -> CameraSpec | None:
    """The table's entry for an EXIF ``Model`` (and optional ``Make``), or None.

    Parameters
    ----------
    model : str or None
        The EXIF ``Model`` tag; NULs, case and spacing are ignored.
    make : str or None
        The EXIF ``Make`` tag. Some writers put the make in front of the
        model; a model that is only found without that prefix still matches.

    Examples
    --------
    >>> lookup_camera("Canon EOS 6D\\x00").sensor_width_mm
    35.8
    """
    if not model:
        return None
    key = normalise_model(model)
    if key in CAMERAS:
        return CAMERAS[key]
    if make:
        prefix = normalise_model(make).split(" ")[0]
        if prefix and key.startswith(prefix + " "):
            return CAMERAS.get(key[len(prefix) + 1 :])
        return CAMERAS.get(normalise_model(f"{prefix} {model}"))
    return None
