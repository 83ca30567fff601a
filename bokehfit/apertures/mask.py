"""The custom ``mask`` aperture of design.md §3b: a tabulated transmission image.

A :class:`MaskTable` is a greyscale image of transmission in [0, 1] centred on
the optical axis. Its pixels are square cells of side ``cell``, chosen so that
the transmitted area Σ t·cell² is 1 (the unit-area convention of design.md §3).
Row 0 of the image is the top (y up in the aperture frame, design.md §2).

The sampler follows pbrt-v4's ``PiecewiseConstant2D``: ``u[..., 1]`` picks a
row from the marginal CDF of the row sums, ``u[..., 0]`` a column from that
row's conditional CDF, and the position inside the chosen cell is the
fractional position of ``u`` between the two CDF values, so the map is
continuous inside cells and stratified ``u`` stays stratified. The density is
the transmission itself (:func:`mask_pdf`), and :func:`invert_mask_sample` maps
a point back to its ``u``. The WGSL twin ``sample_mask`` in
``shaders/apertures.wgsl`` reads the same float32 CDFs (:meth:`MaskTable.gpu_table`)
with the same binary search, so the NumPy sampler uses the float32 CDFs too:
the same ``u`` picks the same cell on both.

References
----------
M. Pharr, W. Jakob, G. Humphreys, *Physically Based Rendering*, 4th ed.,
§A.5.6 (``PiecewiseConstant2D``).
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from bokehfit.errors import InputError

__all__ = ["MAX_MASK_SIDE", "MaskTable", "decode_mask", "invert_mask_sample", "load_mask", "mask_pdf", "sample_mask"]

#: Largest mask image accepted, pixels a side (the CDF tables then hold about 1 M floats).
MAX_MASK_SIDE = 1024


@dataclass(frozen=True, eq=False)
class MaskTable:
    """A validated transmission image at unit transmitted area, with its sampling tables.

    Build it with :meth:`from_array` or :func:`load_mask`. Two tables are equal
    (and hash alike) when their transmission images are equal (:attr:`digest`).

    Attributes
    ----------
    transmission : ndarray of shape (H, W), float64
        Transmission in [0, 1]; row 0 is the top. Read-only.
    cell : float
        Side of one cell in unit-area units: 1/√(Σ t).
    marginal : ndarray of shape (H + 1,), float32
        CDF over the rows, bottom row first (y up).
    conditional : ndarray of shape (H, W + 1), float32
        CDF over the columns of each row, bottom row first.
    digest : str
        SHA-256 of the transmission image and its shape.
    """

    transmission: np.ndarray
    cell: float
    marginal: np.ndarray = field(repr=False)
    conditional: np.ndarray = field(repr=False)
    digest: str

    @classmethod
    def from_array(cls, image, name: str = "mask") -> MaskTable:
        """A table from a 2-D array of transmission in [0, 1] (row 0 the top).

        Raises InputError naming ``name`` for anything else: not 2-D, larger
        than :data:`MAX_MASK_SIDE` a side, non-finite, outside [0, 1], or no
        transmission at all.
        """
        try:
            array = np.asarray(image, dtype=np.float64)
        except (TypeError, ValueError):
            raise InputError(f"{name} must be a 2-D array of transmission in [0, 1] (got {type(image).__name__})") from None
        if array.ndim != 2 or min(array.shape) < 1:
            raise InputError(f"{name} must be a 2-D greyscale image of transmission in [0, 1] (got shape {array.shape})")
        if max(array.shape) > MAX_MASK_SIDE:
            raise InputError(f"{name} must be at most {MAX_MASK_SIDE}×{MAX_MASK_SIDE} pixels (got {array.shape[1]}×{array.shape[0]})")
        if not np.all(np.isfinite(array)):
            raise InputError(f"{name} must hold finite transmission values (got NaN or infinity)")
        if array.min() < 0.0 or array.max() > 1.0:
            raise InputError(f"{name} transmission must lie in [0, 1] (got {array.min():g} to {array.max():g})")
        total = float(array.sum())
        if not total > 0.0:
            raise InputError(f"{name} must transmit some light (got an all-black image)")
        array = array.copy()
        array.flags.writeable = False
        rows = array[::-1]  # bottom row first: y up
        row_sums = rows.sum(axis=1)
        marginal = _cdf(row_sums)
        conditional = np.stack([_cdf(row) for row in rows])
        digest = hashlib.sha256(repr(array.shape).encode() + array.tobytes()).hexdigest()
        return cls(array, 1.0 / math.sqrt(total), marginal, conditional, digest)

    def __eq__(self, other) -> bool:
        return isinstance(other, MaskTable) and other.digest == self.digest

    def __hash__(self) -> int:
        return hash(self.digest)

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W): rows and columns of the image."""
        return self.transmission.shape

    @property
    def half_size(self) -> tuple[float, float]:
        """Half the width and half the height of the image in unit-area units."""
        h, w = self.shape
        return 0.5 * w * self.cell, 0.5 * h * self.cell

    def extent(self) -> float:
        """Largest distance from the centre of a transmitting cell's corner (unit-area units)."""
        rows, cols = np.nonzero(self.transmission)
        h, w = self.shape
        xs = (np.concatenate([cols, cols + 1]) - 0.5 * w) * self.cell
        ys = (0.5 * h - np.concatenate([rows, rows + 1])) * self.cell
        return float(math.hypot(np.max(np.abs(xs)), np.max(np.abs(ys))))

    def gpu_table(self) -> np.ndarray:
        """The float32 storage buffer of WGSL ``sample_mask``: the marginal CDF, then each row's conditional CDF."""
        return np.concatenate([self.marginal, self.conditional.ravel()]).astype(np.float32)

    def describe(self) -> str:
        h, w = self.shape
        return f"mask {w}×{h} {self.digest[:8]}"


