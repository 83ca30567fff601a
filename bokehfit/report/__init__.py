"""Reports for people: overlays drawn on photos (and, with ``compare``, the HTML report)."""

from bokehfit.report.overlay import draw_disc_overlay

__all__ = ["draw_disc_overlay"]
