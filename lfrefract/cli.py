"""``lfrefract``: the core's command line, working on files and presets (no renderer).

    lfrefract describe (PRESET | META.json) [--json]

prints the camera's derived optics (micro-image pitch and radius, lens count, field of view),
the default refraction-free image geometry (K, size) and, for a render's ``meta.json``, the port.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from lfrefract import PRESETS, FlatPort, LightFieldCamera, ParameterError, camera_preset, virtual_camera_for
from lfrefract.io import FileFormatError, read_json

__all__ = ["describe", "main"]


def describe(camera: LightFieldCamera, port: FlatPort | None = None) -> dict:
    """Derived figures of a camera (and port), as plain data."""
    virtual = virtual_camera_for(camera)
    half_w = camera.sensor.size_m[0] / 2 / camera.micro_image_scale
    out = {
        "camera": camera.to_dict(),
        "aperture_radius_m": camera.aperture_radius_m,
        "image_side_f_number": camera.image_side_f_number,
        "mla_f_number": camera.mla.f_number,
        "micro_image_pitch_px": camera.micro_image_pitch_px,
        "micro_image_radius_px": camera.micro_image_radius_px,
        "lens_count": len(camera.lens_indices_on_sensor()),
        "horizontal_fov_in_air_deg": math.degrees(2 * math.atan(half_w / camera.lens_to_mla_m)),
        "refraction_free_image": virtual.to_dict(),
    }
    if port is not None:
        out["port"] = port.to_dict()
        out["port_clearance_m"] = port.clearance_m(camera.aperture_radius_m)
    return out


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    parser = argparse.ArgumentParser(prog="lfrefract", description="Refraction-free light-field imaging (core).")
    sub = parser.add_subparsers(dest="command", required=True)
    desc = sub.add_parser("describe", help="derived optics of a preset camera or a render's meta.json")
    desc.add_argument("source", help=f"a preset ({', '.join(sorted(PRESETS))}) or a meta.json file")
    desc.add_argument("--json", action="store_true", help="print JSON")
    args = parser.parse_args(argv)
    try:
        if args.source in PRESETS:
            info = describe(camera_preset(args.source))
        else:
            meta = read_json(Path(args.source))
            port = FlatPort.from_dict(meta["port"]) if meta.get("port") else None
            info = describe(LightFieldCamera.from_dict(meta["camera"]), port)
    except (ParameterError, FileFormatError, KeyError) as exc:
        print(f"lfrefract: error: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(info, indent=2))
    else:
        for key, value in info.items():
            if isinstance(value, dict):
                print(f"{key}:")
                for k, v in value.items():
                    print(f"  {k}: {v}")
            else:
                print(f"{key}: {value}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
