"""Measure the depth-aware synthesis: corners and depth outside the exact coverage, and its cost.

    python benchmarks/measure_depth_aware.py corners [--out DIR] [--spp 16]
    python benchmarks/measure_depth_aware.py timing [--camera illum] [--frames 2]

``corners`` renders (Mitsuba, tiny-2x) the slanted 7 x 5 chessboard of ``simulator.boards`` behind a
port 40 mm away with 4 mm of glass, tilted about both axes, at several depths and lines of sight
whose whole board lies outside the warp map's exact coverage, and measures against the ground truth:

- ``classic_px``: corner RMS of the paper's synthesis (the warp map, default options) there, where
  nearby rays stand in for the unrecorded necessary rays;
- ``depth_aware_px``: the same for the depth-aware synthesis (depth from the light field itself);
- ``true_depth_px``: the depth-aware render given the board's true depth (its floor);
- ``depth_median_mm`` / ``depth_rms_mm`` / ``depth_rms_pct``: the depth of the board's pixels against
  the truth (RMS after leaving out the worst 5 %, whose share is ``depth_off_5pct``: off by more than
  5 %), and the same median for the estimator with the rays continued straight through the port
  (``no_refraction_median_mm``);
- ``hci_mse_x100`` / ``hci_badpix_0_07``: the HCI benchmark's scores of the board's disparity
  (``f_px * baseline / z`` with the baseline of the default 9 x 9 view stack);

and, for the floor, the corner RMS inside the exact coverage behind the 12 mm port of the corner
tests (``where = inside``). ``--out DIR`` writes ``corners.csv`` and a figure per board there.

``timing`` builds and applies both syntheses on a closed-form light field of a textured plane at
0.5 m behind the paper's reference port (no rendering: each usable ray holds the plane's texture
where it crosses it), in one process, and prints build and per-frame times beside the paper's
method with the depth and image errors of that frame. Both need the project installed with its
``sim`` extra (``pip install -e '.[sim]'``).
"""

from __future__ import annotations

import argparse
import csv
import math
import platform
import time
from pathlib import Path

import numpy as np

SQUARES_PX_NOTE = "9 px squares at the board's centre"


def _texture(x_m: np.ndarray, y_m: np.ndarray) -> np.ndarray:
    return 0.5 + 0.4 * np.sin(2 * np.pi * x_m / 0.03) * np.cos(2 * np.pi * y_m / 0.041)


def _board_scene(tilt, distance_m: float, objects: list, spp: int):
    from simulator import boards
    from simulator.config import parse_scene
    from simulator.geometry import check_geometry

    port = boards.port_table(tilt)
    port["distance_m"] = distance_m
    # The corner tests' lights, moved beyond the farther port (lights must be in the water).
    lights = [
        {**light, "position_m": [*light["position_m"][:2], 0.12], "intensity_w_sr": 0.15} for light in boards.LIGHTS
    ]
    data = {
        "name": "boards",
        "camera": {"preset": boards.CAMERA},
        "render": {"spp": spp, "seed": 0},
        "light": lights,
        "object": objects,
        "port": port,
    }
    config = parse_scene(data, source="<measure_depth_aware>")
    check_geometry(config)
    return config


def _board_depth(board, output) -> np.ndarray:
    """Camera-frame z of the board's plane along every pixel's line of sight, (H, W) metres."""
    from simulator import boards

    corners = boards.chessboard_corners_world(board)
    normal = np.cross(corners[1] - corners[0], corners[-1] - corners[0])
    normal /= np.linalg.norm(normal)
    directions = output.pixel_directions().reshape(output.height_px, output.width_px, 3)
    return (corners.mean(axis=0) @ normal) / (directions @ normal) * directions[..., 2]


def _board_mask(board, output) -> np.ndarray:
    from scipy import ndimage

    from simulator import boards

    uv = np.round(output.project(boards.board_points_world(board, n=61))).astype(int)
    mask = np.zeros((output.height_px, output.width_px), dtype=bool)
    keep = (uv[:, 0] >= 0) & (uv[:, 1] >= 0) & (uv[:, 0] < output.width_px) & (uv[:, 1] < output.height_px)
    mask[uv[keep, 1], uv[keep, 0]] = True
    return ndimage.binary_fill_holes(ndimage.binary_closing(mask, iterations=2))


def _hci_baseline_m(camera) -> float:
    from lfrefract.synthesis.views import subaperture_centre_m, subaperture_limit_px

    spacing = subaperture_limit_px(camera) / (math.sqrt(2.0) * 4)  # the default 9 x 9 stack
    return float(subaperture_centre_m(camera, (spacing, 0.0))[0])


