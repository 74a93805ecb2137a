"""Time the board captures of a calibration command: each Lytro capture developed and its corners located.

``lfrefract calibrate camera`` and ``calibrate port`` read every board capture in turn: developed by
its white image (:func:`lfrefract.formats.capture.read_capture`), its board found in the central view
and each corner fitted on the raw pixels around it
(:func:`lfrefract.calibration.port.board_view_from_light_field`). What depends on the camera and the
white alone (the white's flat field, the light-field samples and their k-d tree, the central view's
resampling matrix) is built by the first capture and reused by the next, so the first capture
costs more. This script prints both, per capture and as the ratio of the first to the median of
the others, measured in the same process (machines differ; the ratio travels)::

    python benchmarks/bench_board_captures.py BOARD.lfr ... --camera mla.json --white WHITES/ \\
        --squares 7 5 --square-size-m S [S ...] [--colour demosaic|cfa]

``--camera``, ``--white``, ``--squares`` and ``--square-size-m`` as for ``lfrefract calibrate camera``;
``--colour`` the board image read (``demosaic``: the camera calibration's, ``cfa``: the port
calibration's).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time

from lfrefract.calibration.port import board_view_from_light_field
from lfrefract.formats.capture import camera_model_from_option, read_capture
from lfrefract.optics.pinhole import virtual_camera_for


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("boards", nargs="+", help="Lytro board captures (.lfr, or .raw with metadata)")
    parser.add_argument("--camera", required=True, help="a preset or camera file (e.g. calibrate mla's output)")
    parser.add_argument("--white", required=True, help="the white image, or a folder of them")
    parser.add_argument("--squares", type=int, nargs=2, required=True, metavar=("C", "R"))
    parser.add_argument("--square-size-m", type=float, nargs="+", required=True)
    parser.add_argument("--colour", choices=("demosaic", "cfa"), default="demosaic")
    args = parser.parse_args()
    sizes = args.square_size_m * len(args.boards) if len(args.square_size_m) == 1 else args.square_size_m
    if len(sizes) != len(args.boards):
        parser.error(f"--square-size-m takes one size or one per board ({len(args.boards)}), got {len(sizes)}")
    camera = camera_model_from_option(args.camera).described_camera
    view = virtual_camera_for(camera)
    pattern = (args.squares[0] - 1, args.squares[1] - 1)
    print(
        f"{camera.name}: {camera.sensor.width_px} x {camera.sensor.height_px} px, view {view.width_px} x "
        f"{view.height_px} px; --colour {args.colour}"
    )
    print(f"{'capture':<40} {'develop s':>10} {'corners s':>10} {'total s':>10} {'corners found':>14}")
    totals = []
    for path, size in zip(args.boards, sizes, strict=True):
        start = time.perf_counter()
        capture = read_capture(path, camera=camera, white=args.white)
        raw = capture.developed.grey() if args.colour == "cfa" and capture.developed is not None else capture.raw
        developed = time.perf_counter()
        found = board_view_from_light_field(camera, raw, pattern=pattern, square_size_m=size, view=view, name=path)
        done = time.perf_counter()
        corners = 0 if found is None else len(found.corners_px) // 5
        totals.append(done - start)
        print(
            f"{path[-40:]:<40} {developed - start:>10.2f} {done - developed:>10.2f} {done - start:>10.2f} "
            f"{corners:>14d}"
        )
    if len(totals) > 1:
        rest = statistics.median(totals[1:])
        print(f"first capture {totals[0]:.2f} s, each next {rest:.2f} s (median): {totals[0] / rest:.1f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
