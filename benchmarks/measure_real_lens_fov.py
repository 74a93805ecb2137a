"""The perfect field of view of the fov experiment, thin lens against each real main lens.

For the fov experiment's cameras and ports (``simulator/experiments/fov.py``: the tiny camera behind a
12 mm port with 4 mm of glass; the Illum behind the authors' reference distance, 52.9 mm, no glass)
at several tilts, the exact pixels of the refraction-free image: the thin lens's at its full aperture
(``required_aperture_radius <= aperture_radius_m``, no rim margin) and each real lens's
(``real_lens_exact_mask``: every necessary ray traced exactly through the lens to the sensor, the
central projection from its entrance pupil). A lens whose front does not clear the port is measured
at the nearest port distance it clears (``--far-m``), beside the thin lens there. Prints the share of
exact pixels, the centred perfect cone and the cone of equal solid angle, degrees.

    python benchmarks/measure_real_lens_fov.py [--scales tiny illum] [--tilts-deg 0 10 20 30]
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys

import numpy as np

from lfrefract import virtual_camera_for
from lfrefract.optics import LENS_PRESETS
from lfrefract.optics.real_lens import RealLensCamera
from simulator.experiments.fov import fov_measures, real_lens_exact_mask, required_aperture_radius, setup_for


def _clearing_distance_m(real: RealLensCamera, tilt_deg: float) -> float:
    """Smallest perpendicular port distance whose air face clears the lens at this tilt (plus 1 mm)."""
    reach_m = max(s.semi_aperture_m for s in real.lens.surfaces)
    tilt = math.radians(tilt_deg)
    return math.cos(tilt) * real.extent_z_m[1] + math.sin(tilt) * reach_m + 1e-3


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scales", nargs="*", default=["tiny", "illum"])
    parser.add_argument("--tilts-deg", nargs="*", type=float, default=[0.0, 10.0, 20.0, 30.0])
    parser.add_argument("--lenses", nargs="*", default=list(LENS_PRESETS))
    args = parser.parse_args()
    print("| scale | port, mm | tilt, deg | main lens | exact share | centred cone, deg | solid-angle cone, deg |")
    print("| --- | ---: | ---: | --- | ---: | ---: | ---: |")
    for scale in args.scales:
        setup = setup_for(scale)
        camera = setup.camera
        output = virtual_camera_for(camera)
        for tilt in args.tilts_deg:
            for name in args.lenses:
                real = RealLensCamera.from_preset(camera, name)
                distance_m = max(setup.distance_m, _clearing_distance_m(real, tilt))
                port = dataclasses.replace(setup.port(tilt), distance_m=distance_m)
                rows = {
                    "thin": required_aperture_radius(camera, port, output) <= camera.aperture_radius_m,
                    name: real_lens_exact_mask(real, port, output),
                }
                for lens, mask in rows.items():
                    if lens == "thin" and name != args.lenses[0] and distance_m == setup.distance_m:
                        continue  # the thin lens at the set-up's distance is printed once
                    m = fov_measures(mask, output)
                    print(
                        f"| {scale} | {distance_m * 1e3:.1f} | {tilt:g} | {lens} | {np.mean(mask):.3f} | "
                        f"{m['perfect_cone_centred_deg']:.1f} | {m['perfect_fov_equiv_deg']:.1f} |",
                        flush=True,
                    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
