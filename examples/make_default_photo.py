"""Render the default photo of ``bokehfit compare``: street lights through a hexagonal aperture.

The photo is synthetic, rendered by bokehfit itself (exact pixel coverage of
the aperture, a Gaussian edge blur, sensor noise, sRGB JPEG), so its answer is
known: an 85 mm lens at f/2 (equal-area) with a six-blade aperture turned by
15°, focused at 3 m on a full-frame (36 mm) sensor. Most lights are far away
(discs of 55.1 px), a few at 12 m (41.3 px); some discs overlap, two are
saturated and one is cut by the frame, as in real night photos.

Run from the repository root to regenerate ``examples/hexagon_85mm_f2.jpg``:

    python examples/make_default_photo.py
"""

from __future__ import annotations

import io
import math
from pathlib import Path

import cv2
import numpy as np
from PIL import Image

from bokehfit.apertures import make_aperture
from bokehfit.optics import coc_mm
from bokehfit.synthetic import SyntheticDisc, encode_srgb8, render_discs

WIDTH, HEIGHT = 1600, 1067
SENSOR_WIDTH_MM = 36.0
FOCAL_LENGTH_MM = 85.0
FSTOP = 2.0
FOCUS_DISTANCE_M = 3.0
APERTURE = make_aperture("hexagon", 15.0)
OUT = Path(__file__).with_name("hexagon_85mm_f2.jpg")


def disc_px(light_distance_m: float) -> float:
    coc = coc_mm(FSTOP, FOCAL_LENGTH_MM, FOCUS_DISTANCE_M, light_distance_m)
    return coc * WIDTH / SENSOR_WIDTH_MM


def main() -> None:
    rng = np.random.default_rng(2024)
    far, mid = disc_px(math.inf), disc_px(12.0)
    discs = []
    # Far lights on a loose grid, jittered; a few mid-distance ones between them.
    for row in range(5):
        for col in range(9):
            if rng.random() < 0.35:
                continue
            centre = (120 + col * 170 + rng.uniform(-25, 25), 140 + row * 190 + rng.uniform(-25, 25))
            distance = 12.0 if rng.random() < 0.2 else math.inf
            discs.append(SyntheticDisc(centre, far if math.isinf(distance) else mid, APERTURE,
                                       brightness=float(rng.uniform(0.25, 0.7))))
    discs.append(SyntheticDisc((700.0, 560.0), far, APERTURE, brightness=0.6))  # an overlapping pair
    discs.append(SyntheticDisc((735.0, 585.0), far, APERTURE, brightness=0.45))
    discs.append(SyntheticDisc((1585.0, 300.0), far, APERTURE, brightness=0.5))  # cut by the frame
    discs.append(SyntheticDisc((300.0, 980.0), far, APERTURE, brightness=2.5))  # saturated
    discs.append(SyntheticDisc((1300.0, 980.0), mid, APERTURE, brightness=2.0))
    # A dim, smoothly varying night background.
    texture = cv2.GaussianBlur(rng.normal(0.0, 1.0, (HEIGHT, WIDTH)).astype(np.float32), (0, 0), 60)
    background = 0.015 + 0.01 * texture / np.abs(texture).max() + np.linspace(0.0, 0.02, HEIGHT, dtype=np.float32)[:, None]
    luminance = render_discs(WIDTH, HEIGHT, discs, background=background, edge_blur_px=0.7, noise_sigma=0.003, seed=7)
    # Warm sodium-lamp colour: R > G > B, scaled so that the luminance is the rendered one.
    tint = np.array([1.25, 0.95, 0.55], dtype=np.float32)
    tint /= float(np.dot([0.2126, 0.7152, 0.0722], tint))
    rgb8 = encode_srgb8(np.clip(luminance[..., None] * tint, 0.0, 1.0))
    exif = Image.Exif()
    exif[271] = "bokehfit"  # Make
    exif[272] = "synthetic full-frame"  # Model
    sub = exif.get_ifd(0x8769)
    sub[33437] = FSTOP  # FNumber
    sub[37386] = FOCAL_LENGTH_MM  # FocalLength
    sub[37382] = FOCUS_DISTANCE_M  # SubjectDistance, m
    sub[41486] = WIDTH / SENSOR_WIDTH_MM  # FocalPlaneXResolution
    sub[41487] = WIDTH / SENSOR_WIDTH_MM
    sub[41488] = 4  # FocalPlaneResolutionUnit: mm
    sub[40962], sub[40963] = WIDTH, HEIGHT  # PixelXDimension, PixelYDimension
    buffer = io.BytesIO()
    Image.fromarray(rgb8).save(buffer, "JPEG", quality=92, exif=exif.tobytes())
    OUT.write_bytes(buffer.getvalue())
    print(f"wrote {OUT}: {len(discs)} lights, far discs {far:.2f} px, 12 m discs {mid:.2f} px")


if __name__ == "__main__":
    main()
