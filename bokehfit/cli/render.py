"""``bokehfit render``: path-trace the Cornell box, or point lights, through a shaped aperture."""

from __future__ import annotations

import argparse
import math
import re
import sys

from bokehfit import __version__
from bokehfit.errors import InputError, check_finite
from bokehfit.outputs import check_output_path, write_json
from bokehfit.scene import (
    FOCAL_LENGTH_MM,
    RENDER_FORMATS,
    SENSOR_WIDTH_MM,
    RenderResult,
    build_scene,
    make_lens,
    make_settings,
    parse_depths,
    render_scene,
    total_work,
    write_render,
)

__all__ = ["add_parser", "run", "parse_size"]

#: Version of the --json layout; keys are added, never renamed, within one version.
SCHEMA_VERSION = 1


def parse_size(text: str) -> tuple[int, int]:
    """``"640x480"`` → (640, 480); ``InputError`` unless both are integers ≥ 1."""
    match = re.fullmatch(r"\s*(\d+)\s*[xX×]\s*(\d+)\s*", text)
    if not match:
        raise InputError(f"size must be WIDTHxHEIGHT in pixels, e.g. 512x512 (got {text!r})")
    width, height = int(match.group(1)), int(match.group(2))
    if width < 1 or height < 1:
        raise InputError(f"size must be at least 1x1 pixels (got {text!r})")
    return width, height


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "render",
        help="path-trace the Cornell box (or point lights) through a shaped aperture",
        description=(
            "Render a scene with the WGSL path tracer through the thin-lens camera of design.md §4: "
            f"a {FOCAL_LENGTH_MM:g} mm lens on a {SENSOR_WIDTH_MM:g} mm wide sensor, the aperture "
            "the area of a circle of diameter f/N. Prints samples per second and the adapter."
        ),
    )
    parser.add_argument(
        "--scene", default="cornell",
        help="cornell: the Cornell box, path traced; points: point lights on black, each drawn by "
        "splatting aperture samples through it (default cornell)",
    )
    parser.add_argument("--shape", default="circle", help="aperture shape (default circle)")
    parser.add_argument("--angle", type=float, default=0.0, metavar="DEG", help="counter-clockwise rotation (default 0)")
    parser.add_argument("--fstop", type=float, default=2.8, help="equal-area f-stop (default 2.8)")
    parser.add_argument(
        "--focus-distance", type=float, default=None, metavar="M",
        help="focus plane's distance along the view axis, m (default: cornell 0.7, points 0.3)",
    )
    parser.add_argument("--aspect", type=float, default=None, help="width/height of a slit (default 0.3)")
    parser.add_argument("--blades", type=int, default=None, help="blade count of an ngon")
    parser.add_argument("--spp", type=int, default=64, help="samples per pixel (default 64)")
    parser.add_argument("--size", default="512x512", metavar="WxH", help="image size in pixels (default 512x512)")
    parser.add_argument("--seed", type=int, default=0, help="random seed; the same seed gives the same image (default 0)")
    parser.add_argument(
        "--light-depths", default=None, metavar="M,M,...",
        help="points scene: depths of the lights, m, 'inf' allowed (default 0.15,0.2,0.3,0.6,inf)",
    )
    parser.add_argument("--exposure", type=float, default=0.0, metavar="EV", help="PNG only: scale by 2^EV before tone mapping")
    parser.add_argument("--out", required=True, help=f"output image ({', '.join(RENDER_FORMATS)})")
    parser.add_argument("--json", default=None, help="write timing, adapter and parameters here")
    parser.set_defaults(run=run)


class _Progress:
    """A tqdm bar on stderr when it is a terminal; otherwise nothing."""

    def __init__(self, total: int):
        self.bar = None
        if sys.stderr.isatty():
            from tqdm import tqdm

            self.bar = tqdm(total=total, desc="render", unit="sample", unit_scale=True, leave=False, file=sys.stderr)

    def __call__(self, n: int) -> None:
        if self.bar is not None:
            self.bar.update(n)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def run(args: argparse.Namespace) -> RenderResult:
    out = check_output_path(args.out, RENDER_FORMATS)
    json_path = check_output_path(args.json, (".json",)) if args.json else None
    exposure = check_finite("exposure", args.exposure)
    width, height = parse_size(args.size)
    depths = parse_depths(args.light_depths) if args.light_depths is not None else None
    scene = build_scene(args.scene, light_depths_m=depths)
    lens = make_lens(
        args.shape,
        args.angle,
        fstop=args.fstop,
        focus_distance_m=scene.default_focus_m if args.focus_distance is None else args.focus_distance,
        blades=args.blades,
        aspect=args.aspect,
    )
    settings = make_settings(width, height, args.spp, args.seed)
    progress = _Progress(total_work(scene, lens, settings))
    try:
        result = render_scene(scene, lens, settings, progress if progress.bar is not None else None)
    finally:
        progress.close()
    if result.nonfinite_pixels:
        print(f"bokehfit: warning: {result.nonfinite_pixels} pixels are NaN or infinite", file=sys.stderr)
    write_render(out, result.image, exposure)
    rate = result.samples_per_second
    rate_text = f"{rate / 1e6:.3g} M samples/s" if math.isfinite(rate) else "instant"
    print(
        f"{scene.name} {width}×{height}, {settings.spp} spp, {lens.describe()}: "
        f"{result.time_s:.2f} s, {rate_text} on {result.adapter} ({result.backend})"
        + (f", {result.tiles} tiles" if result.tiles > 1 else "")
    )
    print(f"wrote {out}")
    if json_path is not None:
        data = dict(
            schema_version=SCHEMA_VERSION,
            bokehfit_version=__version__,
            command_line=" ".join(["bokehfit", *sys.argv[1:]]),
            output=str(out),
            **result.to_json(),
        )
        if not math.isfinite(data["samples_per_second"]):
            data["samples_per_second"] = None
        write_json(json_path, data)
        print(f"wrote {json_path}")
    return result
