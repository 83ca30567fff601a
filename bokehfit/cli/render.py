"""``bokehfit render``: path-trace the Cornell box, or point lights, through a shaped aperture."""

from __future__ import annotations

import argparse
import math
import os
import re
import sys
from pathlib import Path

from bokehfit import __version__
from bokehfit.apertures import SHAPES
from bokehfit.errors import InputError
from bokehfit.output_paths import check_output_path
from bokehfit.outputs import write_json
from bokehfit.scene import (
    FOCAL_LENGTH_MM,
    RENDER_FORMATS,
    SCENES,
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
from bokehfit.scene.renderer import QUICK_WORK, estimate_render_s
from bokehfit.cli.aperture_args import add_feature_arguments, aperture_from_args
from bokehfit.cli.arg_types import arg_type, interval, shape_arg

__all__ = ["add_parser", "run", "parse_size", "check_render_memory", "estimate_write_s", "RENDER_BYTES_PER_PIXEL"]

#: Version of the --json layout; keys are added, never renamed, within one version.
SCHEMA_VERSION = 1
#: Default bound on a render's estimated time (--max-time), seconds.
DEFAULT_MAX_TIME_S = 3600.0
#: Renders estimated to take longer than this print the estimate before they start, seconds.
ANNOUNCE_S = 10.0
#: Memory a render holds per pixel at its peak, bytes: the float32 RGB image (12), the 8-bit copy
#: and the encoded file with its copies while it is written. Measured 28 B/px at 4096² for PNG and
#: EXR (peak RSS less the interpreter's); 32 leaves a margin.
RENDER_BYTES_PER_PIXEL = 32
#: Memory the process holds besides the image (interpreter, libraries, GPU driver), bytes: measured 0.23 GB.
RENDER_BASE_BYTES = 400 << 20
#: Side of the trial image whose writing is timed to estimate the output's writing time, pixels: large enough
#: that it does not sit in the CPU's caches (a 512² trial gave half the time per pixel of a 16384² file).
_WRITE_TRIAL_SIDE = 1024


def available_memory_bytes() -> int | None:
    """Memory the system can give without swapping (Linux ``MemAvailable``), or None where unknown."""
    try:
        with open("/proc/meminfo", "rb") as file:
            for line in file:
                if line.startswith(b"MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def check_render_memory(width: int, height: int) -> int:
    """The bytes a ``width``×``height`` render needs (:data:`RENDER_BYTES_PER_PIXEL`), or ``InputError`` past what is available."""
    needed = width * height * RENDER_BYTES_PER_PIXEL + RENDER_BASE_BYTES
    available = available_memory_bytes()
    if available is not None and needed > available:
        raise InputError(
            f"a {width}×{height} render needs about {needed / 1e9:.3g} GB of memory ({RENDER_BYTES_PER_PIXEL} bytes a pixel), "
            f"more than the {available / 1e9:.3g} GB available: lower --size"
        )
    return needed


def estimate_write_s(width: int, height: int, suffix: str) -> float:
    """Seconds to tone-map, encode and write the output, from a timed trial on a noisy image (the worst to compress)."""
    import tempfile
    import time

    import numpy as np

    side = _WRITE_TRIAL_SIDE
    trial = np.random.default_rng(0).random((side, side, 3), dtype=np.float32)
    with tempfile.TemporaryDirectory(prefix="bokehfit-write-trial-") as folder:
        write_render(Path(folder) / f"warm{suffix}", trial[:16, :16])  # first imports and tables, not counted
        start = time.perf_counter()
        write_render(Path(folder) / f"trial{suffix}", trial)
        elapsed = time.perf_counter() - start
    return elapsed * width * height / (side * side)


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
            "Render a scene with the WGSL path tracer through the renderer camera of the design conventions "
            f"(docs/conventions.md, section 4, 'Renderer camera'): a {FOCAL_LENGTH_MM:g} mm lens on a "
            f"{SENSOR_WIDTH_MM:g} mm wide sensor, the aperture the area of a circle of diameter f/N. "
            "Prints samples per second and the adapter. Renders estimated to take longer than "
            f"{ANNOUNCE_S:g} s print the estimate first; those over --max-time are refused."
        ),
    )
    parser.add_argument(
        "--scene", default="cornell", metavar="|".join(SCENES),
        help="cornell: the Cornell box, path traced; points: point lights on black, each drawn by "
        "splatting aperture samples through it (default cornell)",
    )
    parser.add_argument(
        "--shape", type=shape_arg("--shape"), default="circle",
        help=f"aperture shape: {', '.join(SHAPES)} (with --blades) or ngon(N) (default circle)",
    )
    parser.add_argument("--angle", type=arg_type("angle_deg", "--angle"), default=0.0, metavar="DEG", help="counter-clockwise rotation (default 0)")
    parser.add_argument("--fstop", type=arg_type("fstop", "--fstop"), default=2.8, metavar="N", help=f"equal-area f-stop, {interval('fstop')} (default 2.8)")
    parser.add_argument(
        "--focus-distance", type=arg_type("focus_distance_m", "--focus-distance"), default=None, metavar="M",
        help=f"focus plane's distance along the view axis, {interval('focus_distance_m')} (default: cornell 0.7, points 0.3)",
    )
    parser.add_argument("--aspect", type=arg_type("aspect", "--aspect"), default=None, metavar="A", help="width/height of a slit (default 0.3)")
    parser.add_argument("--blades", type=arg_type("blades", "--blades"), default=None, metavar="N", help=f"blade count of an ngon, {interval('blades')} (default: none)")
    add_feature_arguments(parser, mask=True)
    parser.add_argument("--spp", type=arg_type("spp", "--spp"), default=64, metavar="N", help=f"samples per pixel, {interval('spp')} (default 64)")
    parser.add_argument("--size", default="512x512", metavar="WxH", help=f"image size in pixels, each side {interval('image_side_px')} (default 512x512)")
    parser.add_argument("--seed", type=arg_type("seed", "--seed"), default=0, metavar="S", help="random seed; the same seed gives the same image (default 0)")
    parser.add_argument(
        "--light-depths", default=None, metavar="M,M,...",
        help="points scene: depths of the lights, m, 'inf' allowed (default 0.15,0.2,0.3,0.6,inf)",
    )
    parser.add_argument(
        "--exposure", type=arg_type("exposure_ev", "--exposure"), default=0.0, metavar="EV",
        help=f"PNG only: scale by 2^EV before tone mapping, {interval('exposure_ev')} (default 0)",
    )
    parser.add_argument(
        "--max-time", type=arg_type("max_time_s", "--max-time"), default=DEFAULT_MAX_TIME_S, metavar="S",
        help=f"refuse a render estimated to take longer, seconds, or inf (default {DEFAULT_MAX_TIME_S:g})",
    )
    parser.add_argument("--out", required=True, help=f"output image ({', '.join(RENDER_FORMATS)}); required")
    parser.add_argument("--json", default=None, metavar="OUT.json", help="write timing, adapter and parameters here (default: none)")
    parser.set_defaults(run=run)


