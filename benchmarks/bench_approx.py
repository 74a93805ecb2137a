"""Measure the approximation baseline against the proposed synthesis: corner RMS by method, port tilt, depth.

    python benchmarks/bench_approx.py                      # seeds 0-2, the table of docs/calibration.md
    python benchmarks/bench_approx.py --seeds 0 --depths 0.2 0.6

The set-up of tests/simulator/test_approx_baseline.py (its scenes come from
simulator/boards.py): the tiny camera at twice its focal length and sensor
(188 x 141 px refraction-free image, f = 240 px), a port 12 mm away with 4 mm of glass, tilted
0 or 26.8 deg, 16 spp. ``approx@D`` is calibrated from 6 board views at D metres with their 3D
corners known; ``proposed+distortion`` fits its residual distortion on the synthesized images of
the 0.2 m views. A slanted 7 x 5 test board, off the axis and inside the synthesis's exact
coverage, is rendered at each depth; the figure is the RMS distance (px) between the corners found
in each method's image and the K-projections of the ground-truth corners, as mean (min-max) over
the seeds. Needs the simulator (Mitsuba); prints a Markdown table and the timings.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from lfrefract.methods import build_projector
from simulator import boards
from simulator.backend import load_mitsuba
from simulator.boards import DIRECTIONS, STRAIGHT, TILTED, chessboard_corners_world
from simulator.job import render_raw


def measure(mi, tilt, depths, calibration_depths, seed: int) -> dict[tuple[str, float], float]:
    """Corner RMS (px) by (method label, depth) for one tilt and seed (NaN: board not found)."""
    config = boards.empty_scene(tilt)
    camera, port = config.camera, config.port
    proposed = build_projector("proposed", camera, port)
    projectors = {"naive": build_projector("naive", camera, port)}
    for depth_m in calibration_depths:
        views = boards.calibration_views(mi, tilt, depth_m, seed=seed)
        projectors[f"approx@{depth_m:g}"] = build_projector("approx", camera, port, calibration=views)
        if depth_m == calibration_depths[0]:
            projectors["proposed"] = proposed
            projectors["proposed+distortion"] = build_projector(
                "proposed+distortion", camera, port, calibration=views, warp=proposed.warp
            )
    errors = {}
    for depth_m in depths:
        scene = boards.board_scene(
            tilt, boards.slanted_board(depth_m, DIRECTIONS[tilt], proposed.output.focal_px), seed=seed
        )
        raw = render_raw(mi, scene, progress=False)
        truth = chessboard_corners_world(scene.objects[0])
        for label, projector in projectors.items():
            found = boards.find_corners(projector.apply(raw))
            errors[label, depth_m] = (
                np.nan if found is None else boards.corner_rms_px(found, projector.output.project(truth))
            )
    return errors


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--depths", type=float, nargs="+", default=[0.1, 0.15, 0.2, 0.3, 0.6, 1.0])
    parser.add_argument("--calibration-depths", type=float, nargs="+", default=[0.2, 0.6])
    parser.add_argument("--figure", help="also plot the errors against depth into this PNG")
    args = parser.parse_args(argv)
    mi = load_mitsuba("llvm_ad_rgb")
    start = time.perf_counter()
    rows = {}
    for tilt in (STRAIGHT, TILTED):
        runs = [measure(mi, tilt, args.depths, args.calibration_depths, seed) for seed in args.seeds]
        for key in runs[0]:
            rows[tilt, *key] = np.array([r[key] for r in runs])
    labels = list(dict.fromkeys(k[1] for k in rows))
    print("| method | port tilt | " + " | ".join(f"{d:g} m" for d in args.depths) + " |")
    print("| --- | --- | " + " | ".join("---" for _ in args.depths) + " |")
    for label in labels:
        for tilt in (STRAIGHT, TILTED):
            tilt_deg = np.degrees(np.arccos(np.cos(np.radians(tilt[0])) * np.cos(np.radians(tilt[1]))))
            cells = []
            for depth_m in args.depths:
                v = rows[tilt, label, depth_m]
                cells.append(f"{np.mean(v):.2f} ({np.min(v):.2f}-{np.max(v):.2f})" if len(v) > 1 else f"{v[0]:.2f}")
            print(f"| {label} | {tilt_deg:.1f} deg | " + " | ".join(cells) + " |")
    print(f"\n{len(args.seeds)} seed(s), {time.perf_counter() - start:.0f} s")
    if args.figure:
        _plot(rows, labels, args.depths, args.figure)
    return 0


def _plot(rows: dict, labels: list[str], depths: list[float], path: str) -> None:
    """Corner error against depth, one panel per port tilt (mean over seeds, bars: min-max)."""
    import matplotlib as mpl

    mpl.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4), dpi=100, sharey=True)
    for ax, tilt, title in zip(axes, (STRAIGHT, TILTED), ("port 0 deg", "port 26.8 deg"), strict=True):
        for label in labels:
            if label == "naive":
                continue
            v = np.array([rows[tilt, label, d] for d in depths])
            mean = v.mean(axis=1)
            spread = [mean - v.min(axis=1), v.max(axis=1) - mean]
            ax.errorbar(depths, mean, yerr=spread, marker="o", capsize=3, label=label)
        ax.set(xscale="log", yscale="log", xlabel="board depth [m]", title=title)
        ax.grid(alpha=0.3, which="both")
    axes[0].set_ylabel("corner error [px RMS] against the K-projection")
    axes[1].legend(fontsize=8)
    fig.suptitle("Approximation baseline (calibrated at one depth) vs the refraction-free synthesis", fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    print(f"wrote {path}")


if __name__ == "__main__":
    raise SystemExit(main())
