"""Do PlenoptiCam and lfrefract find the micro-image centres of the simulator's white images?

For each camera, renders the white image (``lfsim render white``: uniform radiance, no port) into
the work folder and forms the grey images

* ``raw``: ``raw.exr``'s channels averaged (noiseless, hard-edged micro-images);
* ``sensor``: the sensor model's white (``simulator.detector.white_frames``, the camera's detector
  preset, ``--frames`` exposures averaged), demosaiced (bilinear), channels averaged;
* ``sensor-green``: that demosaiced image's green channel (``--green``),

each clipped to [0, 1]. On each it runs PlenoptiCam (``benchmarks/plenopticam_centres.py`` under
``--plenopticam-python``: its LoG peaks, refined centroids, sorted lattice centres and fitted grid)
and lfrefract's ``calibrate_mla`` (its measured centroids of the lenses used in the fit, and its
fitted lattice centres), and matches every found centre to the nearest ground-truth micro-image
centre (``lenses.npz``, ``micro_image_centre_px``, (u, v) = (column, row) pixels with pixel
centres at integers). Printed per camera, image and method (a markdown table):

* ``found``: centres found; ``true``: true centres inside the image (within its outer pixel
  edges), and in brackets those whose whole micro-image (half the pitch around it) is inside;
* ``<= 1 px``: found centres within 1 px of a true centre; ``discs hit``: true centres that have
  such a centre; ``multi``: true centres with two or more found centres within half a pitch
  (several peaks on one disc);
* ``RMS / median / max, all``: distance of every found centre to its nearest true centre, px;
* ``RMS <= 1 px`` and ``mean du, dv``: over the found centres within 1 px (their bias, px);
* ``time``: seconds (PlenoptiCam: its driver process, start-up included).

    python benchmarks/measure_white_centres.py --work WORK --plenopticam-python PCAM/bin/python

Without ``--plenopticam-python`` only lfrefract's calibrator is measured. ``--work`` must be a
folder this script may write in (it writes only inside it); it is deleted at the end only with
``--clean`` and only if this run created it.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from lfrefract.calibration import calibrate_mla
from lfrefract.formats.exr import read_exr
from simulator.detector import DETECTOR_PRESETS, demosaic, white_frames

CAMERAS = ("tiny", "f01", "illum")
DRIVER = Path(__file__).with_name("plenopticam_centres.py")
PLENOPTICAM_STAGES = ("peaks", "refined", "sorted", "grid")


@dataclass(frozen=True)
class Scores:
    """Found micro-image centres against the ground truth of one image.

    Attributes
    ----------
    found : int
        Found centres.
    true_inside, true_full : int
        True centres inside the image; those whose whole micro-image is inside.
    within_1px : int
        Found centres within 1 px of their nearest true centre.
    discs_hit : int
        True centres with at least one found centre within 1 px.
    multi : int
        True centres with two or more found centres within half a pitch.
    rms_all_px, median_all_px, max_all_px : float
        Distance of every found centre to its nearest true centre, px (NaN if none found).
    rms_1px : float
        RMS of the distances within 1 px, px.
    bias_uv_px : tuple of float
        Mean (found - true) offset (du, dv) of the centres within 1 px, px.
    """

    found: int
    true_inside: int
    true_full: int
    within_1px: int
    discs_hit: int
    multi: int
    rms_all_px: float
    median_all_px: float
    max_all_px: float
    rms_1px: float
    bias_uv_px: tuple[float, float]


def score_centres(found_uv_px: np.ndarray, true_uv_px: np.ndarray, *, width_px: int, height_px: int) -> Scores:
    """Match found centres to the nearest true centres.

    Parameters
    ----------
    found_uv_px : ndarray, shape (N, 2)
        Found centres, (u, v) pixels; non-finite rows are dropped.
    true_uv_px : ndarray, shape (M, 2)
        True micro-image centres, (u, v) pixels (every lens of the array, on the sensor or not).
    width_px, height_px : int
        Image size.

    Returns
    -------
    Scores
    """
    found = np.asarray(found_uv_px, dtype=np.float64).reshape(-1, 2)
    found = found[np.all(np.isfinite(found), axis=1)]
    truth = np.asarray(true_uv_px, dtype=np.float64)
    tree = cKDTree(truth)
    pitch_px = float(np.median(tree.query(truth, k=2)[0][:, 1]))
    lo = np.array([-0.5, -0.5])
    hi = np.array([width_px - 0.5, height_px - 0.5])
    inside = np.all((truth >= lo) & (truth <= hi), axis=1)
    full = np.all((truth - pitch_px / 2 >= lo) & (truth + pitch_px / 2 <= hi), axis=1)
    if len(found) == 0:
        nan = float("nan")
        return Scores(0, int(inside.sum()), int(full.sum()), 0, 0, 0, nan, nan, nan, nan, (nan, nan))
    distance_px, nearest = tree.query(found)
    close = distance_px <= 1.0
    per_disc = np.bincount(nearest[distance_px < pitch_px / 2], minlength=len(truth))
    offsets = found[close] - truth[nearest[close]]
    bias = offsets.mean(axis=0) if close.any() else np.full(2, np.nan)
    return Scores(
        found=len(found),
        true_inside=int(inside.sum()),
        true_full=int(full.sum()),
        within_1px=int(close.sum()),
        discs_hit=len(np.unique(nearest[close])),
        multi=int(np.sum(per_disc >= 2)),
        rms_all_px=float(np.sqrt(np.mean(distance_px**2))),
        median_all_px=float(np.median(distance_px)),
        max_all_px=float(np.max(distance_px)),
        rms_1px=float(np.sqrt(np.mean(distance_px[close] ** 2))) if close.any() else float("nan"),
        bias_uv_px=(float(bias[0]), float(bias[1])),
    )


def render_white(camera: str, out_dir: Path, *, spp: int | None) -> Path:
    """Render ``lfsim render white --camera CAMERA`` into ``out_dir`` (replacing an earlier render there).

    Returns
    -------
    Path
        ``out_dir``.
    """
    lfsim = Path(sys.executable).with_name("lfsim")
    command = [str(lfsim) if lfsim.exists() else "lfsim", "render", "white", "--camera", camera]
    command += ["--out", str(out_dir), "--no-previews", "--quiet"]
    if spp is not None:
        command += ["--spp", str(spp)]
    if out_dir.exists() and any(out_dir.iterdir()):
        command.append("--overwrite")
    subprocess.run(command, check=True)
    return out_dir


def grey_images(raw_rgb: np.ndarray, camera: str, *, frames: int, seed: int, green: bool) -> dict[str, np.ndarray]:
    """The grey white images measured, each (H, W) float64 clipped to [0, 1].

    Parameters
    ----------
    raw_rgb : ndarray, shape (H, W, 3)
        ``raw.exr`` (radiance; a white image is 1 on the micro-images).
    camera : str
        Detector preset name (the camera's).
    frames, seed : int
        ``white_frames`` exposures averaged and seed.
    green : bool
        Add the demosaiced green channel.

    Returns
    -------
    dict of str to ndarray
        ``raw``, ``sensor`` and optionally ``sensor-green``.
    """
    images = {"raw": np.clip(raw_rgb.astype(np.float64).mean(axis=-1), 0.0, 1.0)}
    mosaic = white_frames(raw_rgb, DETECTOR_PRESETS[camera], frames=frames, seed=seed)
    rgb = demosaic(mosaic)
    images["sensor"] = np.clip(rgb.mean(axis=-1), 0.0, 1.0)
    if green:
        images["sensor-green"] = np.clip(rgb[..., 1], 0.0, 1.0)
    return images


def run_plenopticam(
    python: Path, image: np.ndarray, folder: Path, *, method: str, micro_image_px: int | None, timeout_s: float
) -> tuple[dict[str, np.ndarray], dict, float]:
    """Run the PlenoptiCam driver on one image in its own interpreter.

    ``micro_image_px`` (int or None) replaces PlenoptiCam's estimate of the micro-image size.

    Returns
    -------
    centres : dict of str to ndarray, shape (N, 2)
        Its ``peaks``, ``refined``, ``sorted`` and ``grid`` centres, (u, v) pixels.
    summary : dict
        The driver's JSON summary (``error`` says which stage failed, if one did).
    seconds : float
        Wall time of the driver process.
    """
    folder.mkdir(parents=True, exist_ok=True)
    white = folder / "white.npy"
    np.save(white, image)
    paths = {stage: folder / f"{stage}.npy" for stage in PLENOPTICAM_STAGES}
    command = [str(python), str(DRIVER), str(white), str(paths["grid"]), "--method", method]
    command += ["--peaks-out", str(paths["peaks"]), "--refined-out", str(paths["refined"])]
    command += ["--sorted-out", str(paths["sorted"]), "--summary", str(folder / "summary.json")]
    if micro_image_px is not None:
        command += ["--micro-image-px", str(micro_image_px)]
    start = time.perf_counter()
    try:
        subprocess.run(command, check=True, cwd=folder, timeout=timeout_s, capture_output=True, text=True)
    except subprocess.TimeoutExpired:
        seconds = time.perf_counter() - start
        return {}, {"error": f"timed out after {timeout_s:g} s"}, seconds
    except subprocess.CalledProcessError as error:
        seconds = time.perf_counter() - start
        return {}, {"error": f"driver failed: {error.stderr.strip().splitlines()[-1:]}"}, seconds
    seconds = time.perf_counter() - start
    summary = json.loads((folder / "summary.json").read_text())
    if method not in ("grid-fit", "vign-fit"):
        paths.pop("grid")
    return {stage: np.load(path) for stage, path in paths.items()}, summary, seconds


def run_lfrefract(image: np.ndarray) -> tuple[dict[str, np.ndarray], str | None, float]:
    """lfrefract's ``calibrate_mla`` on one image.

    Returns
    -------
    centres : dict of str to ndarray, shape (N, 2)
        ``measured`` (centroids of the lenses used in the fit) and ``fitted`` (lattice centres of
        every lens on the sensor), (u, v) pixels; empty if it failed.
    error : str or None
        Its error message, if it raised.
    seconds : float
    """
    start = time.perf_counter()
    try:
        calibration = calibrate_mla(image)
    except ValueError as error:  # ParameterError is a ValueError
        return {}, f"{type(error).__name__}: {error}", time.perf_counter() - start
    seconds = time.perf_counter() - start
    centres = {"measured": calibration.measured_px[calibration.used], "fitted": calibration.centres_px}
    return centres, None, seconds


def cpu_name() -> str:
    """The CPU model (Linux ``/proc/cpuinfo``), else ``platform.processor()`` or the architecture."""
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.exists():
        for line in cpuinfo.read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    return platform.processor() or platform.machine()


def _format(value: float, digits: int = 3) -> str:
    return "-" if not np.isfinite(value) else f"{value:.{digits}f}"


def table_row(camera: str, image: str, method: str, scores: Scores, seconds: float, note: str = "") -> str:
    """One markdown table row; ``note`` says why a method found nothing, or anything else."""
    cells = [
        str(scores.found),
        f"{scores.true_inside} ({scores.true_full})",
        str(scores.within_1px),
        str(scores.discs_hit),
        str(scores.multi),
        " / ".join(_format(v) for v in (scores.rms_all_px, scores.median_all_px, scores.max_all_px)),
        _format(scores.rms_1px),
        ", ".join(_format(v) for v in scores.bias_uv_px),
        f"{seconds:.1f}",
        note.replace("|", "/"),
    ]
    return f"| {camera} | {image} | {method} | " + " | ".join(cells) + " |"


TABLE_HEAD = (
    "| camera | image | method | found | true (full) | <= 1 px | discs hit | multi "
    "| RMS / median / max, all, px | RMS <= 1 px | mean du, dv, px | time, s | note |\n"
    "| --- | --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- |"
)


def main(argv: list[str] | None = None) -> int:
    """Command line: see ``--help``."""
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cameras", nargs="+", choices=CAMERAS, default=["tiny", "f01"])
    parser.add_argument("--frames", type=int, default=64, help="white_frames exposures averaged (default 64)")
    parser.add_argument("--seed", type=int, default=1, help="white_frames seed (default 1)")
    parser.add_argument("--spp", type=int, help="samples per pixel of the white render (default: the scene's)")
    parser.add_argument("--green", action="store_true", help="also measure the demosaiced green channel")
    parser.add_argument(
        "--plenopticam-python", type=Path, help="interpreter with PlenoptiCam installed (else it is skipped)"
    )
    parser.add_argument(
        "--plenopticam-method",
        choices=("area", "peak", "grid-fit", "vign-fit"),
        default="grid-fit",
        help="PlenoptiCam's cal_meth (default grid-fit)",
    )
    parser.add_argument(
        "--plenopticam-micro-image-px",
        type=int,
        help="PlenoptiCam's micro-image size M, px, replacing its estimate (default: estimated)",
    )
    parser.add_argument(
        "--plenopticam-timeout-s", type=float, default=1800.0, help="limit per PlenoptiCam run (default 1800 s)"
    )
    parser.add_argument("--work", type=Path, required=True, help="scratch folder (renders and intermediate files)")
    parser.add_argument("--clean", action="store_true", help="delete --work at the end if this run created it")
    args = parser.parse_args(argv)
    if args.plenopticam_python is not None and not args.plenopticam_python.exists():
        parser.error(f"--plenopticam-python {args.plenopticam_python} does not exist")

    created = not args.work.exists()
    args.work.mkdir(parents=True, exist_ok=True)
    print(f"machine: {cpu_name()}, {os.cpu_count()} logical CPUs, Python {platform.python_version()}")
    if args.plenopticam_python is not None:
        version = subprocess.run(
            [str(args.plenopticam_python), "-c", "import importlib.metadata as m; print(m.version('plenopticam'))"],
            capture_output=True,
            text=True,
            check=False,
        ).stdout.strip()
        size = args.plenopticam_micro_image_px
        print(
            f"PlenoptiCam {version or '(version unknown)'}, method {args.plenopticam_method}, "
            f"micro-image size M {'estimated' if size is None else f'{size} px (given)'}"
        )
    print(TABLE_HEAD, flush=True)
    notes: list[str] = []
    for camera in args.cameras:
        start = time.perf_counter()
        render = render_white(camera, args.work / camera / "white", spp=args.spp)
        render_s = time.perf_counter() - start
        raw = np.asarray(read_exr(render / "raw.exr"))
        truth = np.load(render / "lenses.npz")["micro_image_centre_px"]
        height_px, width_px = raw.shape[:2]
        notes.append(f"{camera}: {width_px} x {height_px} px, {len(truth)} lenses, render {render_s:.1f} s")
        images = grey_images(raw, camera, frames=args.frames, seed=args.seed, green=args.green)
        for image_name, image in images.items():
            if args.plenopticam_python is not None:
                centres, summary, seconds = run_plenopticam(
                    args.plenopticam_python,
                    image,
                    args.work / camera / f"plenopticam-{image_name}",
                    method=args.plenopticam_method,
                    micro_image_px=args.plenopticam_micro_image_px,
                    timeout_s=args.plenopticam_timeout_s,
                )
                error = summary.get("error")
                notes.append(
                    f"{camera} {image_name} PlenoptiCam: M = {summary.get('micro_image_px')} px, "
                    f"pattern {summary.get('pattern')}, pitch (row, col) {summary.get('pitch_px')}, "
                    f"stage seconds {json.dumps(summary.get('seconds'))}, error: {error}"
                )
                for stage in PLENOPTICAM_STAGES:
                    found = centres.get(stage, np.zeros((0, 2)))
                    scores = score_centres(found, truth, width_px=width_px, height_px=height_px)
                    note = (error or "not run") if len(found) == 0 else ""
                    print(table_row(camera, image_name, f"PlenoptiCam {stage}", scores, seconds, note), flush=True)
            centres, error, seconds = run_lfrefract(image)
            for name in ("measured", "fitted"):
                found = centres.get(name, np.zeros((0, 2)))
                scores = score_centres(found, truth, width_px=width_px, height_px=height_px)
                note = "" if error is None else error[:100]
                print(table_row(camera, image_name, f"lfrefract {name}", scores, seconds, note), flush=True)
    print()
    for note in notes:
        print(f"- {note}")
    if args.clean and created:
        shutil.rmtree(args.work)
    return 0


if __name__ == "__main__":
    sys.exit(main())
