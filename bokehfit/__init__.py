"""bokehfit: find bokeh discs in photos, fit the aperture that made them, render its kernel."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("bokehfit")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0+unknown"

__all__ = ["__version__", "survey"]


def __getattr__(name):
    """``bokehfit.survey(...)`` without importing the survey's dependencies with bokehfit."""
    if name == "survey":
        import importlib

        return importlib.import_module("bokehfit.survey")
    raise AttributeError(f"module 'bokehfit' has no attribute {name!r}")
