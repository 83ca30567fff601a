"""``python -m bokehfit`` runs the command line."""

from bokehfit.cli import entry_point

entry_point()
