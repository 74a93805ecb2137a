"""The camera's ray model calibrated from in-air chessboard light fields, against the true rays.

Renders the ten in-air boards of ``simulator.boards.in_air_boards`` (tiny-2x camera, 0.15-0.35 m)
through each main lens, locates their corners in the light field with the nominal thin-lens
camera, calibrates the ray model (:func:`lfrefract.calibration.calibrate_camera`) and prints: the
corners' RMS distance to their rays (the ray reprojection error, mm) for the thin-lens model and
the calibrated one, the fitted parameters with their standard deviations, and both models' rays
against the true rays of every 2nd pixel (``RealLensCamera.chief_rays``): where they cross a plane
20 mm in front of the lens (mm), after the frames are aligned along z (the model's gauge: in-air
views fix the camera only up to a shift of its frame along its axis), and their angle (mrad).

Then, for each real lens, the corner test of ``benchmarks/measure_real_lens_gap.py`` (a board at
0.15 and 0.6 m behind a straight port and one tilted (25, 10) deg, the paper's k = 32): the
refraction-free image's corners against the true corners' projection (px RMS), synthesized with
the thin-lens warp map and with the calibrated one (``SynthesisOptions(ray_correction=...)``); and
the port calibrated from the ten underwater boards of ``simulator.boards.port_boards`` on each model
(``corrected_view``) and with the ray model refined together with it
(:func:`lfrefract.calibration.calibrate_port_and_camera`), its normal and distance against the true
port, and the corner test again with each chain's own port and rays.

``--outer-ring`` adds the outer ring of ten in-air and ten port boards (``outer_ring=True`` of
``simulator.boards.in_air_boards`` and ``port_boards``: 1.6 times farther into the field).

    python benchmarks/measure_camera_calibration.py [--lenses thin double-gauss] [--spp 16] [--outer-ring]
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from lfrefract import camera_preset, virtual_camera_for
from lfrefract.calibration import (
    board_view_from_light_field,
    calibrate_camera,
    calibrate_port,
    calibrate_port_and_camera,
)
from lfrefract.calibration.camera import corrected_view
from lfrefract.errors import CalibrationError
from lfrefract.metrics import ray_errors
from lfrefract.optics.real_lens import RealLensCamera
from lfrefract.synthesis.warp_map import PAPER_K, SynthesisOptions, build_warp_map
from simulator import boards
from simulator.backend import load_mitsuba
from simulator.boards import chessboard_corners_world
from simulator.config import main_lens
from simulator.job import render_raw

#: The corner test's ports and lines of sight (as benchmarks/measure_real_lens_gap.py).
TILTS = {(0.0, 0.0): (0.0, 0.0), (25.0, 10.0): (0.16, -0.125)}

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
    parser.add_argument("--outer-ring", action="store_true", help="twenty in-air and twenty port boards (both rings)")
    args = parser.parse_args()
    mi = load_mitsuba()
    camera = camera_preset(boards.CAMERA)
    view = virtual_camera_for(camera)
    vv, uu = np.mgrid[0 : camera.sensor.height_px : 2, 0 : camera.sensor.width_px : 2]
    uv = np.stack([uu.ravel(), vv.ravel()], axis=1).astype(float)
    for lens in args.lenses:
        start = time.perf_counter()
        views = []
        for table in boards.in_air_boards(view, outer_ring=args.outer_ring):
            raw = render_raw(mi, boards.in_air_board_scene(table, lens=lens, spp=args.spp), progress=False)
            found = board_view_from_light_field(
                camera, raw, pattern=boards.PATTERN, square_size_m=table["square_size_m"], view=view
            )
            if found is not None:  # a board the central view does not show is left out, and counted
                views.append(found)
        located = time.perf_counter() - start
        start = time.perf_counter()
        calibration = calibrate_camera(camera, views, view=view)
        fitted = time.perf_counter() - start
        c, std = calibration.correction, calibration.correction_std
        print(
            f"{lens}: {len(views)} boards located; corners to their rays "
            f"{calibration.initial_ray_rms_m * 1e3:.4f} mm RMS (thin-lens model) -> "
            f"{calibration.ray_rms_m * 1e3:.4f} mm (calibrated); pupil scale {c.pupil_scale:.5f} +- {std[0]:.5f}, "
            f"slope scale {c.slope_scale:.5f} +- {std[1]:.5f}, k1 {c.k1:.4f} +- {std[2]:.4f}, k2 {c.k2:.4f} +- "
            f"{std[3]:.4f}, pupil drift {c.pupil_drift_m * 1e3:.2f} +- {std[4] * 1e3:.2f} mm; "
            f"renders and corners {located:.1f} s, fit {fitted:.2f} s"
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
        print("  | port tilt (x, y), deg | board depth, m | corners, thin-lens map / calibrated map, px RMS |")
        print("  | --- | ---: | --- |")
        for tilt, sight in TILTS.items():
            empty = boards.empty_scene(tilt)
            thin_map = build_warp_map(empty.camera, empty.port, options=SynthesisOptions(k=PAPER_K))
            options = SynthesisOptions(k=PAPER_K, ray_correction=calibration.correction)
            fitted_map = build_warp_map(empty.camera, empty.port, options=options)
            for depth_m in (0.15, 0.6):
                config = boards.board_scene(tilt, boards.slanted_board(depth_m, sight, thin_map.output.focal_px))
                config = config.with_overrides(lens=main_lens(lens, config.camera))
                expected = thin_map.output.project(chessboard_corners_world(config.objects[0]))
                raw = render_raw(mi, config, progress=False)
                cells = []
                for warp in (thin_map, fitted_map):
                    found = boards.find_corners(warp.apply(raw))
                    cells.append("not found" if found is None else f"{boards.corner_rms_px(found, expected):.3f}")
                print(f"  | {tilt[0]:g}, {tilt[1]:g} | {depth_m:g} | {cells[0]} / {cells[1]} |", flush=True)
        _port_chain(mi, lens, calibration, view, camera, outer_ring=args.outer_ring)
    return 0


def _port_chain(mi, lens: str, calibration, view, camera, *, outer_ring: bool) -> None:
    """The port on each model, and the corners with each chain's own port."""
    print("  | port tilt (x, y), deg | model | normal error, deg | distance, mm (true) | corners at 0.15 / 0.6 m, px |")
    print("  | --- | --- | ---: | --- | --- |")
    for tilt, sight in TILTS.items():
        truth = boards.empty_scene(tilt).port
        views = []
        for table in boards.port_boards(tilt, view, outer_ring=outer_ring):
            config = boards.board_scene(tilt, table, spp=boards.PORT_SPP)
            raw = render_raw(mi, config.with_overrides(lens=main_lens(lens, config.camera)), progress=False)
            found = board_view_from_light_field(
                camera, raw, pattern=boards.PATTERN, square_size_m=table["square_size_m"], view=view
            )
            if found is not None:
                views.append(found)
        known = {"thickness_m": truth.thickness_m, "n_glass": truth.n_glass, "n_water": truth.n_water}
        for model in CHAINS:
            try:
                correction, port = _chain_port(model, view, views, calibration, known)
            except CalibrationError as exc:  # the views do not determine this port: a row, not a crash
                print(f"  | {tilt[0]:g}, {tilt[1]:g} | {model} | not determined: {exc} | | |", flush=True)
                continue
            error = np.degrees(np.arccos(np.clip(port.normal @ truth.normal, -1.0, 1.0)))
            warp = build_warp_map(camera, port, options=SynthesisOptions(k=PAPER_K, ray_correction=correction))
            reference = build_warp_map(camera, truth, options=SynthesisOptions(k=PAPER_K))
            cells = []
            for depth_m in (0.15, 0.6):
                config = boards.board_scene(tilt, boards.slanted_board(depth_m, sight, reference.output.focal_px))
                config = config.with_overrides(lens=main_lens(lens, config.camera))
                expected = reference.output.project(chessboard_corners_world(config.objects[0]))
                found = boards.find_corners(warp.apply(render_raw(mi, config, progress=False)))
                cells.append("not found" if found is None else f"{boards.corner_rms_px(found, expected):.3f}")
            print(
                f"  | {tilt[0]:g}, {tilt[1]:g} | {model} | {error:.2f} | {port.distance_m * 1e3:.1f} "
                f"({truth.distance_m * 1e3:.1f}) | {cells[0]} / {cells[1]} |",
                flush=True,
            )


#: The port chains compared: the port on each ray model.
CHAINS = ("thin-lens", "calibrated", "refined with the port")


def _chain_port(model: str, view, views, calibration, known: dict) -> tuple:
    """(ray correction or None, port) of one of :data:`CHAINS` on the located underwater ``views``."""
    if model == "thin-lens":
        return None, calibrate_port(view, views, **known).port
    if model == "calibrated":
        corrected = [corrected_view(v, calibration.correction, view) for v in views]
        return calibration.correction, calibrate_port(view, corrected, **known).port
    joint = calibrate_port_and_camera(view, views, prior=calibration.estimate, **known)
    return joint.correction.correction, joint.port.port


if __name__ == "__main__":
    sys.exit(main())
