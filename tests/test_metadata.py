"""Camera metadata from exiv2 and lensfun, and the f-stop it gives (issue 13).

Maker-note focus distances (Canon, Nikon, Olympus; Sony, Fujifilm and Panasonic
files fall back on EXIF), sensor widths from the lensfun database, downscaled and
cropped files, absurd values ignored with the reason, and the f-stop printed as a
value or as the bound it is, beside EXIF's FNumber and the light distances it implies.
Files for other makers are made by writing their maker-note tags with exiv2.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import exiv2
import numpy as np
import pytest
from photo_factory import write_jpeg

from bokehfit.io import load_photo
from bokehfit.optics import FStop, Geometry, coc_mm, estimate_fstop, resolve_geometry

#: lensfun's crop factors have three or four digits: widths agree with the makers' to this (mm).
LENSFUN_WIDTH_TOL_MM = 0.15
#: Canon EOS 50D (photos 07, 08): Canon's published sensor width.
CANON_50D_WIDTH_MM = 22.3


def write_with_tags(path, tags: list[tuple[str, object]], shape=(40, 60, 3)):
    """A plain JPEG with these EXIF tags (maker notes included) written by exiv2, in order."""
    write_jpeg(path, np.full(shape, 90, np.uint8))
    image = exiv2.ImageFactory.open(str(path))
    image.readMetadata()
    data = image.exifData()
    for key, value in tags:
        data[key] = value
    image.writeMetadata()
    return path


def ratio(numerator: int, denominator: int = 1):
    return exiv2.URationalValue([(numerator, denominator)])


def save_with_metadata_of(source, target, pixels_rgb: np.ndarray) -> None:
    """``pixels_rgb`` as a JPEG carrying ``source``'s EXIF block (maker notes included) and XMP packet, byte for byte.

    Pillow copies the packets as they are: exiv2 refuses to write some real XMP packets
    (photo 01's) that bokehfit reads.
    """
    from PIL import Image

    with Image.open(source) as original:
        exif, xmp = original.info.get("exif", b""), original.info.get("xmp", b"")
    Image.fromarray(pixels_rgb).save(target, quality=92, exif=exif, xmp=xmp)


# --------------------------------------------------------------------------------------
# Reference photos with maker notes
# --------------------------------------------------------------------------------------


def test_07_focus_range_from_the_canon_maker_note(reference_photo):
    exif = load_photo(reference_photo("07_touch-the-light_canon-50d-ef100.jpg")).exif
    assert exif.focus_distance_range_m == (1.71, 2.06)
    assert exif.focus_distance_m == pytest.approx((1.71 + 2.06) / 2)
    assert exif.sources["focus_distance_m"].startswith("maker note CanonFi.FocusDistanceLower/Upper")
    assert exif.lens == "EF100mm f/2.8L Macro IS USM" and exif.sources["lens"] == "maker note Canon.LensModel"
    assert exif.native_width_px == 4752 and exif.sources["native_width_px"] == "maker note Canon.AFCanonImageWidth"
    assert exif.frame.startswith("downscaled ×0.421 from the camera's 4752 px")


@pytest.mark.parametrize("name", ["07_touch-the-light_canon-50d-ef100.jpg", "08_morning-dew_canon-50d-400mm.jpg"])
def test_canon_50d_photos_get_the_22_3_mm_sensor(reference_photo, name):
    """Photos downscaled to 2000 px with the native FocalPlaneXResolution gave 9.56 mm before."""
    photo = load_photo(reference_photo(name))
    exif = photo.exif
    assert exif.sensor_width_mm == pytest.approx(CANON_50D_WIDTH_MM, abs=LENSFUN_WIDTH_TOL_MM)
    assert exif.sensor_width_source.startswith("lensfun database (Canon EOS 50D,")
    geometry = resolve_geometry(photo)
    assert geometry.pixel_pitch_mm == pytest.approx(exif.sensor_width_mm / 2000)


def test_08_focus_distance(reference_photo):
    exif = load_photo(reference_photo("08_morning-dew_canon-50d-400mm.jpg")).exif
    assert exif.focus_distance_m == pytest.approx(1.87) and exif.sources["focus_distance_m"] == "EXIF SubjectDistance"
    assert exif.fnumber == 5.6 and exif.focal_length_mm == 400.0


@pytest.mark.parametrize(
    "name,width_mm",
    [("01_water-glints_canon6d_ef85.jpg", 35.8), ("06_christmas-lights_nikon-d5300.jpg", 23.5)],
)
def test_sensor_width_from_lensfun(reference_photo, name, width_mm):
    exif = load_photo(reference_photo(name)).exif
    assert exif.sensor_width_mm == pytest.approx(width_mm, abs=LENSFUN_WIDTH_TOL_MM)
    assert exif.sensor_width_source.startswith("lensfun database")
    assert "downscaled" in exif.frame and "cropped to 1.6:1" in exif.frame


# --------------------------------------------------------------------------------------
# Files made for each maker
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "make,model,tags,focus_m,source,width_mm",
    [
        ("Canon", "Canon EOS 50D",
         [("Exif.CanonFi.FocusDistanceUpper", exiv2.ShortValue(206)), ("Exif.CanonFi.FocusDistanceLower", exiv2.ShortValue(171))],
         1.885, "maker note CanonFi.FocusDistanceLower/Upper (middle of the range)", 22.3),
        ("NIKON CORPORATION", "NIKON D750", [("Exif.Nikon3.FocusDistance", ratio(250, 100))],
         2.5, "maker note Nikon3.FocusDistance", 35.9),
        ("OLYMPUS IMAGING CORP.", "E-M5", [("Exif.OlympusFi.FocusDistance", ratio(123, 100))],
         1.23, "maker note OlympusFi.FocusDistance", 17.3),
        ("OLYMPUS IMAGING CORP.", "E-M5", [("Exif.Olympus.FocusDistance", ratio(77, 100))],
         0.77, "maker note Olympus.FocusDistance", 17.3),
        # exiv2 decodes no focus distance from these makers' notes: EXIF SubjectDistance serves.
        ("SONY", "ILCE-7M3", [("Exif.Sony1.Quality", exiv2.ULongValue(0)), ("Exif.Photo.SubjectDistance", ratio(3))],
         3.0, "EXIF SubjectDistance", 35.6),
        ("FUJIFILM", "X-T3", [("Exif.Fujifilm.Quality", "NORMAL "), ("Exif.Photo.SubjectDistance", ratio(3))],
         3.0, "EXIF SubjectDistance", 23.5),
        ("Panasonic", "DC-GH5", [("Exif.Panasonic.Quality", exiv2.ShortValue(2)), ("Exif.Photo.SubjectDistance", ratio(3))],
         3.0, "EXIF SubjectDistance", 17.3),
    ],
)
def test_focus_distance_and_sensor_for_each_maker(tmp_path, make, model, tags, focus_m, source, width_mm):
    path = write_with_tags(tmp_path / "m.jpg", [("Exif.Image.Make", make), ("Exif.Image.Model", model)] + tags)
    exif = load_photo(path).exif
    assert exif.focus_distance_m == pytest.approx(focus_m) and exif.sources["focus_distance_m"] == source
    # lensfun rounds some crop factors (the A7 III is 1.0, so 36 mm for 35.6): 0.5 mm here.
    assert exif.sensor_width_mm == pytest.approx(width_mm, abs=0.5)
    assert exif.sensor_width_source.startswith("lensfun database")


def test_maker_note_comes_before_subject_distance(tmp_path):
    path = write_with_tags(tmp_path / "m.jpg", [
        ("Exif.Image.Make", "NIKON CORPORATION"), ("Exif.Image.Model", "NIKON D750"),
        ("Exif.Nikon3.FocusDistance", ratio(250, 100)), ("Exif.Photo.SubjectDistance", ratio(9)),
    ])
    assert load_photo(path).exif.focus_distance_m == 2.5


# --------------------------------------------------------------------------------------
# Downscaled and cropped files
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "name",
    ["01_water-glints_canon6d_ef85.jpg", "06_christmas-lights_nikon-d5300.jpg",
     "07_touch-the-light_canon-50d-ef100.jpg", "08_morning-dew_canon-50d-400mm.jpg"],
)
@pytest.mark.parametrize("variant", ["downscaled", "cropped"])
def test_downscaled_and_cropped_copies_keep_the_sensor_width(reference_photo, tmp_path, name, variant):
    source = reference_photo(name)
    original = load_photo(source)
    pixels = np.asarray(original.display)
    if variant == "downscaled":
        pixels = cv2.resize(pixels, None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA)
    else:
        side = min(pixels.shape[:2])
        pixels = np.ascontiguousarray(pixels[:side, :side])
    target = tmp_path / f"{variant}.jpg"
    save_with_metadata_of(source, target, pixels)
    photo = load_photo(target)
    exif = photo.exif
    assert exif.sensor_width_mm == original.exif.sensor_width_mm  # the sensor, not the file, sets it
    assert exif.focus_distance_m == original.exif.focus_distance_m
    assert "downscaled" in exif.frame
    if variant == "cropped":
        assert "cropped to 1:1" in exif.frame
    pitch = resolve_geometry(photo).pixel_pitch_mm
    assert pitch == pytest.approx(exif.sensor_width_mm / max(photo.width, photo.height))


# --------------------------------------------------------------------------------------
# Absurd values
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "key,value,field_name",
    [
        ("Exif.Photo.FNumber", ratio(0), "fnumber"),
        ("Exif.Photo.FNumber", ratio(10**6), "fnumber"),
        ("Exif.Photo.FocalLength", ratio(1, 2), "focal_length_mm"),
        ("Exif.Photo.FocalLength", exiv2.RationalValue([(-50, 1)]), "focal_length_mm"),
        ("Exif.Photo.FocalLength", ratio(10**8), "focal_length_mm"),
        ("Exif.Photo.SubjectDistance", exiv2.RationalValue([(-3, 1)]), "focus_distance_m"),
        ("Exif.Photo.SubjectDistance", ratio(10**9), "focus_distance_m"),
        ("Exif.CanonFi.FocusDistanceLower", exiv2.ShortValue(0), "focus_distance_m"),
    ],
)
def test_absurd_values_are_ignored_with_the_reason(tmp_path, key, value, field_name):
    tags = [("Exif.Image.Make", "Canon"), ("Exif.Image.Model", "Canon EOS 50D"), (key, value)]
    if key.startswith("Exif.CanonFi"):
        tags.append(("Exif.CanonFi.FocusDistanceUpper", exiv2.ShortValue(206)))
    exif = load_photo(write_with_tags(tmp_path / "m.jpg", tags)).exif
    assert getattr(exif, field_name) is None
    if not key.startswith("Exif.CanonFi"):  # a Canon range with a zero end is "not recorded", not absurd
        assert len(exif.ignored) == 1 and field_name in exif.ignored[0] and "outside" in exif.ignored[0]


# --------------------------------------------------------------------------------------
# The f-stop: value, bound, EXIF's FNumber, implied light distances, consistency
# --------------------------------------------------------------------------------------


@dataclass
class _Disc:
    index: int


@dataclass
class _PixelFit:
    diameter_px: float


@dataclass
class _DiscFit:
    disc: _Disc


@dataclass
class _Fit:
    """The parts of an ApertureFit that estimate_fstop reads: fitted discs and the consensus size."""

    diameters_px: list[float]
    diameter_uncertainty_px: float = 0.5
    focus_side: str = "unknown"
    aperture: object = None
    disc_fits: list = field(init=False)

    def __post_init__(self):
        self.disc_fits = [_DiscFit(_Disc(i)) for i in range(len(self.diameters_px))]

    @property
    def diameter_px(self) -> float:
        return float(np.median(self.diameters_px))

    def disc_fit(self, disc):
        return _PixelFit(self.diameters_px[disc.index])


def _photo_with(tmp_path, tags, shape=(400, 600, 3)):
    return load_photo(write_with_tags(tmp_path / "m.jpg", [("Exif.Image.Make", "Canon"), ("Exif.Image.Model", "Canon EOS 50D")] + tags, shape))


def _geometry(photo, light_distance_m=math.inf) -> Geometry:
    return resolve_geometry(photo, light_distance_m=light_distance_m)


def _disc_px(photo, fstop, light_m, geometry):
    return coc_mm(fstop, geometry.focal_length_mm, geometry.focus_distance_m, light_m) / geometry.pixel_pitch_mm


def test_unknown_light_distance_gives_an_upper_bound_with_the_exif_fnumber_inside(tmp_path):
    photo = _photo_with(tmp_path, [("Exif.Photo.FNumber", ratio(28, 10)), ("Exif.Photo.FocalLength", ratio(100)),
                                   ("Exif.Photo.SubjectDistance", ratio(2))])
    geometry = _geometry(photo)
    lights_m = [3.0, 5.0, 8.0]
    fit = _Fit([_disc_px(photo, 2.8, d, geometry) for d in lights_m])
    fstop = estimate_fstop(fit, photo, geometry, "thin", "equal-area")
    assert fstop.bound == "upper" and "smaller f-stop" in fstop.meaning
    assert fstop.value >= 2.8 and fstop.exif_fnumber == 2.8 and fstop.consistency is None
    assert [fstop.light_distances_m[i] for i in range(3)] == pytest.approx(lights_m, rel=1e-9)


def test_known_light_distance_gives_the_fstop_itself(tmp_path):
    photo = _photo_with(tmp_path, [("Exif.Photo.FNumber", ratio(28, 10)), ("Exif.Photo.FocalLength", ratio(100)),
                                   ("Exif.Photo.SubjectDistance", ratio(2))])
    geometry = _geometry(photo, light_distance_m=5.0)
    fit = _Fit([_disc_px(photo, 2.8, 5.0, geometry)] * 3)
    fstop = estimate_fstop(fit, photo, geometry, "thin", "equal-area")
    assert fstop.bound is None and fstop.value == pytest.approx(2.8) and fstop.consistency is None


def test_a_focus_range_widens_the_uncertainty(tmp_path):
    """Canon records the focus distance as a range: its ends bracket the f-stop (f²/(c (d_f − f)) at each end)."""
    photo = _photo_with(tmp_path, [("Exif.Photo.FNumber", ratio(35, 10)), ("Exif.Photo.FocalLength", ratio(100)),
                                   ("Exif.CanonFi.FocusDistanceUpper", exiv2.ShortValue(206)),
                                   ("Exif.CanonFi.FocusDistanceLower", exiv2.ShortValue(171))])
    geometry = _geometry(photo)
    fit = _Fit([40.0] * 3, diameter_uncertainty_px=0.0)
    fstop = estimate_fstop(fit, photo, geometry, "thin", "equal-area")
    c = 40.0 * geometry.pixel_pitch_mm
    at_ends = [100.0**2 / (c * (d_f - 100.0)) for d_f in (1710.0, 2060.0)]
    assert fstop.uncertainty == pytest.approx((at_ends[0] - at_ends[1]) / 2, rel=1e-9)
    assert "1.71–2.06 m" in fstop.meaning


def test_exif_fnumber_that_no_light_distance_explains_is_reported(tmp_path):
    """Discs too large for f/8 from any light behind the focus plane: a crop, wrong metadata, ..."""
    photo = _photo_with(tmp_path, [("Exif.Photo.FNumber", ratio(8)), ("Exif.Photo.FocalLength", ratio(100)),
                                   ("Exif.Photo.SubjectDistance", ratio(2))])
    geometry = _geometry(photo)
    fit = _Fit([_disc_px(photo, 2.0, math.inf, geometry)] * 3)
    fstop = estimate_fstop(fit, photo, geometry, "thin", "equal-area")
    assert fstop.value == pytest.approx(2.0, rel=1e-6)
    assert "any distance" in fstop.consistency and "teleconverter" in fstop.consistency
    assert all(distance is None for distance in fstop.light_distances_m.values())


@pytest.mark.parametrize(
    "tags,reason",
    [
        ([("Exif.Photo.FocalLength", ratio(1, 2)), ("Exif.Photo.SubjectDistance", ratio(2))], "unknown focal_length_mm"),
        ([("Exif.Photo.FocalLength", ratio(100)), ("Exif.Photo.SubjectDistance", ratio(0))], "unknown focus_distance_m"),
        ([("Exif.Photo.FocalLength", ratio(400)), ("Exif.Photo.SubjectDistance", ratio(2, 10))], "is not longer than the focal length"),
    ],
)
def test_out_of_range_exif_gives_a_reason_not_an_error(tmp_path, tags, reason):
    photo = _photo_with(tmp_path, tags)
    fstop = estimate_fstop(_Fit([20.0] * 3), photo, _geometry(photo), "thin", "equal-area")
    assert isinstance(fstop, FStop) and fstop.value is None and reason in fstop.reason


@pytest.mark.parametrize(
    "name",
    ["01_water-glints_canon6d_ef85.jpg", "06_christmas-lights_nikon-d5300.jpg", "08_morning-dew_canon-50d-400mm.jpg"],
)
def test_reference_bound_contains_the_exif_fnumber(compared, name):
    """Lights behind the focus plane at an unknown distance: the bound holds EXIF's FNumber."""
    comparison = compared(name)
    fstop = comparison.fstop
    assert fstop.bound == "upper" and fstop.exif_fnumber is not None
    assert fstop.value >= fstop.exif_fnumber and fstop.consistency is None
    document = comparison.to_json("")
    assert document["aperture"]["exif_fnumber"] == fstop.exif_fnumber
    depths = [disc["depth_m"] for disc in document["discs"] if disc["used"]]
    assert depths and all(d is None or d > comparison.geometry.focus_distance_m for d in depths)
    summary = comparison.summary()
    assert "f-stop: at most f/" in summary and f"EXIF: f/{fstop.exif_fnumber:g}" in summary
    assert "lights' distance implied by EXIF" in summary


def test_07_the_real_discs_contradict_exif_and_the_bound_says_so(compared):
    """Photo 07: the discs a person labels are 170-210 px; at 100 mm, f/3.5 and a focus distance of
    about 1.9 m (maker note) on the 22.3 mm sensor, lights at any distance behind the focus plane
    make discs of at most about 140-160 px. Sized on those discs (not on a small blob beside them),
    the f-stop bound lies below EXIF's FNumber, and fstop_consistency says the metadata cannot all
    be right, naming what would explain it."""
    from photo_factory import reference_labels

    from bokehfit.discs.labels import score_discs

    name = "07_touch-the-light_canon-50d-ef100.jpg"
    _, labels = reference_labels(name)
    comparison = compared(name)
    used = [(d.center_xy, d.diameter_px) for d in comparison.used_discs]
    assert used and score_discs(labels, [], used).used_as["disc"] == len(used), "sized on the labelled discs"
    fstop = comparison.fstop
    assert fstop.bound == "upper" and fstop.value < fstop.exif_fnumber == 3.5
    assert fstop.consistency and "wrong metadata" in fstop.consistency
