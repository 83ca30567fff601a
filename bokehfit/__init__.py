"""bokehfit: find bokeh discs in photos, fit the aperture that made them, render its kernel.

The main job, in Python (the command line is ``bokehfit compare PHOTO``)::

    from bokehfit import compare_photo

    result = compare_photo("examples/hexagon_85mm_f2.jpg")
    print(result.verdict)              # one sentence: what the aperture is, how sure, why
    print(result.summary())            # the numbers: shape, angle, disc size, f-stop, runners-up
    document = result.to_json("")      # the JSON of ``compare --json`` (design.md §7b)

Public API (each also importable from its module; imported on first use):

compare_photo(path, ...) -> Comparison
    Every stage on one photo: discs, fitted aperture, kernel, metrics (:mod:`bokehfit.compare`).
    ``Comparison`` has ``status`` (fitted, unsure, no_fit, no_discs), ``reason``, ``verdict``,
    ``verdict_details``, ``fit``, ``fstop``, ``search`` (the discs), ``kernel``, ``metrics``,
    ``summary()``, ``to_json()``.
load_photo(path) -> Photo
    Any JPEG, PNG, TIFF or camera raw file, linearised, with its EXIF (:mod:`bokehfit.io`).
find_discs(luminance, ...) -> DiscSearch
    The bokeh discs of an image (:mod:`bokehfit.discs`).
fit_aperture(luminance, discs, ...) -> ApertureFit or FailedFit
    The aperture that explains the discs, with the candidates tried (:mod:`bokehfit.fit`).
make_aperture(shape, angle_deg, ...) -> Aperture
    An aperture of design.md §3 and §3b (:mod:`bokehfit.apertures`).
compute_kernel(aperture, diameter_px, ...) -> Kernel
    The point-light defocus kernel of an aperture (:mod:`bokehfit.kernels`).
survey(paths, db, ...) -> pyarrow.Table
    ``compare`` on a photo library into a DuckDB database (:mod:`bokehfit.survey`).

The command line: ``bokehfit --help`` (``compare``, ``discs``, ``kernel``, ``similarity``,
``render``, ``view``, ``bench``, ``survey``).
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("bokehfit")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0+unknown"

#: Public name → the module that holds it (imported on first use, so ``import bokehfit`` stays light).
_LAZY = {
    "compare_photo": "bokehfit.compare",
    "Comparison": "bokehfit.compare",
    "load_photo": "bokehfit.io",
    "find_discs": "bokehfit.discs",
    "fit_aperture": "bokehfit.fit",
    "make_aperture": "bokehfit.apertures",
    "compute_kernel": "bokehfit.kernels",
}

__all__ = ["__version__", "survey", *_LAZY]


def __getattr__(name):
    """``bokehfit.survey(...)``, ``bokehfit.compare_photo(...)``, ... without importing them with bokehfit."""
    import importlib

    if name == "survey":
        return importlib.import_module("bokehfit.survey")
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'bokehfit' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))
