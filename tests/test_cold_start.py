"""A fresh process pays only for what it uses (issue 14): imports on first use, no GPU for a small kernel.

colour-science pulls in matplotlib (about a second to import); the known colour
spaces' curves are written from their standards in ``bokehfit.io.colour`` and
held here to colour-science's own within ``CURVE_ATOL``. ``compare`` draws its
matched kernel by the cheapest method, a GPU's start-up included, so a photo of
usual discs starts no GPU. Each process check runs ``python -c`` in a fresh
interpreter and reads ``sys.modules`` at its end.
"""

from __future__ import annotations

import json
import subprocess
import sys

import cv2
import numpy as np
import pytest

from bokehfit.apertures import make_aperture
from bokehfit.io.colour import KNOWN_SPACES, colour_science, luminance_weights, srgb_display_lut, srgb_encode
from bokehfit.synthetic import SyntheticDisc, encode_srgb8, render_discs

#: The curves and weights against colour-science: the same formulas and constants, so only
#: float64 rounding differs (a few 1e-16 seen).
CURVE_ATOL = 1e-12
#: Modules whose import the compare pipeline must not pay for: colour-science (and the
#: matplotlib it imports) and the GPU's libraries (WebGPU, OpenGL).
HEAVY = ("colour", "matplotlib", "wgpu", "moderngl")


def _fresh_process(code: str) -> dict:
    """Run ``code`` in a fresh interpreter; it prints one JSON line last, which is returned."""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def _loaded(names) -> str:
    return f"[m for m in {list(names)!r} if m in sys.modules]"


def test_importing_compare_imports_nothing_heavy():
    found = _fresh_process(f"import json, sys; import bokehfit.compare; print(json.dumps({_loaded(HEAVY)}))")
    assert found == []


def test_compare_on_usual_discs_starts_no_gpu_and_no_colour_science(tmp_path):
    hexagon = make_aperture("hexagon", 15.0)
    discs = [SyntheticDisc((70.0 + 110.0 * i, 90.0), 48.0, hexagon, brightness=0.7) for i in range(3)]
    linear = render_discs(400, 180, discs, background=0.03, noise_sigma=0.002, seed=3)
    tint = np.array([1.0, 0.8, 0.55])  # a warm light: an RGB photo, not grey
    photo = tmp_path / "warm.jpg"
    cv2.imwrite(str(photo), encode_srgb8(linear[..., None] * tint)[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, 92])
    code = (
        "import json, sys\n"
        "from bokehfit.compare import compare_photo\n"
        f"c = compare_photo({str(photo)!r})\n"
        f"print(json.dumps({{'heavy': {_loaded(HEAVY)}, 'kernel': c.to_json('')['kernel'], 'device': c.device}}))"
    )
    found = _fresh_process(code)
    assert found["kernel"]["method"] == "exact" and found["kernel"]["samples"] is None
    assert found["device"] == {"adapter": None, "backend": None}
    assert found["heavy"] == []


@pytest.mark.parametrize("space", list(KNOWN_SPACES))
def test_known_curves_and_weights_match_colour_science(space):
    from bokehfit.io.colour import named_encoding

    model = colour_science().RGB_COLOURSPACES[space]
    encoding = named_encoding(space, "test")
    dense = np.linspace(0.0, 1.0, 100_001)
    for codes in (dense, np.arange(256) / 255.0, np.arange(65536) / 65535.0):
        np.testing.assert_allclose(encoding.curves[1](codes), model.cctf_decoding(codes), rtol=0, atol=CURVE_ATOL)
    np.testing.assert_allclose(luminance_weights(space), np.asarray(model.matrix_RGB_to_XYZ)[1], rtol=0, atol=CURVE_ATOL)


def test_srgb_encoding_and_display_table_match_colour_science():
    colour = colour_science()
    linear = np.linspace(0.0, 1.0, 100_001)
    np.testing.assert_allclose(srgb_encode(linear), colour.cctf_encoding(linear, function="sRGB"), rtol=0, atol=CURVE_ATOL)
    reference = colour.cctf_encoding(np.arange(65536) / 65535.0, function="sRGB")
    expected = np.round(np.clip(reference, 0.0, 1.0) * 255.0).astype(np.uint8)
    np.testing.assert_array_equal(srgb_display_lut(), expected)
