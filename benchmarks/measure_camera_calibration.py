"""The camera's ray model calibrated from in-air chessboard light fields, against the true rays.

Renders the ten in-air boards of ``simulator.boards.in_air_boards`` (tiny-2x camera, 0.15-0.35 m)
through each main lens, locates their corners in the light field with the nominal thin-lens
camera, calibrates the ray model (:func:`lfrefract.calibration.calibrate_camera`) and prints: the
corners' RMS distance to their rays (the ray reprojection error, mm) for the thin-lens model and
the calibrated one, the fitted parameters with their standard deviations, and both models' rays
against the true rays of every 2nd pixel (``RealLensCamera.chief_rays``): where they cross a plane
20 mm in front of the lens (mm), after the frames are aligned along z (the model's gauge: in-air
views fix the camera only up to a shift of its frame along its axis), and their angle (mrad).

    python benchmarks/measure_camera_calibration.py [--lenses thin double-gauss] [--spp 16]
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from lfrefract import camera_preset, virtual_camera_for
from lfrefract.calibration import board_view_from_light_field, calibrate_camera
from lfrefract.metrics import ray_errors
from lfrefract.optics.real_lens import RealLensCamera
from simulator import boards
from simulator.backend import load_mitsuba
from simulator.job import render_raw

#: The frame shifts along z searched when aligning a model's frame with the true one, metres.
SHIFTS_M = np.linspace(-0.01, 0.01, 401)


def _aligned(rays, true, keep) -> tuple[float, float]:
    """(position RMS after the best shift along z, that shift), metres."""
    best = min(
        (
            ray_errors(
                rays.origins_cam + np.array([0.0, 0.0, dz]),
                rays.directions_cam,
                true.origins_cam,
                true.directions_cam,
                plane_distance_m=0.02,
                valid=keep,
            ).position_rms_m,
            dz,
        )
        for dz in SHIFTS_M
    )
    return best


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--lenses", nargs="*", default=["thin", "double-gauss"])
    parser.add_argument("--spp", type=int, default=16)
    args = parser.parse_args()
    mi = load_mitsuba()
    camera = camera_preset(boards.CAMERA)
    view = virtual_camera_for(camera)
    vv, uu = np.mgrid[0 : camera.sensor.height_px : 2, 0 : camera.sensor.width_px : 2]
    uv = np.stack([uu.ravel(), vv.ravel()], axis=1).astype(float)
    for lens in args.lenses:
        start = time.perf_counter()
        views = []
        for table in boards.in_air_boards(view):
            raw = render_raw(mi, boards.in_air_board_scene(table, lens=lens, spp=args.spp), progress=False)
            views.append(
                board_view_from_light_field(
                    camera, raw, pattern=boards.PATTERN, square_size_m=table["square_size_m"], view=view
                )
            )
        located = time.perf_counter() - start
        start = time.perf_counter()
        calibration = calibrate_camera(camera, views, view=view)
        fitted = time.perf_counter() - start
        c, std = calibration.correction, calibration.correction_std
        print(
            f"{lens}: corners to their rays {calibration.initial_ray_rms_m * 1e3:.4f} mm RMS (thin-lens model) -> "
            f"{calibration.ray_rms_m * 1e3:.4f} mm (calibrated); pupil scale {c.pupil_scale:.5f} +- {std[0]:.5f}, "
            f"slope scale {c.slope_scale:.5f} +- {std[1]:.5f}, k1 {c.k1:.4f} +- {std[2]:.4f}, k2 {c.k2:.4f} +- "
            f"{std[3]:.4f}; renders and corners {located:.1f} s, fit {fitted:.2f} s"
        )
        if lens == "thin":
            continue
        true = RealLensCamera.from_preset(camera, lens).chief_rays(uv)
        for name, rays in (
            ("thin-lens model", camera.captured_rays(uv)),
            ("calibrated", calibration.captured_rays(uv)),
        ):
            keep = rays.in_aperture & true.in_aperture
            e = ray_errors(
                rays.origins_cam,
                rays.directions_cam,
                true.origins_cam,
                true.directions_cam,
                plane_distance_m=0.02,
                valid=keep,
            )
            aligned, shift = _aligned(rays, true, keep)
            print(
                f"  {name}: at 20 mm {e.position_rms_m * 1e3:.3f} mm RMS ({aligned * 1e3:.3f} mm with the frame "
                f"shifted {shift * 1e3:+.2f} mm along z), angle {e.angle_rms_rad * 1e3:.2f} mrad RMS"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
