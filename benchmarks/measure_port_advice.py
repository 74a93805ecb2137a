"""The port calibration's advice on renders: do the views it advises lower the port's error?

``lfrefract calibrate port`` says what its views leave poorly determined and which board views to
add (:func:`lfrefract.calibration.advice.advise_port_views`). This script takes one camera of a kept
``lfsim experiment pipeline --renders DIR`` run, and for each K of ``--first``:

1. calibrates the port from the run's first K port boards as ``lfrefract calibrate port --camera
   camera.json`` does (the run's in-air camera calibration, its uncertainty in the port's; with
   ``--refine-camera``, as ``calibrate port --refine-camera``: the ray model refined with the port
   where held-back boards accept it, the pipeline's data-only chain);
2. takes the advice (``--count`` views at most) and renders the advised views: boards like the run's
   (the squares of its board seen nearest the advised depth, as the advice assumes) at the advised
   poses, behind the same wall, through the same camera, lens and sensor model, with the run's samples
   per pixel and frames (:func:`simulator.experiments.pipeline.port_board_scene`,
   :func:`simulator.boards.advised_board_table`);
3. calibrates the port again from K + the advised views and from K + as many "alike" views: the run's
   next port boards (K, K + 1, ...), the kind of views the user was already taking.

It prints, for each set (cumulatively, one added view at a time), the normal's error (deg) and the
distance's (mm, signed) against the true port (the port boards' scene, seen from where the
calibration puts the camera: a real lens's entrance pupil) beside the standard
deviations the calibration states and the advice predicted. The corners are located as ``calibrate
port`` locates them (the capture's grey mosaic developed with the camera's white image, corners in the
light field). Calibrations are not refused for their spread (limits 90 deg, 1 m): the point is their error.

Before rendering it rebuilds the run's first port board's scene and checks that it is the scene the
run rendered (its kept record's signature), so that the new boards are exactly like the run's. Renders
are kept under ``--work`` (rendered again only if their scene changed).

    python benchmarks/measure_port_advice.py RUN --camera-name left --first 6 8 --work DIR [--refine-camera]

``RUN`` is the pipeline's ``--out`` folder (its ``meta.json`` names the ``--renders`` folder, the options,
the boards' samples per pixel and frames; ``calibration/<camera>/camera.json`` is the camera's in-air
calibration).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lfrefract.calibration import BoardView, board_view_from_light_field, calibrate_port, calibrate_port_and_camera
from lfrefract.calibration.advice import AdvisedView, PortAdvice, advise_port_views
from lfrefract.calibration.camera import corrected_view
from lfrefract.calibration.port import PortCalibration, normal_std_deg
from lfrefract.formats.capture import camera_model_from_option, read_capture
from lfrefract.formats.jsonio import read_json
from lfrefract.optics.camera_model import CameraModel
from lfrefract.optics.pinhole import PinholeCamera, virtual_camera_for
from lfrefract.optics.port import FlatPort
from simulator.boards import PATTERN, advised_board_table
from simulator.config import SceneConfig
from simulator.experiments import ExperimentOptions
from simulator.experiments.kept import kept_render, record_path
from simulator.experiments.pipeline import port_board_scene, scene_signature
from simulator.job import LFR_NAME, render_job

#: Seeds of the advised boards' renders: this plus a hash of the board (the pipeline's seeds are small).
ADVISED_SEED_BASE = 1_000_000
#: The calibrations' limits on the stated spread: never refused (the error is what is measured).
LOOSE = {"max_normal_std_deg": 90.0, "max_distance_std_m": 1.0}


@dataclass(frozen=True)
class Board:
    """One located port board: its name, its views' corners, its square (m) and the capture's folder."""

    name: str
    view: BoardView
    square_size_m: float
    folder: Path


@dataclass(frozen=True)
class Fit:
    """A port calibration of a set of boards, with the views the advice is given on."""

    calibration: PortCalibration
    refined: bool


def _table_of(meta: dict) -> dict:
    """The board table of a kept port board's ``meta.json`` (its scene's one chessboard)."""
    board = meta["scene"]["objects"][0]
    return {
        "type": "chessboard",
        "position_m": board["placement"]["position_m"],
        "rotation_xyz_deg": board["placement"]["rotation_xyz_deg"],
        "squares": board["squares"],
        "square_size_m": board["square_size_m"],
    }


def _locate(model: CameraModel, view: PinholeCamera, folder: Path, white: Path, square_m: float) -> BoardView | None:
    """The board's corners in a capture's light field, as ``calibrate port`` locates them (grey mosaic)."""
    capture = read_capture(folder / LFR_NAME, camera=model.camera, white=str(white))
    return board_view_from_light_field(
        model.camera, capture.developed.grey(), pattern=PATTERN, square_size_m=square_m, view=view, name=str(folder)
    )


def _calibrate(model: CameraModel, view: PinholeCamera, boards: list[Board], true: FlatPort, *, refine: bool) -> Fit:
    """The port from ``boards`` as ``calibrate port --camera`` does (``refine``: ``--refine-camera``)."""
    glass = {
        "thickness_m": true.thickness_m,
        "n_air": true.n_air,
        "n_glass": true.n_glass,
        "n_water": true.n_water,
        "names": [b.name for b in boards],
        **LOOSE,
    }
    views = [b.view for b in boards]
    if refine:
        joint = calibrate_port_and_camera(view, views, prior=model.estimate(), **glass)
        if joint.accepted:
            return Fit(joint.port, True)
    spread = [[corrected_view(v, moved, view) for v in views] for moved in model.spread_corrections()]
    corrected = [corrected_view(v, model.correction, view) for v in views]
    return Fit(calibrate_port(view, corrected, model_views=spread, **glass), False)


def _errors(calibration: PortCalibration, true: FlatPort) -> tuple[float, float]:
    """(normal error, deg; distance error, mm signed) against the true port."""
    cos = float(np.clip(calibration.port.normal @ true.normal, -1.0, 1.0))
    return math.degrees(math.acos(cos)), (calibration.port.distance_m - true.distance_m) * 1e3


def _like_square(advised: AdvisedView, calibration: PortCalibration, boards: list[Board]) -> float:
    """The square of the board the advice took its candidate like: the one seen nearest its depth."""
    depths = np.array([pose.position_m[2] for pose in calibration.board_poses])
    return boards[int(np.argmin(np.abs(depths - advised.centre_m[2])))].square_size_m


def _render_advised(
    options: ExperimentOptions, camera_name: str, table: dict, work: Path, *, spp: int, frames: int
) -> tuple[Path, float]:
    """Render (or reuse) the board ``table`` as the run renders its port boards; (folder, seconds spent)."""
    key = zlib.crc32(json.dumps(table, sort_keys=True).encode())
    seed = ADVISED_SEED_BASE + key % 1_000_000
    config = port_board_scene(options, camera_name, table, seed=seed, spp=spp, frames=frames)
    folder = work / "renders" / camera_name / f"advised-{key:08x}"
    folder.parent.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    kept_render(
        folder,
        scene_signature(config),
        lambda: render_job(config, folder, progress=False, write_previews=False, write_lfr=True, overwrite=True),
    )
    return folder, time.perf_counter() - start


def _row(label: str, fit: Fit, true: FlatPort, predicted: tuple[float, float] | None) -> str:
    """A table row: errors, stated and predicted standard deviations, the camera model's part, residual."""
    normal, distance = _errors(fit.calibration, true)
    c = fit.calibration
    model = c.covariance_parts.get("camera_model", np.zeros((3, 3)))
    guess = "-" if predicted is None else f"{predicted[0]:.3f}"
    guess_d = "-" if predicted is None else f"{predicted[1] * 1e3:.2f}"
    refined = " (refined)" if fit.refined else ""
    return (
        f"| {label}{refined} | {normal:.3f} | {c.normal_std_deg:.3f} | {guess} | {normal_std_deg(c.port, model):.3f} | "
        f"{distance:+.2f} | {c.distance_std_m * 1e3:.2f} | {guess_d} | {c.rms_px:.4f} |"
    )


