"""EXIF and XMP metadata: camera, lens, aperture, focus distance, sensor width and its source."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from photo_factory import exif_for, make_exif, make_xmp, reference_photo, write_jpeg, write_png

from bokehfit.io import Exif, lensfun_camera, load_photo, sensor_width
from bokehfit.io.exif import PLAUSIBLE_SENSOR_WIDTH_MM, build_exif, camera_name, read_exif_tags, xmp_property


def exif_of(blob: bytes | None = None, xmp: bytes | None = None, width_px: int = 6000, height_px: int = 4000) -> Exif:
    return build_exif(read_exif_tags(blob), xmp, width_px=width_px, height_px=height_px)


def jpeg_with(tmp_path, blob=None, xmp=None, shape=(40, 64, 3)):
    return load_photo(write_jpeg(tmp_path / "m.jpg", np.full(shape, 90, np.uint8), exif=blob, xmp=xmp)).exif


# --------------------------------------------------------------------------------------
# Camera, lens, aperture, focal length
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "make,model,expected",
    [
        ("Canon\x00", "Canon EOS 6D\x00", "Canon EOS 6D"),
        ("NIKON CORPORATION", "NIKON D750", "NIKON D750"),
        ("SONY", "ILCE-7M3", "SONY ILCE-7M3"),
        ("OLYMPUS IMAGING CORP.  ", "E-M5", "OLYMPUS E-M5"),
        ("FUJIFILM", "X-T3", "FUJIFILM X-T3"),
        ("Apple", "iPhone 13", "Apple iPhone 13"),
        (None, "Model Only", "Model Only"),
        ("Make Only", None, "Make Only"),
        ("\x00\x00", "  ", None),
    ],
)
def test_camera_name(make, model, expected):
    assert camera_name(make, model) == expected


def test_fields_from_a_jpeg(tmp_path):
    blob = exif_for(
        make="Canon\x00",
        model="Canon EOS 80D\x00",
        fnumber=2.8,
        focal=(50, 1),
        focal35=80,
        lens="EF50mm f/1.8 STM",
        subject_distance=(250, 100),
    )
    exif = jpeg_with(tmp_path, blob)
    assert exif.camera == "Canon EOS 80D" and exif.lens == "EF50mm f/1.8 STM"
    assert exif.fnumber == pytest.approx(2.8) and exif.focal_length_mm == 50.0 and exif.focal_length_35mm == 80.0
    assert exif.focus_distance_m == pytest.approx(2.5)
    # lensfun: crop factor 1.6 on the diagonal of a 3:2 sensor (Canon states 22.3 × 14.9 mm)
    assert exif.sensor_width_mm == pytest.approx(22.3, abs=0.15)
    assert exif.sensor_width_source.startswith("lensfun database (Canon EOS 80D, crop factor")


def test_fields_from_a_png_exif_chunk(tmp_path):
    blob = exif_for(make="NIKON CORPORATION", model="NIKON Z 6_2", fnumber=4.0)
    exif = load_photo(write_png(tmp_path / "m.png", np.zeros((20, 20, 3), np.uint8), exif=blob)).exif
    assert exif.camera == "NIKON Z 6_2" and exif.fnumber == 4.0
    assert exif.sensor_width_source.startswith("lensfun database (Nikon Z 6_2,")
    assert exif.sensor_width_mm == pytest.approx(35.9, abs=0.15)


def test_fnumber_from_apex_aperture_value():
    av = 2 * math.log2(2.8)
    assert exif_of(make_exif(exif={0x9202: float(av)})).fnumber == 2.8


def test_lens_from_xmp_when_exif_has_none():
    assert exif_of(None, make_xmp({"aux:Lens": "EF85mm f/1.8 USM"})).lens == "EF85mm f/1.8 USM"
    both = exif_of(exif_for(lens="From EXIF"), make_xmp({"aux:Lens": "From XMP"}))
    assert both.lens == "From EXIF"


@pytest.mark.parametrize("value", [0, 9, 65535])
def test_invalid_orientation_is_1(value):
    assert exif_of(exif_for(orientation=value)).orientation == 1


def test_no_exif_at_all():
    assert exif_of(None) == Exif()


@pytest.mark.parametrize(
    "blob",
    [b"Exif\x00\x00", b"Exif\x00\x00II*\x00\xff\xff\xff\x7f", b"Exif\x00\x00MM\x00*\x00\x00\x00\x08\x00\x05", b"junk"],
)
def test_damaged_exif_is_ignored_without_warnings(blob):
    # pytest turns warnings into errors: Pillow's warnings on bad EXIF must not escape either.
    assert exif_of(blob) == Exif()


# --------------------------------------------------------------------------------------
# Focus distance
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "distance,expected",
    [((250, 100), 2.5), ((0, 1), None), ((0xFFFFFFFF, 1), None), ((1, 0), None), ((5, 1000), None), ((10**9, 1), None)],
)
def test_subject_distance(distance, expected):
    assert exif_of(exif_for(subject_distance=distance)).focus_distance_m == expected


@pytest.mark.parametrize("attributes", [False, True])
def test_xmp_approximate_focus_distance(attributes):
    xmp = make_xmp({"aux:ApproximateFocusDistance": "727/100"}, attributes=attributes)
    assert exif_of(None, xmp).focus_distance_m == pytest.approx(7.27)
    assert xmp_property(xmp, "aux:ApproximateFocusDistance") == "727/100"


def test_xmp_infinity_and_exif_first():
    assert exif_of(None, make_xmp({"aux:ApproximateFocusDistance": "4294967295/1"})).focus_distance_m is None
    both = exif_of(exif_for(subject_distance=(3, 1)), make_xmp({"aux:ApproximateFocusDistance": "727/100"}))
    assert both.focus_distance_m == 3.0


def test_xmp_in_a_jpeg(tmp_path):
    exif = jpeg_with(tmp_path, None, make_xmp({"aux:ApproximateFocusDistance": "1.5"}))
    assert exif.focus_distance_m == 1.5


# --------------------------------------------------------------------------------------
# Sensor width
# --------------------------------------------------------------------------------------


def test_lensfun_beats_a_downscaled_focal_plane_resolution():
    """Photo 01's trap: 2560 px wide with the native frame's 152 px/mm would say 16.8 mm."""
    width, source = sensor_width(
        make="Canon",
        model="Canon EOS 6D",
        focal_plane_x_resolution=152.0,
        focal_plane_unit=4,
        width_px=2560,
        height_px=1600,
    )
    assert width == pytest.approx(35.8, abs=0.1) and source.startswith("lensfun database (Canon EOS 6D,")
    naive, naive_source = sensor_width(
        focal_plane_x_resolution=152.0, focal_plane_unit=4, width_px=2560, height_px=1600
    )
    assert naive == pytest.approx(2560 / 152, abs=0.01) and "native pixel width" in naive_source


def test_lensfun_beats_35mm_equivalent():
    width, source = sensor_width(
        model="ILCE-6400", make="SONY", focal_length_mm=50, focal_length_35mm=50, width_px=6000, height_px=4000
    )
    assert width == pytest.approx(23.5, abs=0.15) and source.startswith("lensfun database")


def test_native_width_from_the_maker_note_fixes_the_focal_plane_resolution():
    """A file downscaled to 2000 px whose maker note gives the native 4752 px: 4752 px at 5315 px/inch."""
    width, source = sensor_width(
        focal_plane_x_resolution=4752000 / 894, focal_plane_unit=2, width_px=2000, height_px=1333, native_width_px=4752
    )
    assert width == pytest.approx(22.71, abs=0.01) and "native width 4752 px" in source


@pytest.mark.parametrize(
    "focal,focal35,width_px,height_px,expected",
    [
        (50.0, 75.0, 6000, 4000, 24.0),  # 3:2, crop 1.5: exactly 36 mm · f / f35
        (85.0, 85.0, 3000, 2000, 36.0),
        (5.1, 26.0, 4032, 3024, 43.2666 * 5.1 / 26 * 0.8),  # 4:3 phone: the long side is 4/5 of the diagonal
        (5.1, 26.0, 3024, 4032, 43.2666 * 5.1 / 26 * 0.8),  # stored portrait: still the long side
    ],
)
def test_35mm_equivalent(focal, focal35, width_px, height_px, expected):
    width, source = sensor_width(
        focal_length_mm=focal, focal_length_35mm=focal35, width_px=width_px, height_px=height_px
    )
    assert width == pytest.approx(expected, abs=0.01)
    assert source.startswith("35 mm-equivalent focal length")


def test_35mm_equivalent_beats_focal_plane():
    width, source = sensor_width(
        focal_length_mm=50.0,
        focal_length_35mm=75.0,
        focal_plane_x_resolution=100.0,
        focal_plane_unit=4,
        width_px=6000,
        height_px=4000,
    )
    assert width == 24.0 and "35 mm-equivalent" in source


@pytest.mark.parametrize(
    "resolution,unit,expected",
    [
        (2540.0, 2, 2000 / 2540 * 25.4),  # inch
        (2540.0, None, 2000 / 2540 * 25.4),  # the unit defaults to inch
        (1000.0, 3, 20.0),  # cm
        (100.0, 4, 20.0),  # mm
        (0.25, 5, 8.0),  # µm
        (10.0, 1, None),  # "no absolute unit"
    ],
)
def test_focal_plane_units(resolution, unit, expected):
    width, source = sensor_width(
        focal_plane_x_resolution=resolution, focal_plane_unit=unit, width_px=2000, height_px=1500
    )
    if expected is None:
        assert width is None and source is None
    else:
        assert width == pytest.approx(expected, abs=0.01) and source.startswith("focal-plane resolution")


@pytest.mark.parametrize("resolution", [152.0 * 20, 2000 / 70.0])
def test_implausible_focal_plane_width_is_refused(resolution):
    width, _ = sensor_width(focal_plane_x_resolution=resolution, focal_plane_unit=4, width_px=2000, height_px=1500)
    low, high = PLAUSIBLE_SENSOR_WIDTH_MM
    assert not low <= 2000 / resolution <= high
    assert width is None


def test_sensor_width_through_a_jpeg(tmp_path):
    plausible = jpeg_with(tmp_path, exif_for(fp_xres=4.0, fp_unit=4))  # 64 px / 4 px/mm = 16 mm
    assert plausible.sensor_width_mm == 16.0 and plausible.sensor_width_source.startswith("focal-plane resolution")
    implausible = jpeg_with(tmp_path, exif_for(fp_xres=152.0, fp_unit=4))  # 0.42 mm
    assert implausible.sensor_width_mm is None and implausible.sensor_width_source is None


# --------------------------------------------------------------------------------------
# Camera table, JSON
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "model,make,width",
    [
        ("Canon EOS 6D", "Canon", 35.8),
        ("Canon EOS 50D", "Canon", 22.3),
        ("NIKON D5300", "NIKON CORPORATION", 23.5),
        ("E-M1MarkII", "OLYMPUS CORPORATION", 17.3),
        ("X-T3", "FUJIFILM", 23.5),
        ("DC-GH5", "Panasonic", 17.3),
    ],
)
def test_lensfun_sensor_widths(model, make, width):
    """lensfun's crop factors give the makers' published widths within 0.15 mm (its factors have 3-4 digits)."""
    assert lensfun_camera(make, model) is not None
    got, source = sensor_width(make=make, model=model, width_px=6000, height_px=4000)
    assert got == pytest.approx(width, abs=0.15) and source.startswith("lensfun database")


def test_unknown_camera_is_not_in_lensfun():
    assert lensfun_camera("X", "Unknown 1") is None
    assert sensor_width(make="X", model="Unknown 1", width_px=6000, height_px=4000) == (None, None)


def test_to_json_is_plain():
    exif = exif_of(exif_for(make="SONY", model="ILCE-7M3", fnumber=1.4, focal=(35, 1), orientation=6))
    document = exif.to_json()
    assert list(document) == list(Exif.__dataclass_fields__)
    assert json.loads(json.dumps(document)) == document
    assert document["sensor_width_source"].startswith("lensfun database (ILCE-7M3,") and document["orientation"] == 6
    assert document["sources"]["fnumber"] == "EXIF FNumber" and document["ignored"] == []
    assert all(isinstance(v, (str, int, float, dict, list, type(None))) for v in document.values())


# --------------------------------------------------------------------------------------
# Reference photo 01 (BOKEHFIT_REFERENCE_DIR)
# --------------------------------------------------------------------------------------


def test_reference_photo_01_exif():
    exif = load_photo(reference_photo("01_water-glints_canon6d_ef85.jpg")).exif
    assert exif.camera == "Canon EOS 6D" and exif.lens == "EF85mm f/1.8 USM"
    assert exif.fnumber == 1.8 and exif.focal_length_mm == 85.0 and exif.focal_length_35mm is None
    assert exif.sensor_width_mm == pytest.approx(35.8, abs=0.1)
    assert exif.sensor_width_source.startswith("lensfun database (Canon EOS 6D,")
    assert exif.focus_distance_m == pytest.approx(7.27)
    assert exif.orientation == 1
