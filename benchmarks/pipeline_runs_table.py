"""The data-only chain on several ``lfsim experiment pipeline`` runs, one line each: the lens-family table.

For each run folder (an ``lfsim experiment pipeline --out`` folder) it prints the lens and where a
calibration puts the camera (the lens's paraxial entrance pupil, from the simulator's camera origin,
mm), each camera's ray model, the data-only chain's rays against the true ones at the port face, its
test-board corners, plane RMSE and error against the true plane as multiples of the oracle's (with
each synthesis method the run used: ``--methods``) and of the true-rays chain's (the same real
captures synthesized with the lens traced and the true port: the calibration's own share), the
share of the test-board corners each renders exactly (where the run measured it), and each
camera's port: normal and distance errors beside the standard deviations its port file states, and
the error's length in that file's covariance. Then the coverage of the stated uncertainty over every
data-only port of the runs: the share whose normal and distance errors each lie within three stated standard deviations.

    python benchmarks/pipeline_runs_table.py RUN [RUN ...]

All figures are the runs' own (``table.csv``, ``ports.csv``, ``meta.json``); the entrance pupil is
recomputed from the run's options (:attr:`simulator.config.SceneConfig.calibration_origin_cam`).
"""

from __future__ import annotations

import argparse
import csv
import math
from pathlib import Path

from lfrefract.formats.jsonio import read_json
from simulator.experiments import ExperimentOptions
from simulator.experiments.pipeline import real_rig, row_label, setup_for_pipeline


def _rows(path: Path) -> list[dict]:
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


def _ratio(rows: dict, chain: str, synthesis: str, key: str) -> str:
    """``chain``'s ``key`` for ``synthesis``, with its ratio to the oracle's and to the true-rays chain's
    (the real captures with the lens traced: what a perfect calibration gives on them), where known."""
    value = float(rows.get(row_label(chain, synthesis), {}).get(key, "nan"))
    if not math.isfinite(value):
        return "-"
    ratios = []
    for reference in ("oracle", "true-rays"):
        known = float(rows.get(row_label(reference, synthesis), {}).get(key, "nan"))
        ratios.append(f"{value / known:.2f}x" if math.isfinite(known) and known > 0 else "-")
    return f"{value:.3f} ({' / '.join(ratios)})"


def _exact_share(rows: dict, synthesis: str) -> str:
    """The share of the test-board corners the data-only and the true-rays chains render exactly."""
    shares = []
    for chain in ("data-only", "true-rays"):
        value = float(rows.get(row_label(chain, synthesis), {}).get("corners_exact_share", "nan") or "nan")
        shares.append(f"{100 * value:.0f} %" if math.isfinite(value) else "-")
    return f"{shares[0]} ({shares[1]})"


def _short(error: str, limit: int = 160) -> str:
    """The first ``limit`` characters of a row's error (its first camera's, where both failed alike)."""
    return error if len(error) <= limit else error[: limit - 3] + "..."


def _lens_name(options: dict) -> str:
    lens = options.get("lens")
    if isinstance(lens, dict):
        return str(lens.get("name", "lens file"))
    return str(lens or "double-gauss")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("runs", type=Path, nargs="+", help="lfsim experiment pipeline --out folders")
    args = parser.parse_args()
    header = (
        "| lens | pupil z, mm | ray model | rays at the port, mm (aligned along the axis, shift mm) / mrad | synthesis "
        "| corners, px (x oracle / x true rays) | plane RMSE, mm (x oracle / x true rays) "
        "| error to the true plane, mm (x oracle / x true rays) | corners rendered exactly (true rays) | status |"
    )
    lines = [header, "|" + " --- |" * 10]
    port_lines = [
        "| lens | camera | normal error, deg (stated) | distance error, mm (stated) | error / stated covariance |",
        "|" + " --- |" * 5,
    ]
    covered, total = 0, 0
    for run in args.runs:
        meta = read_json(run / "meta.json")
        options = ExperimentOptions.from_dict(meta["options"])
        real = real_rig(setup_for_pipeline(options.scale), options)
        pupil = ", ".join(f"{c.scene.calibration_origin_cam[2] * 1e3:+.2f}" for c in real.cameras[:1])
        rows = {row["method"]: row for row in _rows(run / "table.csv")}
        name = _lens_name(meta["options"])
        syntheses = meta["parameters"].get("syntheses", ["proposed"])
        data = rows.get("data-only", {})
        rays = "-"
        if data and math.isfinite(float(data["ray_rms_mm"])):
            aligned = data.get("ray_rms_aligned_mm", "nan")  # runs before the aligned measure: nan
            shift = data.get("frame_shift_mm", "nan")
            rays = (
                f"{float(data['ray_rms_mm']):.3f} ({float(aligned):.3f}, {float(shift):+.2f}) "
                f"/ {float(data['ray_angle_mrad']):.3f}"
            )
        for synthesis in syntheses:
            row = rows.get(row_label("data-only", synthesis), {})
            cells = [
                name,
                pupil,
                str(row.get("ray_model", "-")),
                rays,
                synthesis,
                _ratio(rows, "data-only", synthesis, "corner_rms_px"),
                _ratio(rows, "data-only", synthesis, "plane_rmse_mm"),
                _ratio(rows, "data-only", synthesis, "truth_error_mm"),
                _exact_share(rows, synthesis),
                str(row.get("status", "-"))
                + (f": {_short(row['error'])}" if row.get("error") else "")
                + f" (true rays: {rows.get(row_label('true-rays', synthesis), {}).get('status', '-')})",
            ]
            lines.append("| " + " | ".join(cells) + " |")
        ports = run / "ports.csv"
        for port in _rows(ports) if ports.is_file() else []:
            if port["method"] != "data-only":
                continue
            normal, normal_std = float(port["port_normal_err_deg"]), float(port["port_normal_std_deg"])
            distance, distance_std = float(port["port_distance_err_mm"]), float(port["port_distance_std_mm"])
            total += 1
            covered += normal <= 3 * normal_std and abs(distance) <= 3 * distance_std
            port_lines.append(
                f"| {name} | {port['camera']} | {normal:.3f} ({normal_std:.3f}) | {distance:+.2f} ({distance_std:.2f}) "
                f"| {float(port['port_error_sigmas']):.2f} |"
            )
    print("\n".join(lines))
    print()
    print("\n".join(port_lines))
    if total:
        print(f"\nports within three stated standard deviations (normal and distance): {covered} of {total}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