def _duration(seconds: float) -> str:
    """``42 s``, ``3.5 min``, ``2.1 h``, ``3.2 days``."""
    for unit, size in (("days", 86400.0), ("h", 3600.0), ("min", 60.0)):
        if seconds >= 2 * size:
            return f"{seconds / size:.2g} {unit}"
    return f"{seconds:.2g} s" if seconds < 10 else f"{seconds:.0f} s"  # 118 s, not 1.2e+02 s


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
    exposure = args.exposure
    width, height = parse_size(args.size)
    depths = parse_depths(args.light_depths) if args.light_depths is not None else None
    scene = build_scene(args.scene, light_depths_m=depths)
    lens = make_lens(
        aperture_from_args(args),
        fstop=args.fstop,
        focus_distance_m=scene.default_focus_m if args.focus_distance is None else args.focus_distance,
    )
    settings = make_settings(width, height, args.spp, args.seed)
    check_render_memory(width, height)
    if total_work(scene, lens, settings, args.adapter) > QUICK_WORK:
        rendering, rate = estimate_render_s(scene, lens, settings, args.adapter)
        estimate = rendering + estimate_write_s(width, height, out.suffix.lower())
        if estimate > args.max_time:
            raise InputError(
                f"the render would take about {_duration(estimate)} ({rate / 1e6:.3g} M samples/s in a trial, and writing "
                f"the file), more than --max-time {args.max_time:g} s: lower --spp or --size, or raise --max-time"
            )
        if estimate > ANNOUNCE_S:
            print(f"estimated time: about {_duration(estimate)} ({rate / 1e6:.3g} M samples/s in a trial; "
                  f"{_duration(estimate - rendering)} of it writing the file)", flush=True)
    progress = _Progress(total_work(scene, lens, settings, args.adapter))
    try:
        result = render_scene(scene, lens, settings, progress if progress.bar is not None else None, adapter=args.adapter)
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
            command_line=args.command_line,
            output=str(out),
            **result.to_json(),
        )
        if not math.isfinite(data["samples_per_second"]):
            data["samples_per_second"] = None
        write_json(json_path, data)
        print(f"wrote {json_path}")
    return result