def corners(args: argparse.Namespace) -> None:
    from lfrefract.metrics import hci_scores
    from lfrefract.synthesis.depth_aware import (
        DepthAwareSynthesis,
        estimate_depth,
        render_given_depth,
        trace_scene_rays,
    )
    from lfrefract.synthesis.warp_map import build_warp_map
    from simulator import boards
    from simulator.backend import load_mitsuba
    from simulator.job import render_raw

    mi = load_mitsuba()
    rows = []
    # The floor: boards inside the exact coverage behind the corner tests' 12 mm port.
    for tilt, direction in boards.DIRECTIONS.items():
        config = boards.empty_scene(tilt)
        warp = build_warp_map(config.camera, config.port)
        for depth in (0.15, 0.6):
            scene = boards.board_scene(tilt, boards.slanted_board(depth, direction, warp.output.focal_px))
            board = scene.objects[0]
            expected = warp.output.project(boards.chessboard_corners_world(board))
            found = boards.find_corners(warp.apply(render_raw(mi, scene, progress=False)))
            rows.append(
                {
                    "where": "inside",
                    "port_mm": 12,
                    "tilt_deg": tilt,
                    "direction": direction,
                    "depth_m": depth,
                    "classic_px": np.nan if found is None else boards.corner_rms_px(found, expected),
                }
            )
            print(rows[-1], flush=True)
    distance = 0.04
    # Per compound tilt, lines of sight whose board lies wholly in the approximated band at every
    # depth (found on a 0.05 grid of x / z and y / z).
    sight_lines = {
        (25.0, 10.0): ((0.16, -0.125), (0.1, -0.06), (0.0, -0.1)),
        (15.0, -20.0): ((0.0, -0.1), (0.0, -0.05)),
        (-20.0, 15.0): ((0.0, 0.05), (0.05, 0.05)),
    }
    out = Path(args.out) if args.out else None
    if out is not None and out.exists() and any(out.iterdir()):
        raise SystemExit(f"--out {out} is not empty; name a new or empty folder")
    for tilt, directions in sight_lines.items():
        empty = _board_scene(tilt, distance, [], args.spp)
        camera, port = empty.camera, empty.port
        warp = build_warp_map(camera, port)
        synthesis = DepthAwareSynthesis.build(camera, port, warp=warp)
        straight = trace_scene_rays(camera, None)
        output = warp.output
        baseline = _hci_baseline_m(camera)
        classes_before = warp.filled_classes
        for direction in directions:
            for depth in (0.2, 0.35, 0.6):
                board_table = boards.slanted_board(depth, direction, output.focal_px)
                try:
                    scene = _board_scene(tilt, distance, [board_table], args.spp)
                except ValueError:
                    continue
                board = scene.objects[0]
                mask = _board_mask(board, output)
                uv = np.round(output.project(boards.board_points_world(board))).astype(int)
                inside = np.all((uv >= 0) & (uv < [output.width_px, output.height_px]), axis=1)
                if not inside.all():
                    continue
                under = classes_before[uv[:, 1], uv[:, 0]]
                if np.any(under != 1):  # every board point approximated: none exact, none empty
                    continue
                raw = render_raw(mi, scene, progress=False)
                expected = output.project(boards.chessboard_corners_world(board))
                result = synthesis.apply(raw)
                truth = _board_depth(board, output)
                values, keep = synthesis.rays.values(raw)
                true_image, _ = render_given_depth(synthesis.rays, values, output, truth, synthesis.options, keep=keep)
                true_image = np.where((result.classes == 3)[..., None], true_image, result.image)
                values_air, keep_air = straight.values(raw)
                air = estimate_depth(straight, values_air, output, synthesis.options, keep=keep_air)
                classic = warp.apply(raw)
                found = {
                    name: boards.find_corners(np.nan_to_num(image))
                    for name, image in (
                        ("classic", classic),
                        ("depth_aware", result.image),
                        ("true_depth", true_image),
                    )
                }
                on_board = mask & np.isfinite(result.depth.depth_m)
                error = (result.depth.depth_m - truth)[on_board]
                relative = np.abs(error) / truth[on_board]
                kept = np.abs(error) <= np.quantile(np.abs(error), 0.95)
                disparity = output.focal_px * baseline / result.depth.depth_m
                scores = hci_scores(disparity, output.focal_px * baseline / truth, mask=mask, boundary_px=0)
                row = {
                    "where": "outside",
                    "port_mm": 40,
                    "tilt_deg": tilt,
                    "direction": direction,
                    "depth_m": depth,
                    **{
                        f"{name}_px": np.nan if f is None else boards.corner_rms_px(f, expected)
                        for name, f in found.items()
                    },
                    "depth_median_mm": 1e3 * float(np.median(error)),
                    "depth_rms_mm": 1e3 * float(np.sqrt(np.mean(error[kept] ** 2))),
                    "depth_rms_pct": 100 * float(np.sqrt(np.mean((error[kept] / depth) ** 2))),
                    "depth_off_5pct": float(np.mean(relative > 0.05)),
                    "no_refraction_median_mm": 1e3 * float(np.nanmedian((air.depth_m - truth)[mask])),
                    "hci_mse_x100": scores.mse_x100,
                    "hci_badpix_0_07": scores.badpix_0_07,
                    "given_depth_share": float(np.mean(result.classes[mask] == 3)),
                }
                rows.append(row)
                print({k: round(v, 3) if isinstance(v, float) else v for k, v in row.items()}, flush=True)
                if out is not None:
                    _board_figure(out, row, result, truth, mask, classic)
    _corner_summary(rows)
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        keys = list(dict.fromkeys(k for row in rows for k in row))
        with open(out / "corners.csv", "w", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=keys)
            writer.writeheader()
            writer.writerows(rows)
        print(f"wrote {out / 'corners.csv'}")


