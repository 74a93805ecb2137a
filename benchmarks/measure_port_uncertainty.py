"""Does the port calibration's stated uncertainty cover its error? A synthetic study over lenses and seeds.

Each lens (a preset name or a lens file), scaled and stopped to the ``tiny-2x`` camera, is the truth:
its true rays (``RealLensCamera.chief_rays`` of every 2nd raw pixel, with the micro-image lattice the
lens gives, as an MLA calibration from a white image would measure it) fitted by a polynomial ray model
of capacity (7, 3) without the frame's directions (``PolynomialCorrection``; 0.002 mm from the true
rays on the presets), so that truth and calibration share one frame. For each seed:

1. ten in-air boards (7 x 5 corners, 0.15-0.35 m, spanning 0.4-0.6 of the view) are seen from five
   aperture points (the centre and four at 0.3 of the aperture radius), each corner along the thin-lens
   slope whose true ray passes it, with ``--noise-px`` Gaussian noise in the pinhole view;
2. the camera is calibrated from them (``calibrate_camera``, ``--ray-model``);
3. ten boards in the water (0.2-0.5 m) behind a port of the given tilts are seen the same way through
   the port, and the port is calibrated on the calibrated model, with its spread propagated
   (``calibrate_port(model_views=...)``);
4. the port's normal and distance errors are divided by the stated standard deviations.

Prints one row per run and, per lens, how many runs have both errors within 3 stated sigma, and how
many were refused (a camera model or port the views do not determine: a refusal states no uncertainty).

    python benchmarks/measure_port_uncertainty.py [--lenses double-gauss scenes/lenses/tessar.toml] [--seeds 5]
"""

from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np

from lfrefract import virtual_camera_for
from lfrefract.calibration import calibrate_camera, calibrate_port_and_camera
from lfrefract.errors import CalibrationError
from lfrefract.optics.port import FlatPort
from simulator.lens_family import board_views, port_on_model, truth_model


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--lenses", nargs="*", default=["double-gauss"])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--noise-px", type=float, default=0.05)
    parser.add_argument(
        "--ray-model",
        choices=("radial", "polynomial", "truth"),
        default="polynomial",
        help="the camera model the port is calibrated on; truth: the true rays (no camera calibration, no spread)",
    )
    parser.add_argument(
        "--refine",
        action="store_true",
        help="refine the ray model with the port (calibrate_port_and_camera, as calibrate port --refine-camera; "
        "radial model only): the port it keeps, and whether it kept the refinement",
    )
    parser.add_argument("--tilt-deg", type=float, nargs=2, default=(20.0, 10.0))
    parser.add_argument("--distance-m", type=float, default=0.03)
    parser.add_argument("--thickness-m", type=float, default=0.005)
    args = parser.parse_args()
    port = FlatPort.from_degrees(
        distance_m=args.distance_m,
        thickness_m=args.thickness_m,
        tilt_x_deg=args.tilt_deg[0],
        tilt_y_deg=args.tilt_deg[1],
    )
    print("| lens | seed | model | normal error, deg (z) | distance error, mm (z) | camera-model share |")
    print("| --- | ---: | --- | ---: | ---: | ---: |")
    for name in args.lenses:
        camera, truth = truth_model(name)
        view = virtual_camera_for(camera)
        covered, refused = [], 0
        for seed in range(args.seeds):
            start = time.perf_counter()
            rng = np.random.default_rng(seed)
            in_air = board_views(truth, camera, view, rng, n=10, depths=(0.15, 0.35), port=None, noise_px=args.noise_px)
            water = board_views(truth, camera, view, rng, n=10, depths=(0.2, 0.5), port=port, noise_px=args.noise_px)
            try:
                if args.ray_model == "truth":
                    correction, spread = truth, np.zeros((0, truth.vector().size))
                else:
                    calibration = calibrate_camera(camera, in_air, view=view, ray_model=args.ray_model)
                    correction, spread = calibration.correction, calibration.spread
                kept = ""
                if args.refine:
                    joint = calibrate_port_and_camera(
                        view, water, prior=calibration.estimate, thickness_m=port.thickness_m,
                        n_water=port.n_water, n_glass=port.n_glass,
                    )  # fmt: skip
                    kept = " refined" if joint.accepted else " (refinement rejected)"
                    result = joint.port if joint.accepted else port_on_model(view, water, correction, spread, port)
                else:
                    result = port_on_model(view, water, correction, spread, port)
            except CalibrationError as exc:  # a refusal states nothing: its own count, not the coverage's
                refused += 1
                reason = str(exc).splitlines()[0][:120]
                print(f"| {name} | {seed} | {args.ray_model} | refused: {reason} | | |", flush=True)
                continue
            normal_error = math.degrees(math.acos(min(1.0, float(result.port.normal @ port.normal))))
            distance_error = result.port.distance_m - port.distance_m
            z_normal = normal_error / result.normal_std_deg
            z_distance = abs(distance_error) / result.distance_std_m
            parts = result.covariance_parts.get("camera_model")
            share = 0.0 if parts is None else parts[2, 2] / result.covariance[2, 2]
            covered.append(z_normal <= 3.0 and z_distance <= 3.0)
            label = ("truth" if args.ray_model == "truth" else getattr(correction, "name", "radial")) + kept
            print(
                f"| {name} | {seed} | {label} | {normal_error:.4f} ({z_normal:.2f}) | {distance_error * 1e3:+.4f} "
                f"({z_distance:.2f}) | {share:.0%} | {time.perf_counter() - start:.0f} s |",
                flush=True,
            )
        summary = f"within 3 sigma: {sum(covered)} of {len(covered)}; refused: {refused}"
        print(f"| {name} | all | | {summary} | | |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
