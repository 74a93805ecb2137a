"""Benchmark the plenoptic render against Mitsuba's own ``perspective`` sensor.

For each camera preset, renders the embedded default scene (port tilted 20 deg) at the same
pixel count, spp and band size: with the plenoptic sensor (the ``sensor`` port model: the sensor
refracts its rays through the port) and with Mitsuba's ``perspective`` sensor covering the same
field in the same glass-free scene and integrator; with ``--geometry`` also with the port as
scene geometry (the reference model, crossed by Mitsuba's path tracer). Each render runs in a fresh process so its peak
memory (max RSS) is its own. Prints seconds, Msamples/s, peak memory and the ratio.

    python benchmarks/bench_render.py                  # tiny and illum, 16 spp
    python benchmarks/bench_render.py --cameras tiny --spp 64 --geometry
    python benchmarks/bench_render.py --lenses double-gauss wide-angle   # real main lenses too

Targets (issue 2): ratio <= 1.1; full Illum at 16 spp in <= 30 s on the 2-core CI machine.
Target (issue 14): a real-lens Illum raw at 16 spp within 2x the thin-lens time and 2.5 GB.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import platform
import resource
import subprocess
import sys
import time

import numpy as np


def _worker(camera_name: str, sensor_kind: str, spp: int, band_pixels: int) -> dict:
    from lfrefract.optics import RealLensCamera, camera_preset
    from simulator.backend import load_mitsuba, versions
    from simulator.config import RenderSettings, load_scene
    from simulator.render import render_bands
    from simulator.scene import build_scene
    from simulator.sensor import plenoptic_sensor_dict

    mi = load_mitsuba()
    camera = camera_preset(camera_name)
    port_model = "geometry" if sensor_kind == "plenoptic-geometry" else "sensor"
    config = load_scene().with_overrides(camera=camera, render=RenderSettings(spp=spp, port_model=port_model))
    lens = None
    if sensor_kind.startswith("plenoptic+"):  # a real main lens: the port moved out to clear it if needed
        real = RealLensCamera.from_preset(camera, sensor_kind.split("+", 1)[1])
        lens = real.lens
        clear_m = real.extent_z_m[1] + max(s.semi_aperture_m for s in lens.surfaces) + 1e-3
        port = dataclasses.replace(config.port, distance_m=max(config.port.distance_m, clear_m))
        config = config.with_overrides(port=port, lens=lens)
    scene = build_scene(mi, config, port_geometry=port_model == "geometry")
    width, height = camera.sensor.width_px, camera.sensor.height_px

    if sensor_kind.startswith("plenoptic"):
        sensor_port = config.port if port_model == "sensor" else None

        def sensor_for_crop(crop):
            return plenoptic_sensor_dict(mi, camera, config.pose, spp=spp, crop=crop, port=sensor_port, lens=lens)

    else:
        # Mitsuba's camera looks along +z with +x left and +y up: OpenCV frame = diag(-1, -1, 1).
        # Same (glass-free) scene and integrator as the plenoptic sensor with its port model.
        to_world = config.pose.matrix @ np.diag([-1.0, -1.0, 1.0, 1.0])
        half_width = camera.sensor.size_m[0] / 2 / camera.micro_image_scale
        fov_deg = math.degrees(2 * math.atan(half_width / camera.lens_to_mla_m))

        def sensor_for_crop(crop):
            x, y, w, h = crop
            film = {
                "type": "hdrfilm",
                "width": width,
                "height": height,
                "rfilter": {"type": "box"},
                "pixel_format": "rgb",
                "component_format": "float32",
                "crop_offset_x": x,
                "crop_offset_y": y,
                "crop_width": w,
                "crop_height": h,
            }
            return {
                "type": "perspective",
                "fov": fov_deg,
                "fov_axis": "x",
                "to_world": mi.ScalarTransform4f(to_world.tolist()),
                "film": film,
                "sampler": {"type": "independent", "sample_count": spp},
            }

    start = time.perf_counter()
    image = render_bands(
        mi, scene, sensor_for_crop, width, height, spp=spp, seed=0, max_band_pixels=band_pixels, progress=False
    )
    seconds = time.perf_counter() - start
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    return {
        "camera": camera_name,
        "sensor": sensor_kind,
        "pixels": width * height,
        "spp": spp,
        "seconds": seconds,
        "msamples_per_s": width * height * spp / seconds / 1e6,
        "peak_rss_mb": peak_mb,
        "mean_radiance": float(np.mean(image)),
        **versions(),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cameras", nargs="+", default=["tiny", "illum"])
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--band-pixels", type=int, default=None, help="default: simulator.render's")
    parser.add_argument("--worker", nargs=2, metavar=("CAMERA", "SENSOR"), help=argparse.SUPPRESS)
    parser.add_argument("--json", action="store_true", help="print the figures as JSON too")
    parser.add_argument(
        "--geometry", action="store_true", help="also render with the port as scene geometry (the slow reference)"
    )
    parser.add_argument(
        "--lenses",
        nargs="*",
        default=[],
        help="also render with these real main lenses (lfsim lenses); the port is moved out to clear a long lens",
    )
    args = parser.parse_args()
    from simulator.render import DEFAULT_MAX_BAND_PIXELS

    band_pixels = args.band_pixels or DEFAULT_MAX_BAND_PIXELS
    if args.worker:
        print(json.dumps(_worker(args.worker[0], args.worker[1], args.spp, band_pixels)))
        return 0

    print(
        f"machine: {platform.processor() or platform.machine()}, {__import__('os').cpu_count()} cores, "
        f"python {platform.python_version()}"
    )
    print(f"scene: embedded default (port tilted 20 deg), spp {args.spp}, band {band_pixels / 1e6:.1f} Mpx")
    print(f"{'camera':8} {'sensor':19} {'pixels':>12} {'seconds':>9} {'Msample/s':>10} {'peak MB':>9} {'ratio':>6}")
    results = []
    for name in args.cameras:
        row = {}
        kinds = ("perspective", "plenoptic", "plenoptic-geometry") if args.geometry else ("perspective", "plenoptic")
        kinds = (*kinds, *(f"plenoptic+{lens}" for lens in args.lenses))
        for kind in kinds:
            cmd = [
                sys.executable,
                __file__,
                "--worker",
                name,
                kind,
                "--spp",
                str(args.spp),
                "--band-pixels",
                str(band_pixels),
            ]
            proc = subprocess.run(cmd, capture_output=True, text=True, check=True)
            row[kind] = json.loads(proc.stdout.strip().splitlines()[-1])
        for kind in kinds:
            r = row[kind]
            ratio = r["seconds"] / row["perspective"]["seconds"]
            shown = f"{ratio:6.2f}" if kind != "perspective" else ""
            if kind.startswith("plenoptic+"):
                shown += f"  ({r['seconds'] / row['plenoptic']['seconds']:.2f} x thin lens)"
            print(
                f"{name:8} {kind:19} {r['pixels']:>12,} {r['seconds']:9.2f} {r['msamples_per_s']:10.2f} "
                f"{r['peak_rss_mb']:9.0f} {shown:>6}"
            )
        results.append({"camera": name, **row})
    if args.json:
        print(json.dumps(results, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