def _corner_summary(rows: list[dict]) -> None:
    def rms(values) -> str:
        v = np.asarray([x for x in values if np.isfinite(x)])
        return f"{np.sqrt(np.mean(v**2)):.3f} px ({v.size} boards)" if v.size else "none found"

    inside = [r for r in rows if r["where"] == "inside"]
    outside = [r for r in rows if r["where"] == "outside"]
    print(f"inside the exact coverage (12 mm port), the paper's synthesis: {rms(r['classic_px'] for r in inside)}")
    for name in ("classic", "depth_aware", "true_depth"):
        print(f"outside (40 mm port), {name}: {rms(r[f'{name}_px'] for r in outside)}")
    for depth in sorted({r["depth_m"] for r in outside}):
        sel = [r for r in outside if r["depth_m"] == depth]
        print(
            f"  {depth:g} m: classic {rms(r['classic_px'] for r in sel)}, depth-aware "
            f"{rms(r['depth_aware_px'] for r in sel)}, true depth {rms(r['true_depth_px'] for r in sel)}; depth median "
            f"{np.median([r['depth_median_mm'] for r in sel]):.1f} mm, RMS "
            f"{np.median([r['depth_rms_mm'] for r in sel]):.1f} mm "
            f"({np.median([r['depth_rms_pct'] for r in sel]):.2f} %), off > 5 %: "
            f"{np.median([r['depth_off_5pct'] for r in sel]):.1%}; without refraction handling median "
            f"{np.median([r['no_refraction_median_mm'] for r in sel]):.0f} mm; HCI MSE x100 "
            f"{np.median([r['hci_mse_x100'] for r in sel]):.3g}, BadPix(0.07) "
            f"{np.median([r['hci_badpix_0_07'] for r in sel]):.1f} % (medians over boards)"
        )


def _board_figure(out: Path, row: dict, result, truth: np.ndarray, mask: np.ndarray, classic: np.ndarray) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    lo, hi = float(np.min(truth[mask])) * 0.9, float(np.max(truth[mask])) * 1.1
    fig, axes = plt.subplots(1, 4, figsize=(17, 3.8))
    white = float(np.nanpercentile(result.image, 99.5)) or 1.0
    for ax, image, title in (
        (axes[0], classic, f"paper's synthesis: corners {row['classic_px']:.2f} px RMS"),
        (axes[1], result.image, f"depth-aware: corners {row['depth_aware_px']:.2f} px RMS"),
    ):
        ax.imshow(np.clip(np.nan_to_num(image) / white, 0, 1) ** (1 / 2.2), cmap="gray")
        ax.set_title(title, fontsize=9)
        ax.set_axis_off()
    shown = axes[2].imshow(np.where(mask, result.depth.depth_m, np.nan), vmin=lo, vmax=hi, cmap="viridis")
    axes[2].set_title("depth from the light field on the board", fontsize=9)
    fig.colorbar(shown, ax=axes[2], label="depth (m)")
    error = axes[3].imshow(
        np.where(mask, 1e3 * (result.depth.depth_m - truth), np.nan), cmap="coolwarm", vmin=-30, vmax=30
    )
    axes[3].set_title("depth error on the board", fontsize=9)
    fig.colorbar(error, ax=axes[3], label="estimated - true depth (mm)")
    for ax in axes[2:]:
        ax.set_axis_off()
    fig.suptitle(
        f"tiny-2x, port 40 mm / 4 mm glass, tilt {row['tilt_deg']} deg, board at {row['depth_m']} m on line of sight "
        f"{row['direction']}, outside the exact coverage",
        fontsize=10,
    )
    tilt, direction = row["tilt_deg"], row["direction"]
    name = f"board_tilt{tilt[0]:g}_{tilt[1]:g}_dir{direction[0]:g}_{direction[1]:g}_z{row['depth_m']:g}.png"
    fig.savefig(out / name, dpi=100, bbox_inches="tight")
    plt.close(fig)


