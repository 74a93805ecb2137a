"""The camera's ray model calibrated from in-air boards, radial and polynomial, against a real lens's true rays.

For each main lens (a preset name or a lens file, e.g. ``scenes/lenses/tessar.toml``), scaled and
stopped to the ``tiny-2x`` camera: renders the camera calibration's in-air boards
(``simulator.boards.in_air_boards``, ten, or twenty with ``--outer-ring``), locates their corners in the
light field, and calibrates the ray model twice (:func:`lfrefract.calibration.calibrate_camera`,
``ray_model="radial"`` and ``"polynomial"``). Each model's rays of every 2nd raw pixel are compared with
the lens's true rays (``RealLensCamera.chief_rays``): RMS distance where they cross the plane z = 20 mm
(about a port's air-side face) after the model's frame is shifted along z to fit the true one best (the
calibration's frame has its origin at the entrance pupil, the simulator's at the rear principal plane),
and RMS angle.

The camera the chain works with is the thin-lens camera with the micro-image lattice of the real lens
(its MLA pitch scaled by the lens's micro-image scale over the thin lens's): what the MLA calibration
from a white image measures (``lfrefract calibrate mla``), taken here from the truth so that only the
ray model is measured.

    python benchmarks/measure_ray_models.py [--lenses double-gauss scenes/lenses/tessar.toml] [--spp 16] [--cache DIR]
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

from lfrefract import camera_preset, virtual_camera_for
from lfrefract.calibration import board_view_from_light_field, calibrate_camera
from lfrefract.metrics import ray_errors
from lfrefract.optics.real_lens import RealLensCamera
from simulator import boards
from simulator.backend import load_mitsuba
from simulator.config import main_lens
from simulator.job import render_raw

#: Frame shifts along z searched when aligning a model's frame with the true one: coarse, then fine.
COARSE_SHIFTS_M = np.linspace(-0.2, 0.2, 401)
#: The plane the rays are compared on (camera frame z, metres).
PLANE_M = 0.02


def _position_rms(rays, true, keep, dz: float) -> float:
    return ray_errors(
        rays.origins_cam + np.array([0.0, 0.0, dz]),
        rays.directions_cam,
        true.origins_cam,
        true.directions_cam,
        plane_distance_m=PLANE_M,
        valid=keep,
    ).position_rms_m


def _aligned(rays, true, keep) -> tuple[float, float]:
    """(position RMS after the best shift along z, that shift), metres."""
    _, coarse = min((_position_rms(rays, true, keep, dz), dz) for dz in COARSE_SHIFTS_M)
    step = COARSE_SHIFTS_M[1] - COARSE_SHIFTS_M[0]
    return min((_position_rms(rays, true, keep, dz), dz) for dz in np.linspace(coarse - step, coarse + step, 201))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--lenses", nargs="*", default=["double-gauss"])
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--outer-ring", action="store_true", help="twenty in-air boards (both rings)")
    parser.add_argument("--cache", type=Path, help="folder keeping the renders (raw .npy by lens and board) for reruns")
    args = parser.parse_args()
    mi = load_mitsuba()
    nominal = camera_preset(boards.CAMERA)
    vv, uu = np.mgrid[0 : nominal.sensor.height_px : 2, 0 : nominal.sensor.width_px : 2]
    uv = np.stack([uu.ravel(), vv.ravel()], axis=1).astype(float)
    print("| lens | model | corners to rays, um RMS | rays at 20 mm, mm RMS (z shift) | angle, mrad RMS | fit, s |")
    print("| --- | --- | ---: | ---: | ---: | ---: |")
    for name in args.lenses:
        lens = main_lens(name, nominal)
        real = RealLensCamera(camera=nominal, lens=lens)
        scale = real.micro_image_scale / nominal.micro_image_scale
        camera = dataclasses.replace(nominal, mla=dataclasses.replace(nominal.mla, pitch_m=nominal.mla.pitch_m * scale))
        view = virtual_camera_for(camera)
        views = []
        for number, table in enumerate(boards.in_air_boards(virtual_camera_for(nominal), outer_ring=args.outer_ring)):
            kept = None if args.cache is None else args.cache / f"{lens.name}-{args.spp}spp-{number}.npy"
            if kept is not None and kept.is_file():
                raw = np.load(kept)
            else:
                raw = render_raw(mi, boards.in_air_board_scene(table, lens=lens, spp=args.spp), progress=False)
                if kept is not None:
                    kept.parent.mkdir(parents=True, exist_ok=True)
                    np.save(kept, raw)
            found = board_view_from_light_field(
                camera, raw, pattern=boards.PATTERN, square_size_m=table["square_size_m"], view=view
            )
            if found is not None:
                views.append(found)
        true = real.chief_rays(uv)
        thin = camera.captured_rays(uv)
        keep = thin.in_aperture & true.in_aperture
        for model in ("thin", "radial", "polynomial"):
            start = time.perf_counter()
            if model == "thin":
                rays, rms, label = thin, float("nan"), "thin lens"
            else:
                calibration = calibrate_camera(camera, views, view=view, ray_model=model)
                rays, rms = calibration.captured_rays(uv), calibration.ray_rms_m
                label = getattr(calibration.correction, "name", "radial")
            seconds = time.perf_counter() - start
            aligned, shift = _aligned(rays, true, keep)
            angle = ray_errors(
                rays.origins_cam,
                rays.directions_cam,
                true.origins_cam,
                true.directions_cam,
                plane_distance_m=PLANE_M,
                valid=keep,
            ).angle_rms_rad
            print(
                f"| {lens.name} ({len(views)} boards) | {label} | {rms * 1e6:.2f} | {aligned * 1e3:.4f} "
                f"({shift * 1e3:+.2f} mm) | {angle * 1e3:.3f} | {seconds:.1f} |",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
