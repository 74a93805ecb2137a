"""Light-field corners located on real-lens renders against where the lens's true rays put them.

The calibrations see a board through its corners' tracks across the aperture
(:func:`lfrefract.calibration.board_view_from_light_field`: each corner at the aperture's centre and at
four points on its axes). This script takes the board renders an ``lfsim experiment pipeline --renders
DIR`` run kept (in air and behind its port), locates their corners from the Lytro captures exactly as
``lfrefract calibrate camera`` / ``calibrate port`` do (developed with the camera's white image), and
compares them with the pixels whose true rays (the lens traced, :func:`simulator.lens_family.truth_model`
in the simulator's frame, through the render's true port) pass the true corners. It prints, per aperture
point, the mean error (px) over boards, and the error along the aperture offset as a share of the
parallax (the corner's move from the centre view): a located track that is flatter than the truth
shows a negative bias. With ``--port``, the port is also calibrated from the located port boards on the
lens's true rays, so that the corners' share of a port's error is seen apart from the camera model's.

The camera is the thin-lens camera with the lens's micro-image lattice (what ``calibrate mla`` finds);
the rays are the lens's chief rays of every 2nd pixel fitted by a polynomial of capacity (7, 7)
(0.03 um and 0.009 mrad RMS from the chief rays of other pixels on the double Gauss). The reference
must be that close: a fit of capacity (7, 3) (0.6 um, 0.076 mrad) moves the expected parallax of the
in-air boards by about 1 %, as much as the bias this script looks for. The in-air boards are read as
``calibrate camera`` reads them (``--colour``, default the grey mosaic), the port boards as the grey
mosaic.

    python benchmarks/measure_corner_bias.py RENDERS --lens double-gauss [--camera-name left] [--boards 0 2 4] [--port]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from lfrefract import virtual_camera_for
from lfrefract.calibration import board_view_from_light_field
from lfrefract.calibration.camera import corrected_view
from lfrefract.calibration.port import calibrate_port
from lfrefract.formats.capture import port_from_file, read_capture
from lfrefract.optics.camera_model import BOARD_COLOURS
from simulator.boards import chessboard_corners_world
from simulator.config import Chessboard, Placement
from simulator.lens_family import slopes_seeing, truth_model

#: Inner corners of the pipeline's boards (its 7 x 5 squares).
PATTERN = (6, 4)


def _board(meta: dict) -> Chessboard:
    table = meta["scene"]["objects"][0]
    placement = table["placement"]
    return Chessboard(
        placement=Placement(
            position_m=tuple(placement["position_m"]), rotation_xyz_deg=tuple(placement["rotation_xyz_deg"])
        ),
        squares=tuple(table["squares"]),
        square_size_m=table["square_size_m"],
        margin_squares=table["margin_squares"],
    )


def _pixels(truth, view, a: np.ndarray, corners: np.ndarray, port) -> np.ndarray:
    """View pixels (N, 2) from aperture point ``a`` (2,) whose true rays pass ``corners`` (N, 3)."""
    t = slopes_seeing(truth, np.tile(a, (len(corners), 1)), corners, port)
    return np.column_stack([t, np.ones(len(t))]) @ view.K.T[:, :2]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("renders", type=Path, help="the --renders folder of an lfsim experiment pipeline run")
    parser.add_argument("--lens", required=True, help="the run's --lens (a preset or a lens file)")
    parser.add_argument("--camera-preset", default="tiny-2x", help="the rig cameras' preset (tiny: tiny-2x)")
    parser.add_argument("--camera-name", default="left")
    parser.add_argument("--boards", type=int, nargs="*", default=None, help="board numbers (default: all)")
    parser.add_argument("--port", action="store_true", help="also calibrate the port on the true rays")
    parser.add_argument(
        "--colour", choices=BOARD_COLOURS, default="cfa", help="how the in-air boards are read (as calibrate camera)"
    )
    args = parser.parse_args()
    root = args.renders / "renders"
    camera, truth = truth_model(args.lens, camera=args.camera_preset, capacity=(7, 7), calibration_frame=False)
    view = virtual_camera_for(camera)
    white = root / "whites" / args.camera_name
    located_port = []
    true_port = None
    for kind in ("air", "port"):
        folders = sorted((root / kind / args.camera_name).glob("board-*[0-9]"), key=lambda p: int(p.name.split("-")[1]))
        if args.boards is not None:
            folders = [f for f in folders if int(f.name.split("-")[1]) in args.boards]
        rows = []
        for folder in folders:
            meta = json.loads((folder / "meta.json").read_text())
            board = _board(meta)
            corners = chessboard_corners_world(board)
            port = port_from_file(folder / "meta.json") if kind == "port" else None
            true_port = port or true_port
            capture = read_capture(folder / "capture.lfr", camera=camera, white=str(white))
            grey = kind == "port" or args.colour == "cfa"
            raw = capture.developed.grey() if grey else capture.developed.measured()
            found = board_view_from_light_field(
                camera, raw, pattern=PATTERN, square_size_m=board.square_size_m, view=view, name=str(folder)
            )
            if found is None:
                print(f"{folder}: board not located", file=sys.stderr)
                continue
            if kind == "port":
                located_port.append(found)
            a_all = found.centres_m[:, :2]
            centre = _pixels(truth, view, np.zeros(2), corners, port)
            for a in np.unique(a_all, axis=0):
                got = found.corners_px[np.all(a_all == a, axis=1)]
                expected = _pixels(truth, view, a, corners, port)
                nearest = np.linalg.norm(got[:, None] - expected[None], axis=2).argmin(axis=1)
                error = got - expected[nearest]
                parallax = expected[nearest] - centre[nearest]
                axis = int(np.argmax(np.abs(a))) if np.any(a) else -1
                along = np.nan if axis < 0 else float(np.mean(error[:, axis] * np.sign(a[axis])))
                share = np.nan if axis < 0 else float(np.mean(error[:, axis] / parallax[:, axis]))
                rows.append((a * 1e3, error.mean(axis=0), np.sqrt(np.mean(np.sum(error**2, axis=1))), along, share))
        print(f"\n{kind} boards ({len(folders)}), {args.lens}, camera {args.camera_name}:")
        print("| aperture point, mm | mean error x, y, px | RMS px | along the offset, px | share of the parallax |")
        print("| --- | --- | ---: | ---: | ---: |")
        points = np.array([r[0] for r in rows])
        for a in np.unique(points, axis=0):
            sel = [r for r in rows if np.array_equal(r[0], a)]
            mean = np.mean([r[1] for r in sel], axis=0)
            rms = float(np.sqrt(np.mean([r[2] ** 2 for r in sel])))
            along = np.mean([r[3] for r in sel])
            share = np.mean([r[4] for r in sel])
            print(
                f"| ({a[0]:+.2f}, {a[1]:+.2f}) | ({mean[0]:+.4f}, {mean[1]:+.4f}) | {rms:.4f} | {along:+.4f} | "
                f"{share * 100:+.2f} % |"
            )
    if args.port and located_port and true_port is not None:
        on_truth = [corrected_view(v, truth, view) for v in located_port]
        fit = calibrate_port(
            view,
            on_truth,
            thickness_m=true_port.thickness_m,
            n_water=true_port.n_water,
            n_glass=true_port.n_glass,
            max_normal_std_deg=90.0,
            max_distance_std_m=1.0,
        )
        angle = np.degrees(np.arccos(np.clip(fit.port.normal @ true_port.normal, -1.0, 1.0)))
        print(
            f"\nport on the true rays from {len(on_truth)} located boards: normal {angle:.3f} deg off "
            f"(stated {fit.normal_std_deg:.3f}), distance {(fit.port.distance_m - true_port.distance_m) * 1e3:+.2f} mm "
            f"(stated {fit.distance_std_m * 1e3:.2f}), residual {fit.rms_px:.3f} px"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
