"""bokehfit: find bokeh discs in photos, fit the aperture that made them, render its kernel."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("bokehfit")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0+unknown"

__all__ = ["__version__"]
