"""How far the thin-lens ray model is from the true rays of a camera with a real main lens.

For each camera and lens, every raw pixel's true object-space ray (its chief sample through a real
lens, :meth:`lfrefract.optics.real_lens.RealLensCamera.chief_rays`, what ``lfsim render --rays``
writes) against the ray the thin-lens model of the same first-order data gives it
(:meth:`LightFieldCamera.captured_rays`: what the core assumes today), both in air: where they
cross a plane at ``--plane-m`` in front of the lens (a port's air-side face; 1 mm in front of a lens
that reaches farther; mm) and the angle
between them (mrad), over the pixels both models let through, and over those of them that both
assign to the same microlens. This is the ``ray_rms_mm`` anchor of a calibrated camera model.

    python benchmarks/measure_ray_model_errors.py [--cameras tiny illum] [--plane-m 0.02]
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from lfrefract import camera_preset
from lfrefract.metrics import ray_errors
from lfrefract.optics import LENS_PRESETS
from lfrefract.optics.real_lens import RealLensCamera


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cameras", nargs="*", default=["tiny", "illum"])
    parser.add_argument("--lenses", nargs="*", default=list(LENS_PRESETS))
    parser.add_argument("--plane-m", type=float, default=0.02)
    parser.add_argument("--stride", type=int, default=1, help="every n-th pixel row and column (Illum: 4)")
    args = parser.parse_args()
    print(
        "| camera | main lens | plane, mm | pixels | position RMS / max, mm | angle RMS / max, mrad "
        "| same microlens: pixels, position RMS, angle RMS |"
    )
    print("| --- | --- | ---: | ---: | --- | --- | --- |")
    for name in args.cameras:
        camera = camera_preset(name)
        stride = args.stride if name != "illum" else max(args.stride, 4)
        vv, uu = np.mgrid[0 : camera.sensor.height_px : stride, 0 : camera.sensor.width_px : stride]
        uv = np.stack([uu.ravel(), vv.ravel()], axis=1).astype(np.float64)
        thin = camera.captured_rays(uv)
        for lens in args.lenses:
            real = RealLensCamera.from_preset(camera, lens)
            plane_m = max(args.plane_m, real.extent_z_m[1] + 1e-3)  # in front of the lens, where a port can be
            true = real.chief_rays(uv)
            both = thin.in_aperture & true.in_aperture
            same = both & np.all(thin.lens_indices == true.lens_indices, axis=1)
            cells = []
            for keep in (both, same):
                e = ray_errors(
                    thin.origins_cam,
                    thin.directions_cam,
                    true.origins_cam,
                    true.directions_cam,
                    plane_distance_m=args.plane_m,
                    valid=keep,
                )
                cells.append(e)
            a, b = cells
            print(
                f"| {name} | {lens} | {plane_m * 1e3:.1f} | {a.count} | "
                f"{a.position_rms_m * 1e3:.3f} / {a.position_max_m * 1e3:.3f} | "
                f"{a.angle_rms_rad * 1e3:.2f} / {a.angle_max_rad * 1e3:.2f} | "
                f"{b.count}, {b.position_rms_m * 1e3:.3f} mm, {b.angle_rms_rad * 1e3:.2f} mrad |",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
