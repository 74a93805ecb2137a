"""``lfrefract``: the core's command line, working on files and presets (no renderer).

    lfrefract describe (PRESET | META.json) [--json]
    lfrefract synth RAW.exr --out OUT.exr [--k 32] [--supersample 2] [--lambda 0.3] [--map-cache DIR]
    lfrefract naive RAW.exr --out OUT.exr [--kind central|full]
    lfrefract views RAW.exr --out DIR [--grid 9] [--spacing-px S] [--format png|exr] [--overwrite]
    lfrefract calibrate mla WHITE.exr --out MLA.json [--grid hex|square]
    lfrefract calibrate port BOARD.exr... --squares C R --square-size-m S --out PORT.json
    lfrefract calibrate approx BOARD.exr... --squares C R --square-size-m S --out APPROX.json

``describe`` prints a camera's derived optics and the default refraction-free image geometry.
``synth`` reads the camera and port from the ``meta.json`` beside ``RAW.exr`` and writes the
refraction-free image ``OUT.exr``, its sidecar ``OUT.json`` (K, size, pose, options, coverage
statistics), the coverage map ``OUT.coverage.exr`` and a figure ``OUT.png``. ``naive`` writes the
conventional view with no refraction handling, for comparison. ``views`` writes a regular grid of
sub-aperture views (no refraction handling either) in the HCI 4D light field benchmark layout that
light-field depth-estimation methods read (``lfrefract.io.write_view_stack``).

``calibrate`` estimates what the pipeline would otherwise be told: ``mla`` the microlens lattice
and every micro-image centre from a white image; ``port`` the port's normal and distance from
underwater chessboard captures (corners found in their central views; the glass thickness and
refractive indices are known, from the options or the first capture's ``meta.json``), also written
in the Refractive COLMAP / calibmar flat-port layout (``PORT.txt``); ``approx`` the approximation
baseline (a pinhole with distortion from views at one depth). ``synth --port PORT.json
--mla MLA.json`` uses the estimates instead of the capture's ``meta.json``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from lfrefract import (
    PRESETS,
    FlatPort,
    LightFieldCamera,
    ParameterError,
    PinholeCamera,
    camera_preset,
    virtual_camera_for,
)
from lfrefract.calibration import MlaCalibration, calibrate_approx, calibrate_mla, calibrate_port
from lfrefract.calibration.port import CORNER_METHODS, board_view_from_light_field
from lfrefract.io import (
    VIEW_STACK_FORMATS,
    FileFormatError,
    read_exr,
    read_json,
    write_exr,
    write_flat_port,
    write_json,
    write_view_stack,
)
from lfrefract.methods import ConventionalView
from lfrefract.synthesis import SEARCH_METHODS, SynthesisOptions, WarpMap, build_warp_map, warp_map_key
from lfrefract.views import naive_view, subaperture_stack

__all__ = [
    "calibrate_approx_command",
    "calibrate_mla_command",
    "calibrate_port_command",
    "describe",
    "main",
    "naive",
    "synth",
    "views",
]


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


def _capture(raw_path: Path) -> tuple[np.ndarray, dict]:
    """A raw image and the sidecar beside it (``meta.json`` of a render directory)."""
    raw = read_exr(raw_path)
    meta = read_json(raw_path.parent / "meta.json")
    return raw, meta


def synth(args: argparse.Namespace) -> int:
    """``lfrefract synth``: refraction-free image of a raw capture."""
    raw, meta = _capture(Path(args.raw))
    camera = LightFieldCamera.from_dict(meta["camera"])
    if args.mla:
        camera = MlaCalibration.from_dict(read_json(Path(args.mla))["mla"]).calibrated_camera(camera)
    if args.port:
        port = FlatPort.from_dict(read_json(Path(args.port))["port"])
    elif meta.get("port"):
        port = FlatPort.from_dict(meta["port"])
    else:
        raise ParameterError(f"{args.raw!r}: its meta.json has no port and no --port was given; nothing to remove")
    options = SynthesisOptions(k=args.k, supersample=args.supersample, lambda_m_per_rad=args.lam, search=args.search)
    output = PinholeCamera.from_dict(meta["ideal"]) if meta.get("ideal") else virtual_camera_for(camera)
    key = warp_map_key(camera, port, output, options)
    cached = Path(args.map_cache) / f"{key}.npz" if args.map_cache else None
    start = time.perf_counter()
    if cached is not None and cached.is_file():
        warp = WarpMap.load(cached, expected_key=key)
        how = f"loaded {cached}"
    else:
        warp = build_warp_map(camera, port, output=output, options=options, progress=not args.quiet)
        how = "built"
        if cached is not None:
            warp.save(cached)
            how += f", cached as {cached}"
    map_seconds = time.perf_counter() - start
    start = time.perf_counter()
    image = warp.apply(raw)
    apply_seconds = time.perf_counter() - start
    out = Path(args.out)
    stats = {
        "exact_fraction": float(warp.exact.mean()),
        "filled_fraction": float(warp.filled.mean()),
        "mean_coverage": float(warp.coverage.mean()),
        "nonzeros_per_pixel": float(len(warp.indices) / max(1, len(warp.gain))),
    }
    write_exr(out, image, role="refraction_free")
    write_exr(out.with_suffix(".coverage.exr"), warp.coverage.astype(np.float32), role="coverage")
    write_json(
        out.with_suffix(".json"),
        {
            "kind": "lfrefract.synth",
            "source": str(args.raw),
            "K": warp.output.K.tolist(),
            "width_px": warp.output.width_px,
            "height_px": warp.output.height_px,
            "pose": meta.get("pose"),
            "camera": camera.to_dict(),
            "port": port.to_dict(),
            "options": options.to_dict(),
            "map_key": warp.key,
            "coverage": stats,
            "seconds": {"map": map_seconds, "apply": apply_seconds},
            "files": {"image": out.name, "coverage": out.with_suffix(".coverage.exr").name},
        },
    )
    _figure(out.with_suffix(".png"), image, warp)
    print(
        f"{how} warp map ({map_seconds:.2f} s), applied in {apply_seconds * 1e3:.1f} ms; exact coverage "
        f"{stats['exact_fraction']:.1%}, filled {stats['filled_fraction']:.1%}; wrote {out}"
    )
    return 0


def _figure(path: Path, image: np.ndarray, warp: WarpMap) -> None:
    import matplotlib as mpl

    mpl.use("Agg")
    import matplotlib.pyplot as plt

    shown = image if image.ndim == 2 else image[..., :3]
    white = float(np.percentile(shown[warp.filled], 99.5)) if warp.filled.any() else 1.0
    fig, ax = plt.subplots(figsize=(6, 6 * warp.output.height_px / warp.output.width_px + 0.5), dpi=120)
    ax.imshow(np.clip(shown / (white or 1.0), 0, 1) ** (1 / 2.2), cmap="gray", interpolation="nearest")
    ax.contour(warp.coverage, levels=[0.999], colors="yellow", linewidths=1)
    ax.set_title("refraction-free image; yellow: edge of exact coverage")
    ax.set_axis_off()
    fig.savefig(path, bbox_inches="tight")
    plt.close(fig)


def naive(args: argparse.Namespace) -> int:
    """``lfrefract naive``: conventional view with no refraction handling."""
    raw, meta = _capture(Path(args.raw))
    camera = LightFieldCamera.from_dict(meta["camera"])
    output = PinholeCamera.from_dict(meta["ideal"]) if meta.get("ideal") else virtual_camera_for(camera)
    image = naive_view(camera, raw, output=output, kind=args.kind)
    write_exr(Path(args.out), image, role=f"naive_{args.kind}")
    print(f"wrote {args.out}")
    return 0


def views(args: argparse.Namespace) -> int:
    """``lfrefract views``: a grid of sub-aperture views in the HCI benchmark layout."""
    raw, meta = _capture(Path(args.raw))
    camera = LightFieldCamera.from_dict(meta["camera"])
    output = PinholeCamera.from_dict(meta["ideal"]) if meta.get("ideal") else virtual_camera_for(camera)
    stack = subaperture_stack(camera, raw, grid=args.grid, spacing_px=args.spacing_px, output=output)
    out = write_view_stack(
        Path(args.out),
        stack,
        overwrite=args.overwrite,
        image_format=args.format,
        metadata={"source": str(args.raw), "pose": meta.get("pose")},
    )
    print(
        f"{stack.grid} x {stack.grid} views of {output.width_px} x {output.height_px} px, spacing "
        f"{stack.spacing_px:.4g} px, baseline {stack.baseline_m * 1e3:.4g} mm, disparity "
        f"{output.focal_px * stack.baseline_m:.4g} px m / depth; wrote {out}"
    )
    return 0


def calibrate_mla_command(args: argparse.Namespace) -> int:
    """``lfrefract calibrate mla``."""
    white = read_exr(Path(args.white))
    result = calibrate_mla(white, grid=args.grid)
    data = {"kind": "lfrefract.calibrate.mla", "source": str(args.white), "mla": result.to_dict()}
    meta_path = Path(args.white).parent / "meta.json"
    if meta_path.is_file():
        data["camera"] = result.calibrated_camera(LightFieldCamera.from_dict(read_json(meta_path)["camera"])).to_dict()
    write_json(Path(args.out), data)
    counts = result.status_counts()
    print(
        f"{result.grid} lattice, pitch {result.pitch_px:.4f} px, rotation {math.degrees(result.rotation_rad):.4f} deg; "
        f"{counts.get('used', 0)} micro-images used, residual {result.residual_rms_px:.4f} px RMS; wrote {args.out}"
    )
    return 0


def _board_captures(args: argparse.Namespace) -> tuple[LightFieldCamera, dict, PinholeCamera]:
    """The camera of the board captures (one, from the first capture's meta.json), that meta, and
    the geometry of their conventional views."""
    if min(args.squares) < 2:
        raise ParameterError(f"--squares must be at least 2 x 2, got {args.squares!r}")
    metas = [read_json(Path(path).parent / "meta.json") for path in args.boards]
    meta = metas[0]
    for path, other in zip(args.boards, metas, strict=True):
        if other["camera"] != meta["camera"]:
            raise ParameterError(f"{path!r} was taken with another camera than {args.boards[0]!r}")
    camera = LightFieldCamera.from_dict(meta["camera"])
    return camera, meta, virtual_camera_for(camera)


def calibrate_port_command(args: argparse.Namespace) -> int:
    """``lfrefract calibrate port``: corners located in each capture's light field (or in its
    sub-aperture views), then :func:`calibrate_port`."""
    camera, meta, view = _board_captures(args)
    known = meta.get("port") or {}
    try:
        n_air = known.get("n_air", 1.0)
        thickness = args.thickness_m if args.thickness_m is not None else known["thickness_m"]
        n_glass = args.n_glass if args.n_glass is not None else known["n_glass"]
        n_water = args.n_water if args.n_water is not None else known["n_water"]
    except KeyError as exc:
        raise ParameterError(
            f"--{exc.args[0].replace('_', '-')} is needed (the capture's meta.json has no port)"
        ) from None
    pattern = (args.squares[0] - 1, args.squares[1] - 1)
    step = args.subaperture_offset_px
    if step != 0 and args.corners != "views":
        raise ParameterError(f"--subaperture-offset-px={step!r} needs --corners views")
    offsets = ((0.0, 0.0),) if step == 0 else ((0.0, 0.0), (step, 0.0), (-step, 0.0), (0.0, step), (0.0, -step))
    views = []
    for path in args.boards:
        board_view = board_view_from_light_field(
            camera,
            read_exr(Path(path)),
            pattern=pattern,
            square_size_m=args.square_size_m,
            view=view,
            method=args.corners,
            offsets_px=offsets,
            name=str(path),
        )
        if board_view is None:
            raise ParameterError(
                f"{path!r}: no chessboard with {pattern[0]} x {pattern[1]} inner corners found "
                "(or under 8 of its corners located)"
            )
        views.append(board_view)
    result = calibrate_port(view, views, thickness_m=thickness, n_air=n_air, n_glass=n_glass, n_water=n_water)
    out = Path(args.out)
    write_json(out, {"kind": "lfrefract.calibrate.port", "sources": [str(p) for p in args.boards], **result.to_dict()})
    write_flat_port(out.with_suffix(".txt"), result.port)
    print(
        f"port normal {np.round(result.port.normal, 5).tolist()} (+- {result.normal_std_deg:.3f} deg), distance "
        f"{result.port.distance_m * 1e3:.2f} mm (+- {result.distance_std_m * 1e3:.2f}), "
        f"residual {result.rms_px:.3f} px RMS; wrote {out} and {out.with_suffix('.txt')}"
    )
    return 0


def calibrate_approx_command(args: argparse.Namespace) -> int:
    """``lfrefract calibrate approx``: the approximation baseline on the captures' central views."""
    camera, _, view = _board_captures(args)
    conventional = ConventionalView(camera=camera, view=view)
    images = [conventional.apply(read_exr(Path(path))) for path in args.boards]
    pattern = (args.squares[0] - 1, args.squares[1] - 1)
    result = calibrate_approx(images, pattern=pattern, square_size_m=args.square_size_m)
    result.save(Path(args.out))
    print(f"pinhole + distortion from {len(images)} views, {result.rms_px:.3f} px RMS; wrote {args.out}")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    parser = argparse.ArgumentParser(prog="lfrefract", description="Refraction-free light-field imaging (core).")
    sub = parser.add_subparsers(dest="command", required=True)
    desc = sub.add_parser("describe", help="derived optics of a preset camera or a render's meta.json")
    desc.add_argument("source", help=f"a preset ({', '.join(sorted(PRESETS))}) or a meta.json file")
    desc.add_argument("--json", action="store_true", help="print JSON")
    syn = sub.add_parser("synth", help="refraction-free image of a raw capture (meta.json beside it)")
    syn.add_argument("raw", help="raw lenslet image (EXR) with meta.json in its directory")
    syn.add_argument("--out", required=True, help="output EXR")
    syn.add_argument("--k", type=int, default=32, help="captured rays averaged per necessary ray")
    syn.add_argument("--supersample", type=int, default=2, help="necessary rays per pixel along each axis")
    syn.add_argument("--lambda", dest="lam", type=float, default=0.3, help="angle weight of D, metres per radian")
    syn.add_argument("--search", choices=SEARCH_METHODS, default="auto", help="candidate search (default: auto)")
    syn.add_argument("--map-cache", help="directory of warp maps, keyed by their parameters")
    syn.add_argument("--quiet", action="store_true", help="no progress bar while building the map")
    syn.add_argument("--port", help="port from `lfrefract calibrate port` (default: the capture's meta.json)")
    syn.add_argument("--mla", help="MLA from `lfrefract calibrate mla` (default: the capture's meta.json)")
    cal = sub.add_parser("calibrate", help="estimate the MLA, the port or the approximation baseline")
    cal_sub = cal.add_subparsers(dest="target", required=True)
    cal_mla = cal_sub.add_parser("mla", help="microlens lattice and micro-image centres from a white image")
    cal_mla.add_argument("white", help="white image (EXR)")
    cal_mla.add_argument("--out", required=True, help="output JSON")
    cal_mla.add_argument("--grid", choices=["hex", "square"], help="lattice type (default: detected)")
    for target, what in (("port", "port normal and distance"), ("approx", "pinhole + distortion at one depth")):
        board = cal_sub.add_parser(target, help=f"{what} from underwater chessboard captures")
        board.add_argument("boards", nargs="+", help="raw captures (EXR) of a chessboard, meta.json beside them")
        board.add_argument(
            "--squares", type=int, nargs=2, required=True, metavar=("C", "R"), help="squares of the board"
        )
        board.add_argument("--square-size-m", type=float, required=True, help="edge of a square, metres")
        board.add_argument("--out", required=True, help="output JSON")
    cal_port = cal_sub.choices["port"]
    cal_port.add_argument("--thickness-m", type=float, help="glass thickness (default: the first capture's meta.json)")
    cal_port.add_argument("--n-glass", type=float, help="glass index (default: meta.json)")
    cal_port.add_argument("--n-water", type=float, help="water index (default: meta.json)")
    cal_port.add_argument(
        "--corners",
        choices=CORNER_METHODS,
        default="light-field",
        help="locate corners on every raw pixel around them (default), or in sub-aperture views",
    )
    cal_port.add_argument(
        "--subaperture-offset-px",
        type=float,
        default=0.0,
        help="with --corners views: also the four sub-aperture views this far from the micro-image centres",
    )
    nv = sub.add_parser("naive", help="conventional view with no refraction handling")
    nv.add_argument("raw", help="raw lenslet image (EXR) with meta.json in its directory")
    nv.add_argument("--out", required=True, help="output EXR")
    nv.add_argument("--kind", choices=["central", "full"], default="central")
    vw = sub.add_parser("views", help="grid of sub-aperture views in the HCI 4D light field benchmark layout")
    vw.add_argument("raw", help="raw lenslet image (EXR) with meta.json in its directory")
    vw.add_argument("--out", required=True, help="output directory")
    vw.add_argument("--grid", type=int, default=9, help="views per row and column, odd >= 3 (default: 9)")
    vw.add_argument(
        "--spacing-px", type=float, help="sensor offset between neighbouring views (default: the largest that fits)"
    )
    vw.add_argument("--format", choices=VIEW_STACK_FORMATS, default="png", help="view images (default: png)")
    vw.add_argument("--overwrite", action="store_true", help="replace an earlier view stack in --out")
    args = parser.parse_args(argv)
    try:
        if args.command == "synth":
            return synth(args)
        if args.command == "naive":
            return naive(args)
        if args.command == "views":
            return views(args)
        if args.command == "calibrate":
            return {"mla": calibrate_mla_command, "port": calibrate_port_command, "approx": calibrate_approx_command}[
                args.target
            ](args)
        if args.source in PRESETS:
            info = describe(camera_preset(args.source))
        else:
            meta = read_json(Path(args.source))
            port = FlatPort.from_dict(meta["port"]) if meta.get("port") else None
            info = describe(LightFieldCamera.from_dict(meta["camera"]), port)
    except (ParameterError, FileFormatError, FileExistsError, KeyError) as exc:
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
