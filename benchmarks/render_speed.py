"""Path tracer speed and noise against time, beside Mitsuba 3 on the same Cornell box.

Usage::

    python benchmarks/render_speed.py [--sizes 64,128,256,512] [--speed-spp 16]
        [--size 128] [--spp 16,64,256,1024] [--reference-spp 4096] [--repeats 3]
        [--shape circle] [--fstop 2.8] [--focus-distance 0.7] [--mitsuba-variant llvm_ad_rgb]
        [--json out.json]

Three parts, all in one run on one machine:

1. Samples per second (camera paths per second) of ``bokehfit render --scene
   cornell`` at several resolutions, after a warm-up (shader compilation is not
   timed; the time includes every dispatch and the read-back), the fastest of
   ``--repeats`` renders.
2. Noise against time: RMSE of renders at increasing spp against a
   high-spp reference of the same renderer (other seeds; the mean of
   several renders, so that no renderer holds one huge wavefront), at one
   size. The reference's own noise is taken out: with variance ∝ 1/spp,
   RMSE_true² = RMSE_measured² / (1 + spp / reference_spp).
3. The same for Mitsuba 3, rendering the same box (geometry, materials,
   light, camera, resolution, box pixel filter) with its ``thinlens`` camera
   (a circular aperture of the same area: radius f/(2N)) and its ``path``
   integrator. Each renderer is measured against its own reference. Time to
   equal RMSE: where RMSE falls as t^(-1/2), a renderer needs a time
   proportional to t·RMSE² for a given RMSE, so the ratio of times to equal
   RMSE at each spp is the ratio of t·RMSE². Every spp is rendered once
   before it is timed (kernels compiled for a new size are not timed).
   bokehfit is measured as it renders by default (next-event estimation at
   diffuse vertices, everything else by the paths' bounces: the estimator of
   Mitsuba's ``path``) and with ``mirror_nee=True`` (next-event estimation
   also reaches the light through the planar mirror).

Mitsuba is not a dependency of bokehfit. Install it into the same environment
for this benchmark only::

    pip install mitsuba      # 3.x; the llvm_ad_rgb variant needs an LLVM shared library

Without it, part 3 is skipped with a message.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time

import numpy as np

from bokehfit.apertures import make_aperture
from bokehfit.scene import cornell_box, make_lens, make_settings, render_scene
from bokehfit.scene.geometry import Scene


def rmse(image: np.ndarray, reference: np.ndarray) -> float:
    return float(np.sqrt(np.mean((image.astype(np.float64) - reference) ** 2)))


def fitted_slope(times, errors) -> float:
    """Slope of the least-squares line log RMSE against log t (−½ for plain Monte Carlo)."""
    if len(times) < 2:
        return math.nan
    return float(np.polyfit(np.log(times), np.log(errors), 1)[0])


# --- bokehfit ----------------------------------------------------------------------------------


def bokehfit_render(scene, lens, size, spp, seed, mirror_nee=False):
    settings = make_settings(size, size, spp, seed, mirror_nee=mirror_nee)
    return render_scene(scene, lens, settings)


# --- Mitsuba 3 ---------------------------------------------------------------------------------


def mitsuba_scene(mi, scene: Scene, lens, size: int, spp: int, texel_m: float = 1e-4) -> dict:
    """A Mitsuba scene dict of a bokehfit :class:`Scene` (quads, boxes, spheres; three material kinds)."""
    from mitsuba import ScalarTransform4f as T

    def bsdf(material):
        if material.kind == "mirror":
            return {"type": "conductor", "material": "none", "specular_reflectance": {"type": "rgb", "value": list(material.albedo)}}
        if material.kind == "emitter":
            return {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.0, 0.0, 0.0]}}
        if material.checker_size > 0.0 or material.line_spacing > 0.0:
            # One period of the pattern as a bitmap (nearest texels), repeated over the quad.
            period = 2.0 * material.checker_size if material.checker_size > 0.0 else material.line_spacing
            n = int(round(period / texel_m))
            centres = (np.arange(n) + 0.5) * (period / n)
            u, v = np.meshgrid(centres, centres, indexing="xy")  # rows: v, columns: u
            texture = material.albedo_at(np.stack([u, v], axis=-1)).astype(np.float32)
            # Mitsuba's bitmap puts v = 0 on the last row (image rows run downwards).
            bitmap = mi.TensorXf(np.ascontiguousarray(texture[::-1]))
            return {"type": "diffuse", "reflectance": {"type": "bitmap", "data": bitmap, "filter_type": "nearest",
                                                      "raw": True, "period_m": period}}
        return {"type": "diffuse", "reflectance": {"type": "rgb", "value": list(material.albedo)}}

    shapes = {}
    for i, quad in enumerate(scene.quads):
        material = scene.material(quad.material)
        origin, u, v = (np.asarray(a, dtype=np.float64) for a in (quad.origin, quad.u, quad.v))
        normal = np.cross(u, v)
        normal /= np.linalg.norm(normal)
        centre = origin + 0.5 * (u + v)
        matrix = np.eye(4)
        matrix[:3, 0], matrix[:3, 1], matrix[:3, 2], matrix[:3, 3] = 0.5 * u, 0.5 * v, normal, centre
        entry = {"type": "rectangle", "to_world": T(matrix.tolist()), "bsdf": bsdf(material)}
        reflectance = entry["bsdf"].get("reflectance", {})
        if reflectance.get("type") == "bitmap":
            period = reflectance.pop("period_m")
            # Mitsuba's rectangle has uv = (α, β) ∈ [0, 1]²; bokehfit's texture coordinates are (α|u|, β|v|).
            reflectance["to_uv"] = T().scale([np.linalg.norm(u) / period, np.linalg.norm(v) / period, 1.0])
        if material.kind == "emitter":
            entry["emitter"] = {"type": "area", "radiance": {"type": "rgb", "value": list(material.emission)}}
        shapes[f"quad{i}"] = entry
    for i, box in enumerate(scene.boxes):
        to_world = T().translate(list(box.center)).rotate([0.0, 1.0, 0.0], -box.angle_deg).scale(list(box.half))
        shapes[f"box{i}"] = {"type": "cube", "to_world": to_world, "bsdf": bsdf(scene.material(box.material))}
    for i, sphere in enumerate(scene.spheres):
        shapes[f"sphere{i}"] = {"type": "sphere", "center": list(sphere.center), "radius": sphere.radius,
                                "bsdf": bsdf(scene.material(sphere.material))}

    right, up, forward = scene.pose.basis()
    position = np.asarray(scene.pose.position, dtype=np.float64)
    fov_deg = math.degrees(2.0 * math.atan(lens.sensor_width_mm / (2.0 * lens.focal_length_mm)))
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 65, "rr_depth": 3},
        "sensor": {
            "type": "thinlens",
            "fov": fov_deg,
            "fov_axis": "x",
            "aperture_radius": lens.aperture_diameter_mm / 2000.0,
            "focus_distance": lens.focus_distance_m,
            "to_world": T().look_at(origin=position.tolist(), target=(position + forward).tolist(), up=up.tolist()),
            "film": {"type": "hdrfilm", "width": size, "height": size, "rfilter": {"type": "box"}, "pixel_format": "rgb"},
            "sampler": {"type": "independent", "sample_count": spp},
        },
        **shapes,
    }


def mitsuba_renderer(variant: str, scene: Scene, lens, size: int):
    """A function (spp, seed) → (image, seconds) rendering with Mitsuba, or None without Mitsuba."""
    try:
        import mitsuba as mi
    except ImportError:
        return None, "Mitsuba 3 is not installed (pip install mitsuba): its part is skipped"
    mi.set_variant(variant)
    loaded = mi.load_dict(mitsuba_scene(mi, scene, lens, size, 1))

    def run(spp: int, seed: int):
        start = time.perf_counter()
        image = np.asarray(mi.render(loaded, spp=spp, seed=seed), dtype=np.float32)[..., :3]
        return image, time.perf_counter() - start

    run(1, 12345)  # warm-up: kernel compilation is not timed
    return run, f"Mitsuba {mi.__version__} {variant}"


def reference_image(render, spp: int, chunk: int = 512) -> tuple[np.ndarray, float]:
    """Mean of renders of ``chunk`` spp (seeds 7, 8, ...) making ``spp`` in all, and the seconds."""
    images, seconds = [], 0.0
    for k in range(max(1, spp // chunk)):
        image, t = render(min(spp, chunk), 7 + k)
        images.append(image.astype(np.float64))
        seconds += t
    return np.mean(images, axis=0), seconds


def convergence(renderers: dict, references: dict, spps, reference_spp: int, repeats: int) -> dict:
    """Per renderer, rows (spp, seconds, RMSE, t·RMSE²), the reference's noise taken out.

    The renderers take turns at each spp (so that a load that comes and goes on
    the machine falls on all of them); each spp is rendered once untimed, then
    ``repeats`` times with other seeds: the time is the fastest, the RMSE the
    root mean square over the repeats.
    """
    rows = {label: [] for label in renderers}
    for spp in spps:
        for label, render in renderers.items():
            render(spp, 999)  # warm-up at this size
        samples = {label: ([], []) for label in renderers}
        for k in range(repeats):
            for label, render in renderers.items():
                image, seconds = render(spp, 1000 + 17 * k)
                samples[label][0].append(seconds)
                samples[label][1].append(rmse(image, references[label]))
        for label, (times, errors) in samples.items():
            measured = float(np.sqrt(np.mean(np.square(errors))))
            corrected = measured / math.sqrt(1.0 + spp / reference_spp)
            time_s = float(min(times))
            rows[label].append(dict(spp=spp, time_s=time_s, time_s_all=times, rmse_measured=measured, rmse=corrected,
                                    efficiency=time_s * corrected**2))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", default="64,128,256,512")
    parser.add_argument("--speed-spp", type=int, default=16)
    parser.add_argument("--size", type=int, default=128)
    parser.add_argument("--spp", default="16,64,256,1024")
    parser.add_argument("--reference-spp", type=int, default=4096)
    parser.add_argument("--repeats", type=int, default=3, help="timed renders per spp (the fastest counts)")
    parser.add_argument("--shape", default="circle")
    parser.add_argument("--fstop", type=float, default=2.8)
    parser.add_argument("--focus-distance", type=float, default=0.7)
    parser.add_argument("--mitsuba-variant", default="llvm_ad_rgb")
    parser.add_argument("--json", help="write every number here")
    args = parser.parse_args()

    scene = cornell_box()
    lens = make_lens(make_aperture(args.shape), fstop=args.fstop, focus_distance_m=args.focus_distance)
    out = dict(args=vars(args))

    # 1. Samples per second at several resolutions.
    bokehfit_render(scene, lens, 16, 1, 0)  # warm-up: compile the pipeline
    speed = []
    for size in (int(s) for s in args.sizes.split(",")):
        runs = [bokehfit_render(scene, lens, size, args.speed_spp, 1 + k) for k in range(args.repeats)]
        result = min(runs, key=lambda r: r.time_s)
        speed.append(dict(size=size, spp=args.speed_spp, time_s=result.time_s, samples_per_second=result.samples_per_second))
    out["adapter"], out["backend"] = result.adapter, result.backend
    out["speed"] = speed
    print(f"bokehfit on {result.adapter} ({result.backend}), Cornell box, {lens.describe()}")
    print(f"{'size':>6}{'spp':>6}{'time s':>10}{'M samples/s':>14}")
    for row in speed:
        print(f"{row['size']:>6}{row['spp']:>6}{row['time_s']:>10.3f}{row['samples_per_second'] / 1e6:>14.3f}")

    # 2. and 3. Noise against time, each renderer against its own reference.
    spps = [int(s) for s in args.spp.split(",")]
    renderers = {}
    for label, mirror_nee in (("bokehfit", False), ("bokehfit, mirror NEE", True)):
        def run(spp, seed, mirror_nee=mirror_nee):
            r = bokehfit_render(scene, lens, args.size, spp, seed, mirror_nee)
            return r.image, r.time_s
        renderers[label] = run
    mitsuba, note = mitsuba_renderer(args.mitsuba_variant, scene, lens, args.size)
    if mitsuba is None:
        print(note)
    else:
        renderers[note] = mitsuba

    references, reference_times = {}, {}
    for label, run in renderers.items():
        references[label], reference_times[label] = reference_image(run, args.reference_spp)
    rows = convergence(renderers, references, spps, args.reference_spp, args.repeats)
    results = {
        label: dict(
            reference_spp=args.reference_spp,
            reference_time_s=reference_times[label],
            rows=rows[label],
            slope=fitted_slope([r["time_s"] for r in rows[label]], [r["rmse"] for r in rows[label]]),
            mean_rgb=[float(v) for v in references[label].reshape(-1, 3).mean(axis=0)],
        )
        for label in renderers
    }
    out["convergence"] = results

    print(f"\nRMSE against each renderer's own {args.reference_spp}-spp reference, {args.size}×{args.size}"
          " (the reference's noise taken out):")
    print(f"{'renderer':<30}{'spp':>6}{'time s':>10}{'RMSE':>10}{'t·RMSE²':>12}")
    for label, result in results.items():
        for row in result["rows"]:
            print(f"{label:<30}{row['spp']:>6}{row['time_s']:>10.3f}{row['rmse']:>10.4f}{row['efficiency']:>12.3e}")
        print(f"{label:<30} RMSE ∝ t^{result['slope']:.2f}; reference mean RGB "
              + ", ".join(f"{v:.4f}" for v in result["mean_rgb"]))
    if mitsuba is not None:
        ratios = {}
        for label in ("bokehfit", "bokehfit, mirror NEE"):
            per_spp = [m["efficiency"] / b["efficiency"] for m, b in zip(results[note]["rows"], results[label]["rows"])]
            ratios[label] = dict(zip(spps, per_spp))
            print(f"time to equal RMSE, Mitsuba / {label}, by spp: "
                  + ", ".join(f"{spp}: {r:.2f}" for spp, r in zip(spps, per_spp)))
        diff = np.abs(references["bokehfit"] - references[note]).mean() / references[note].mean()
        means = np.abs(references["bokehfit"].mean(axis=(0, 1)) / references[note].mean(axis=(0, 1)) - 1.0).max()
        print(f"references, bokehfit against Mitsuba: mean |difference| {100 * diff:.1f} % of the mean "
              f"(the renders' own noise included); mean RGB within {100 * means:.2f} %")
        out["time_ratio_mitsuba_over_bokehfit"] = ratios
        out["reference_mean_abs_difference_rel"] = float(diff)
        out["reference_mean_rgb_difference_rel"] = float(means)
        out["mitsuba"] = note
    out["load_average_end"] = os.getloadavg()
    print(f"load average (1, 5, 15 min) at the end: {', '.join(f'{v:.2f}' for v in out['load_average_end'])}; "
          f"{os.cpu_count()} CPUs (other processes on the machine slow every renderer alike only if they stay)")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
