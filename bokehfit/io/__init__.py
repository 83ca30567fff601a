"""Reading photos: linear light, clipped pixels, EXIF and maker notes, colour spaces, sensor sizes.

The public entry point is :func:`load_photo`, which returns a :class:`Photo`.
"""

from bokehfit.io.colour import Encoding, detect_encoding, luminance_weights
from bokehfit.io.exif import Exif, build_exif, lensfun_camera, read_exif_tags, sensor_width
from bokehfit.io.photo import MAX_PIXELS, MIN_SIDE_PX, RAW_SUFFIXES, Photo, load_photo

__all__ = [
    "Encoding",
    "Exif",
    "MAX_PIXELS",
    "MIN_SIDE_PX",
    "Photo",
    "RAW_SUFFIXES",
    "build_exif",
    "detect_encoding",
    "load_photo",
    "lensfun_camera",
    "luminance_weights",
    "read_exif_tags",
    "sensor_width",
]
