"""MLA calibration on soft, realistic white images: fitted micro-image centres against ground truth.

Renders (once, into ``--work``) the white image of each camera (``lfsim render white``: raw.exr,
noiseless with hard-edged micro-images, and lenses.npz, the true centres), then calibrates
(:func:`lfrefract.calibration.calibrate_mla`) on

* ``raw``: the render itself (channels averaged);
* ``blurred``: the render blurred by a Gaussian of ``--sigma-px`` (per camera), the soft edges of a
  real white image;
* ``sensor``: the camera's detector preset, ``--frames`` exposures averaged
  (:func:`simulator.detector.white_frames`), demosaiced (OpenCV bilinear), black subtracted,
  channels averaged: what a Lytro white image gives,

and prints, per camera and image, the lenses used, the pitch error and the RMS / max distance of
the fitted centres from the true ones (px), and the seconds the calibration took. Run it with
``PYTHONPATH`` pointing at another checkout to measure that version's calibration on the same
images (the renders are reused).

    python benchmarks/measure_mla_calibration.py --work /tmp/mla [--cameras tiny f01 illum]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from lfrefract.calibration import calibrate_mla
from lfrefract.errors import ParameterError
from lfrefract.formats.exr import read_exr
from simulator.detector import DETECTOR_PRESETS, demosaic, white_frames

#: Blur of the ``blurred`` images, pixels: the issue's soft whites (Illum 2 px, F01 1.5 px), and 1 px
#: for the tiny camera's 10 um pixels.
SIGMA_PX = {"tiny": 1.0, "tiny-2x": 1.0, "f01": 1.5, "illum": 2.0}


def _white(work: Path, camera: str, spp: int) -> Path:
    folder = work / f"white-{camera}"
    if not (folder / "raw.exr").is_file():
        cmd = ["lfsim", "render", "white", "--camera", camera, "--spp", str(spp), "--out", str(folder)]
        subprocess.run([*cmd, "--quiet", "--no-previews", "--overwrite"], check=True)
    return folder


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--work", type=Path, required=True, help="folder for the renders (reused when present)")
    parser.add_argument("--cameras", nargs="*", default=["tiny", "f01", "illum"])
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--frames", type=int, default=16)
    args = parser.parse_args()
    args.work.mkdir(parents=True, exist_ok=True)
    print("| camera | white | lenses used | pitch error, px | fitted centres RMS / max, px | seconds |")
    print("| --- | --- | ---: | ---: | ---: | ---: |")
    for camera in args.cameras:
        folder = _white(args.work, camera, args.spp)
        raw = read_exr(folder / "raw.exr")
        truth = np.load(folder / "lenses.npz")["micro_image_centre_px"]
        sensor_npy = args.work / f"sensor-{camera}-{args.frames}.npy"
        if not sensor_npy.is_file():
            mosaic = white_frames(
                raw, DETECTOR_PRESETS[camera if camera in DETECTOR_PRESETS else "tiny"], frames=args.frames, seed=1
            )
            np.save(sensor_npy, demosaic(mosaic).mean(axis=2))
        images = {
            "raw": raw.mean(axis=2),
            f"blurred {SIGMA_PX[camera]:g} px": ndimage.gaussian_filter(raw.mean(axis=2), SIGMA_PX[camera]),
            f"sensor, {args.frames} frames": np.load(sensor_npy),
        }
        tree = cKDTree(truth)
        true_pitch = float(np.median(tree.query(truth, k=2)[0][:, 1]))
        for name, image in images.items():
            start = time.perf_counter()
            try:
                cal = calibrate_mla(image)
            except ParameterError as exc:
                print(f"| {camera} | {name} | refused: {exc} | | | |", flush=True)
                continue
            seconds = time.perf_counter() - start
            fitted = cal.centres_px[cal.used]
            distance, _ = tree.query(fitted)
            print(
                f"| {camera} | {name} | {int(cal.used.sum())} | {abs(cal.pitch_px - true_pitch):.1e} | "
                f"{np.sqrt(np.mean(distance**2)):.4f} / {distance.max():.4f} | {seconds:.1f} |",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