def _cdf(weights: np.ndarray) -> np.ndarray:
    """Float32 CDF of non-negative ``weights`` (n + 1 values from 0 to 1); uniform where they sum to 0."""
    weights = np.asarray(weights, dtype=np.float64)
    total = weights.sum()
    if not total > 0.0:
        weights, total = np.ones_like(weights), float(len(weights))
    cdf = np.concatenate([[0.0], np.cumsum(weights) / total]).astype(np.float32)
    cdf[-1] = 1.0
    return np.maximum.accumulate(cdf)


def load_mask(path, name: str = "mask") -> MaskTable:
    """A :class:`MaskTable` from an image file (PNG): greyscale, or the luminance of RGB; 8 or 16 bits.

    Pixel values are scaled by the bit depth's maximum (255 or 65535) to
    transmission in [0, 1]; an alpha channel is ignored. RGB becomes luminance
    with the ITU-R 601-2 weights of Pillow's ``convert("L")``.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{name} must be an image file (PNG); {str(path)!r} does not exist")
    return _read_image(path, repr(str(path)), name)


def decode_mask(data: bytes, name: str = "mask", source: str = "the upload") -> MaskTable:
    """A :class:`MaskTable` from the bytes of an image file (PNG), read as :func:`load_mask` reads a file.

    ``source`` names where the bytes came from in error messages.
    """
    import io

    if not isinstance(data, (bytes, bytearray)) or not data:
        raise InputError(f"{name} must be the bytes of an image file (PNG) (got nothing from {source})")
    return _read_image(io.BytesIO(data), source, name)


def _read_image(source, where: str, name: str) -> MaskTable:
    """The transmission table of the image file ``source`` (a path or a binary file object).

    The size is checked before the pixels are decoded, so that a small file
    claiming a huge image costs nothing.
    """
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(source) as image:
            width, height = image.size
            if max(width, height) > MAX_MASK_SIDE:
                raise InputError(f"{name} must be at most {MAX_MASK_SIDE}×{MAX_MASK_SIDE} pixels (got {width}×{height} in {where})")
            image.load()
            mode = image.mode
            if mode in ("I;16", "I;16B", "I;16L", "I"):
                array = np.asarray(image, dtype=np.float64) / 65535.0
            elif mode in ("L", "LA", "P", "RGB", "RGBA", "1"):
                array = np.asarray(image.convert("L"), dtype=np.float64) / 255.0
            else:
                raise InputError(f"{name} must be a greyscale or RGB image of 8 or 16 bits (got mode {mode!r} in {where})")
    except (UnidentifiedImageError, OSError) as error:
        reason = "not an image format Pillow reads" if isinstance(error, UnidentifiedImageError) else str(error)
        raise InputError(f"{name} must be a readable image file (PNG) (got {where}: {reason})") from None
    return MaskTable.from_array(array, name)


def _sample_1d(cdf: np.ndarray, u: np.ndarray, row: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(cell index, position in [0, 1) inside it) of ``u`` under a piecewise-constant CDF.

    The index is the last i with cdf[i] ≤ u, so zero-width cells are never
    picked. With ``row``, ``cdf`` holds one CDF per row and each ``u`` uses its
    row's: one search over the keys row + cdf (exact in float64).
    """
    n = cdf.shape[-1] - 1
    u = u.astype(np.float64)
    if row is None:
        index = np.clip(np.searchsorted(cdf, u, side="right") - 1, 0, n - 1)
        low, high = cdf[index], cdf[index + 1]
    else:
        keys = (np.arange(cdf.shape[0])[:, None] + cdf.astype(np.float64)).ravel()
        index = np.clip(np.searchsorted(keys, row + u, side="right") - 1 - row * (n + 1), 0, n - 1)
        low, high = cdf[row, index], cdf[row, index + 1]
    low, high = low.astype(np.float32), high.astype(np.float32)
    width = high - low
    safe = np.where(width > 0.0, width, np.float32(1.0))
    fraction = np.where(width > 0.0, (u.astype(np.float32) - low) / safe, np.float32(0.0))
    return index, fraction.astype(np.float32)


