"""What today's core does when the camera has a real main lens but the core assumes the thin lens.

Renders the chessboard set-ups of the corner tests (``tests/simulator/test_synthesis_corners.py``:
the tiny-2x camera, a 7 x 5 board at 0.15 m and 0.6 m, a straight port and one tilted 26.8 deg)
through the thin lens and through each real lens that fits in front of the port, synthesizes the
refraction-free image with the thin-lens warp map (the paper's k = 32), finds the corners and
prints their RMS error against the pinhole projections of the true corners, pixels. The gap
between the rows is what calibrating the real lens from the data has to close.

    python benchmarks/measure_real_lens_gap.py
"""

from __future__ import annotations

import argparse
import sys

from lfrefract.errors import ParameterError
from lfrefract.optics import LENS_PRESETS
from lfrefract.synthesis.warp_map import PAPER_K, SynthesisOptions, build_warp_map
from simulator import boards
from simulator.backend import load_mitsuba
from simulator.boards import chessboard_corners_world
from simulator.config import main_lens
from simulator.job import render_raw

TILTS = {(0.0, 0.0): (0.0, 0.0), (25.0, 10.0): (0.16, -0.125)}
DEPTHS_M = (0.15, 0.6)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--lenses", nargs="*", default=["thin", *LENS_PRESETS])
    args = parser.parse_args()
    mi = load_mitsuba()
    print("| port tilt (x, y), deg | board depth, m | main lens | corner RMS, px |")
    print("| --- | ---: | --- | ---: |")
    for tilt, sight in TILTS.items():
        empty = boards.empty_scene(tilt)
        warp = build_warp_map(empty.camera, empty.port, options=SynthesisOptions(k=PAPER_K))
        for depth_m in DEPTHS_M:
            config = boards.board_scene(tilt, boards.slanted_board(depth_m, sight, warp.output.focal_px))
            expected = warp.output.project(chessboard_corners_world(config.objects[0]))
            for name in args.lenses:
                try:
                    scene = config.with_overrides(lens=main_lens(name, config.camera))
                except ParameterError as exc:  # a long lens does not fit behind the 12 mm port
                    print(f"| {tilt[0]:g}, {tilt[1]:g} | {depth_m:g} | {name} | does not fit ({str(exc)[:60]}...) |")
                    continue
                found = boards.find_corners(warp.apply(render_raw(mi, scene, progress=False)))
                rms = "board not found" if found is None else f"{boards.corner_rms_px(found, expected):.3f}"
                print(f"| {tilt[0]:g}, {tilt[1]:g} | {depth_m:g} | {name} | {rms} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