def timing(args: argparse.Namespace) -> None:
    import numba

    from lfrefract import camera_preset
    from lfrefract.synthesis.depth_aware import DepthAwareSynthesis, trace_scene_rays
    from lfrefract.synthesis.warp_map import build_warp_map
    from simulator.experiments.fov import reference_port

    camera = camera_preset(args.camera)
    port = reference_port()
    # Compile the kernels on the tiny camera first.
    tiny = camera_preset("tiny")
    small = DepthAwareSynthesis.build(tiny, port)
    small.apply(np.ones((tiny.sensor.height_px, tiny.sensor.width_px, 3), dtype=np.float32))
    start = time.perf_counter()
    warp = build_warp_map(camera, port)
    map_s = time.perf_counter() - start
    start = time.perf_counter()
    rays = trace_scene_rays(camera, port)
    rays_s = time.perf_counter() - start
    synthesis = DepthAwareSynthesis(warp=warp, rays=rays)
    z = 0.5
    o, d = rays.origins_cam.astype(np.float64), rays.directions_cam.astype(np.float64)
    x = o + ((z - o[:, 2]) / d[:, 2])[:, None] * d
    raw = np.zeros(rays.raw_shape[0] * rays.raw_shape[1], dtype=np.float32)
    raw[rays.raw_index] = _texture(x[:, 0], x[:, 1]) / rays.gain
    raw = np.repeat(raw.reshape(rays.raw_shape)[..., None], 3, axis=2)
    del o, d, x
    warp.apply(raw)
    apply_ms = []
    for _ in range(args.frames):
        start = time.perf_counter()
        warp.apply(raw)
        apply_ms.append(1e3 * (time.perf_counter() - start))
    frame_s = []
    for _ in range(args.frames):
        start = time.perf_counter()
        result = synthesis.apply(raw)
        frame_s.append(time.perf_counter() - start)
    out = warp.output
    vv, uu = np.mgrid[0 : out.height_px, 0 : out.width_px]
    truth = _texture((uu - out.cx_px) / out.focal_px * z, (vv - out.cy_px) / out.focal_px * z)
    given = result.classes == 3
    approximated = warp.filled_classes == 1
    error = result.depth.depth_m[given] - z
    classic = warp.apply(raw)[..., 0]
    print(
        f"{platform.processor() or platform.machine()}, {numba.get_num_threads()} threads; camera {camera.name}, "
        f"raw {camera.sensor.width_px} x {camera.sensor.height_px}, output {out.width_px} x {out.height_px}, "
        f"reference port"
    )
    print(f"paper's method: build {map_s:.1f} s, apply {np.median(apply_ms):.0f} ms per frame")
    print(
        f"depth-aware: build (rays) {rays_s:.1f} s + the warp map, {len(rays.raw_index) / 1e6:.1f} M rays; "
        f"apply {np.median(frame_s):.1f} s per frame ({args.frames} frames: {', '.join(f'{t:.1f}' for t in frame_s)} s)"
    )
    print(
        f"coverage: {result.coverage}; depth on the plane at {z} m (exact-given-depth pixels): median "
        f"{1e3 * np.median(error):.2f} mm, within 1 %: {np.mean(np.abs(error) < 0.01 * z):.1%}; image RMS error "
        f"against the texture (0.1-0.9): {np.sqrt(np.mean((result.image[given][:, 0] - truth[given]) ** 2)):.4f} "
        f"given depth, {np.sqrt(np.mean((classic[approximated] - truth[approximated]) ** 2)):.4f} for the paper's "
        "approximated pixels"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="what", required=True)
    c = sub.add_parser("corners", help="rendered chessboards outside the exact coverage (tiny-2x)")
    c.add_argument("--out", help="folder for corners.csv and the figures (created; nothing else is written)")
    c.add_argument("--spp", type=int, default=16, help="samples per pixel of the renders")
    c.set_defaults(run=corners)
    t = sub.add_parser("timing", help="build and apply times beside the paper's method")
    t.add_argument("--camera", default="illum", help="camera preset")
    t.add_argument("--frames", type=int, default=2, help="frames timed")
    t.set_defaults(run=timing)
    args = parser.parse_args()
    args.run(args)


if __name__ == "__main__":
    main()