def sample_mask(u: np.ndarray, table: MaskTable) -> np.ndarray:
    """Points of the unit-area mask at angle 0 with density :func:`mask_pdf`, from ``u`` in [0, 1)².

    ``u[..., 1]`` picks the row (marginal CDF, bottom first), ``u[..., 0]``
    the column in it (conditional CDF); the rest of each places the point
    inside the cell. Arithmetic in float32, as the WGSL twin.
    """
    u = np.asarray(u, dtype=np.float32)
    row, dy = _sample_1d(table.marginal, u[..., 1])
    col, dx = _sample_1d(table.conditional, u[..., 0], row)
    h, w = table.shape
    cell = np.float32(table.cell)
    x = (col.astype(np.float32) + dx - np.float32(0.5 * w)) * cell
    y = (row.astype(np.float32) + dy - np.float32(0.5 * h)) * cell
    return np.stack([x, y], axis=-1).astype(np.float64)


def _cell_of(p: np.ndarray, table: MaskTable) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(row from the bottom, column, inside, fractional x, fractional y) of points ``p``."""
    p = np.asarray(p, dtype=np.float64)
    h, w = table.shape
    gx = p[..., 0] / table.cell + 0.5 * w
    gy = p[..., 1] / table.cell + 0.5 * h
    inside = (gx >= 0.0) & (gx < w) & (gy >= 0.0) & (gy < h)
    col = np.clip(np.floor(gx), 0, w - 1).astype(np.int64)
    row = np.clip(np.floor(gy), 0, h - 1).astype(np.int64)
    return row, col, inside, gx - col, gy - row


def mask_pdf(p: np.ndarray, table: MaskTable) -> np.ndarray:
    """Density of :func:`sample_mask` at ``p``: the transmission there (the transmitted area is 1), 0 outside."""
    row, col, inside, _, _ = _cell_of(p, table)
    h = table.shape[0]
    return np.where(inside, table.transmission[h - 1 - row, col], 0.0)


def invert_mask_sample(p: np.ndarray, table: MaskTable) -> np.ndarray:
    """The ``u`` that :func:`sample_mask` maps to ``p`` (p inside a transmitting cell)."""
    row, col, _, fx, fy = _cell_of(p, table)
    marginal = table.marginal.astype(np.float64)
    conditional = table.conditional.astype(np.float64)
    u1 = marginal[row] + fy * (marginal[row + 1] - marginal[row])
    u0 = conditional[row, col] + fx * (conditional[row, col + 1] - conditional[row, col])
    return np.stack([u0, u1], axis=-1)