def _check_same_scenes(
    options: ExperimentOptions, camera_name: str, folder: Path, spp: int, frames: int
) -> SceneConfig:
    """The scene of the run's board in ``folder``, rebuilt; refuse to go on unless it is the scene it
    was rendered from."""
    meta = read_json(folder / "meta.json")
    config = port_board_scene(
        options, camera_name, _table_of(meta), seed=int(meta["render"]["seed"]), spp=spp, frames=frames
    )
    kept = read_json(record_path(folder))["signature"]
    if json.loads(json.dumps(scene_signature(config))) != kept:
        raise SystemExit(
            f"{folder}: the pipeline builds another scene today than the run rendered (compare "
            f"{record_path(folder)} with scene_signature(port_board_scene(...))): new boards would not be like "
            "its boards"
        )
    print(f"{folder.name}'s scene rebuilt from the run's options: the one the run rendered")
    return config


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("run", type=Path, help="the --out folder of an lfsim experiment pipeline run")
    parser.add_argument("--renders", type=Path, default=None, help="its --renders folder (default: its meta.json's)")
    parser.add_argument("--camera-name", default="left")
    parser.add_argument("--first", type=int, nargs="+", default=[8], help="K: calibrate from the first K boards")
    parser.add_argument("--count", type=int, default=3, help="advised (and alike) views to add, at most")
    parser.add_argument("--target-normal-std-deg", type=float, default=0.1)
    parser.add_argument("--target-distance-std-m", type=float, default=1e-3)
    parser.add_argument("--refine-camera", action="store_true", help="as calibrate port --refine-camera")
    parser.add_argument("--work", type=Path, required=True, help="where the advised views' renders are kept")
    args = parser.parse_args()
    start = time.perf_counter()
    meta = read_json(args.run / "meta.json")
    options = ExperimentOptions.from_dict(meta["options"])
    spp, frames = int(meta["parameters"]["board_spp"]), int(meta["parameters"]["board_frames"])
    root = (args.renders if args.renders is not None else Path(meta["renders_dir"])) / "renders"
    camera_name = args.camera_name
    model = camera_model_from_option(args.run / "calibration" / camera_name / "camera.json")
    view = virtual_camera_for(model.camera)
    white = root / "whites" / camera_name
    folders = sorted(
        (p for p in (root / "port" / camera_name).glob("board-*") if p.is_dir()),
        key=lambda p: int(p.name.split("-")[1]),
    )
    scene = _check_same_scenes(options, camera_name, folders[0], spp, frames)
    # the true port where the calibration puts the camera (a real lens's entrance pupil)
    true = scene.port.seen_from(scene.calibration_origin_cam)
    located: dict[int, Board | None] = {}

    def run_board(k: int) -> Board | None:
        if k not in located:
            square = float(read_json(folders[k] / "meta.json")["scene"]["objects"][0]["square_size_m"])
            found = _locate(model, view, folders[k], white, square)
            located[k] = None if found is None else Board(folders[k].name, found, square, folders[k])
            if found is None:
                print(f"{folders[k]}: board not located, left out", file=sys.stderr)
        return located[k]

    print(
        f"\ncamera {camera_name}: {meta['options']['lens']} lens, {len(folders)} port boards at {spp} spp, "
        f"{frames} frames; true port: normal {np.round(true.normal, 5).tolist()}, {true.distance_m * 1e3:.2f} mm"
    )
    rendered_s = 0.0
    for first in args.first:
        if first + args.count > len(folders):
            raise SystemExit(
                f"--first {first} leaves fewer than --count {args.count} of the run's boards as alike views"
            )
        boards = [b for k in range(first) if (b := run_board(k)) is not None]
        base = _calibrate(model, view, boards, true, refine=args.refine_camera)
        advice: PortAdvice = advise_port_views(
            view,
            base.calibration,
            [b.view for b in boards],
            target_normal_std_deg=args.target_normal_std_deg,
            target_distance_std_m=args.target_distance_std_m,
            count=args.count,
            camera_model=model,
        )
        print(f"\nK = {first} (boards 0-{first - 1}, {len(boards)} located); the advice:")
        print("\n".join(advice.lines()) or "  nothing poorly determined")
        if not advice.views:
            normal, distance = _errors(base.calibration, true)
            print(
                f"  the port from them{' (refined)' if base.refined else ''}: normal {normal:.3f} deg off (stated "
                f"{base.calibration.normal_std_deg:.3f}), distance {distance:+.2f} mm (stated "
                f"{base.calibration.distance_std_m * 1e3:.2f})"
            )
            continue
        advised: list[Board | None] = []
        for i, item in enumerate(advice.views):
            table = advised_board_table(item, _like_square(item, base.calibration, boards))
            folder, seconds = _render_advised(options, camera_name, table, args.work, spp=spp, frames=frames)
            rendered_s += seconds
            found = _locate(model, view, folder, white, table["square_size_m"])
            advised.append(None if found is None else Board(f"advised-{i + 1}", found, table["square_size_m"], folder))
            status = "located" if found is not None else "NOT located"
            print(f"  advised {i + 1}: {folder.name}, square {table['square_size_m'] * 1e3:.2f} mm, {status}")
        alike = [run_board(first + i) for i in range(len(advice.views))]
        print(
            "\n| boards | normal error, deg | stated | predicted | camera model's part | distance error, mm | stated | "
            "predicted | residual, px |"
        )
        print("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
        print(_row(f"first {first}", base, true, None))
        for i in range(1, len(advice.views) + 1):
            added = [b for b in advised[:i] if b is not None]
            predicted = (advice.views[i - 1].normal_std_deg, advice.views[i - 1].distance_std_m)
            print(
                _row(
                    f"+ advised 1-{i}",
                    _calibrate(model, view, boards + added, true, refine=args.refine_camera),
                    true,
                    predicted,
                )
            )
        for i in range(1, len(advice.views) + 1):
            added = [b for b in alike[:i] if b is not None]
            print(
                _row(
                    f"+ alike {first}-{first + i - 1}",
                    _calibrate(model, view, boards + added, true, refine=args.refine_camera),
                    true,
                    None,
                )
            )
    print(
        f"\n{rendered_s:.0f} s rendering the advised views (none where kept); "
        f"{time.perf_counter() - start:.0f} s in all"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
