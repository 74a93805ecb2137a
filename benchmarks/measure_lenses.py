"""Measure what a real main lens changes against the thin lens of the same first-order data.

For each camera preset and main lens (thin, then every preset of ``lfsim lenses`` scaled and stopped
to the camera), from the exact numpy trace (:class:`lfrefract.optics.RealLensCamera`), prints:

* distortion: the object-space angle of the chief ray of the microlens at 50 % and 100 % of the
  sensor's half width (from its micro-image centre), against the thin lens's chief ray of the same
  microlens: ``tan`` of the real angle over the thin one, minus 1, percent (positive: barrel, a
  wider angle at the same image height);
* micro-image centre offset: how far the micro-image centre of that edge microlens lies from
  where the thin lens puts it, pixels (the exit pupil is not at the rear principal plane);
* vignetting: the fraction of the light a micro-image receives (the share of a 9 x 9 grid of
  samples over each pixel's microlens cell that gets through the lens, summed over the
  micro-image) at 50 % and 100 % of the half width and at the corner, relative to the centre.

    python benchmarks/measure_lenses.py                 # tiny and illum
    python benchmarks/measure_lenses.py --cameras f01
"""

from __future__ import annotations

import argparse
import math
import sys

import numpy as np

from lfrefract.optics import LENS_PRESETS, RealLensCamera, camera_preset


def _micro_image_light(optics, camera, centre_px: np.ndarray, radius_px: float) -> float:
    """Light through the main lens into the micro-image around ``centre_px``: passing samples."""
    r = math.ceil(radius_px + 2)
    du, dv = np.meshgrid(np.arange(-r, r + 1), np.arange(-r, r + 1))
    uv = np.round(centre_px) + np.column_stack([du.ravel(), dv.ravel()])
    g = (np.arange(9) + 0.5) / 9.0
    gx, gy = np.meshgrid(g, g)
    cells = camera.mla.cell_offsets_m(np.column_stack([gx.ravel(), gy.ravel()]))
    uv_all = np.repeat(uv, len(cells), axis=0)
    offsets = np.tile(cells, (len(uv), 1))
    rays = optics.rays_through_lenses(uv_all, lens_offsets_m=offsets)
    idx = rays.lens_indices.reshape(len(uv), len(cells), 2)[:, 0]
    own = np.all(idx == optics.lens_indices_for_pixels(centre_px[None])[0], axis=1)
    return float(rays.in_aperture.reshape(len(uv), len(cells))[own].sum())


def measure(camera_name: str) -> list[str]:
    camera = camera_preset(camera_name)
    half_w = camera.sensor.width_px / 2.0
    c = np.array([(camera.sensor.width_px - 1) / 2.0, (camera.sensor.height_px - 1) / 2.0])
    points = {
        "50%": c + np.array([0.5 * half_w, 0.0]),
        "100%": c + np.array([0.98 * half_w, 0.0]),
        "corner": c + 0.98 * np.array([half_w, camera.sensor.height_px / 2.0]),
    }
    rows = []
    for lens in ("thin", *LENS_PRESETS):
        optics = camera if lens == "thin" else RealLensCamera.from_preset(camera, lens)
        # The microlens under each point and its micro-image centre (where its chief ray starts).
        idx = {k: optics.lens_indices_for_pixels(p[None]) for k, p in points.items()}
        centres = {k: optics.micro_image_centres_px(i)[0] for k, i in idx.items()}
        thin_centres = {k: camera.micro_image_centres_px(i)[0] for k, i in idx.items()}
        chief = {k: optics.rays_through_lenses(centres[k][None]) for k in points}
        thin = {k: camera.rays_through_lenses(thin_centres[k][None]) for k in points}
        dist = []
        for k in ("50%", "100%"):
            d, t = chief[k].directions_cam[0], thin[k].directions_cam[0]
            tan_real, tan_thin = math.hypot(d[0], d[1]) / d[2], math.hypot(t[0], t[1]) / t[2]
            dist.append(100.0 * (tan_real / tan_thin - 1.0) if chief[k].in_aperture[0] else float("nan"))
        offset = float(np.linalg.norm(centres["100%"] - thin_centres["100%"]))
        radius = optics.micro_image_radius_px
        light0 = _micro_image_light(optics, camera, optics.micro_image_centres_px(np.zeros((1, 2), int))[0], radius)
        vig = [_micro_image_light(optics, camera, centres[k], radius) / light0 for k in points]
        angle = math.degrees(
            math.atan(math.hypot(*chief["100%"].directions_cam[0][:2]) / chief["100%"].directions_cam[0][2])
        )
        rows.append(
            f"| {camera_name} | {lens} | {angle:.1f} | {dist[0]:+.2f} | {dist[1]:+.2f} | {offset:.2f} | "
            f"{vig[0]:.3f} | {vig[1]:.3f} | {vig[2]:.3f} |"
        )
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cameras", nargs="+", default=["tiny", "illum"])
    args = parser.parse_args()
    print(
        "| camera | main lens | edge field, deg | distortion at 50 %, % | at 100 %, % | micro-image centre offset at "
        "the edge, px | light at 50 % | at 100 % | at the corner |"
    )
    print("| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for name in args.cameras:
        for row in measure(name):
            print(row, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
