"""The command-line options of the real-lens aperture features (design.md §3b), in one place.

``kernel``, ``render`` and ``similarity`` (once per side) take the same options
with the same checks, ranges and help; values go to the aperture model as given,
and :func:`aperture_from_args` builds the one :class:`~bokehfit.apertures.Aperture`
each command passes on.
"""

from __future__ import annotations

import argparse

from bokehfit.apertures import Aperture, Chromatic, Vignetting, make_aperture
from bokehfit.apertures.mask import MAX_MASK_SIDE
from bokehfit.cli.arg_types import arg_type, interval, pair_arg

__all__ = ["add_feature_arguments", "aperture_from_args"]


def aperture_from_args(args: argparse.Namespace, side: str = "") -> Aperture:
    """The aperture of a command's options, built once by :func:`~bokehfit.apertures.make_aperture`.

    Reads ``shape``, ``angle``, ``blades``, ``aspect`` and the options of
    :func:`add_feature_arguments`; ``side`` (e.g. ``"a"``) reads one side of a
    comparison (``shape_a``, ``angle_a``, ...). An option the command lacks
    (``similarity`` has no ``--rim``) is at the model's default.

    Raises
    ------
    InputError
        From ``make_aperture``, naming the parameter.
    """

    def value(name: str, default=None):
        return getattr(args, f"{name}_{side}" if side else name, default)

    vignetting, chromatic = value("vignetting"), value("chromatic")
    return make_aperture(
        value("shape"),
        value("angle", 0.0),
        blades=value("blades"),
        aspect=value("aspect"),
        roundness=value("roundness", 0.0),
        squeeze=value("squeeze", 1.0),
        vignetting=None if vignetting is None else Vignetting(*vignetting),
        rim=value("rim", 0.0),
        chromatic=None if chromatic is None else Chromatic(*chromatic),
        mask=value("mask"),
    )


def add_feature_arguments(
    parser: argparse.ArgumentParser, suffix: str = "", whose: str = "", outline_only: bool = False, chromatic_help: str = "",
    mask: bool = False,
) -> None:
    """Add ``--roundness``, ``--squeeze``, ``--vignetting``, unless ``outline_only`` ``--rim`` and ``--chromatic``, and with ``mask`` ``--mask``.

    ``suffix`` (e.g. ``-a``) and ``whose`` (e.g. `` of A``) name one side of a
    comparison; ``outline_only`` leaves out the options that change the light
    but not the outline (a comparison of outlines has no use for them).
    ``mask`` adds the transmission image of shape ``mask`` (design.md §3b),
    for the commands that draw it (``kernel``, ``render``, ``similarity``).
    """

    def option(name: str) -> str:
        return f"--{name}{suffix}"

    if mask:
        parser.add_argument(
            option("mask"), default=None, metavar="PNG",
            help=f"transmission image{whose} for shape mask: greyscale or RGB (luminance), 8 or 16 bits, at most "
            f"{MAX_MASK_SIDE}² pixels, centred on the optical axis, scaled to unit transmitted area (default: none; "
            "only with shape mask)",
        )
    parser.add_argument(
        option("roundness"), type=arg_type("roundness", option("roundness")), default=0.0, metavar="R",
        help=f"blade curvature R/ρ{whose}, {interval('roundness')}: 0 straight blades, 1 the circle; n-gons only (default 0)",
    )
    parser.add_argument(
        option("squeeze"), type=arg_type("squeeze", option("squeeze")), default=1.0, metavar="S",
        help=f"anamorphic squeeze{whose}, {interval('squeeze')}: > 1 makes discs taller than wide (default 1)",
    )
    parser.add_argument(
        option("vignetting"),
        type=pair_arg(option("vignetting"), ("vignetting_radius", "vignetting_shift"), "RADIUS,SHIFT"),
        default=None, metavar="RADIUS,SHIFT",
        help=f"cat-eye vignetting{whose}: the barrel's circle of radius RADIUS·R0 ({interval('vignetting_radius')}) "
        f"centred at SHIFT·R0·q ({interval('vignetting_shift')}), q the field position in half-diagonals, R0 the "
        "radius of the aperture's equal-area circle (default: none)",
    )
    if outline_only:
        return
    parser.add_argument(
        "--rim", type=arg_type("rim", "--rim"), default=0.0, metavar="W",
        help=f"intensity profile 1 + W·(2ρ² − 1), {interval('rim')}: > 0 bright rim (soap bubble), < 0 bright centre (default 0)",
    )
    parser.add_argument(
        "--chromatic", type=pair_arg("--chromatic", ("chromatic", "chromatic"), "RED,BLUE"), default=None, metavar="RED,BLUE",
        help=f"longitudinal colour: red and blue disc diameters over green's minus 1, each {interval('chromatic')}"
        f"{chromatic_help} (default: none)",
    )
