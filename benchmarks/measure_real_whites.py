"""MLA calibration on real lenslet white images: the light-field microscope examples of napari-LF.

The napari-LF package (PyPI, 0.1.7) ships three light-field microscope captures, each with a
"radiometry" frame (a flat fluorescent slide: the white image) and a dark frame, and the optics'
nominal lenslet pitch and pixel size. This downloads its wheel (``pip download --no-deps``, 26 MB,
into ``--work``, reused when present), calibrates ``radiometry - dark`` with
:func:`lfrefract.calibration.calibrate_mla`, and prints the lattice found, the residual of the
centroids about it and the nominal pitch (lenslet pitch over pixel size; a microscope's image side
is telecentric, so the micro-image pitch is the lenslet pitch).

    python benchmarks/measure_real_whites.py --work /tmp/napari-lf
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import imageio.v3 as iio
import numpy as np

from lfrefract.calibration import calibrate_mla

WHEEL = "napari-lf==0.1.7"
#: Example, white, dark, nominal lenslet pitch over pixel size (um / um): from its metadata.txt or README.
EXAMPLES = {
    "GUVExperim1": ("Radiometry_GUVExperim1.tif", "DarkFrame_GUVExperim1.tif", 100.0 / 6.5),
    "seaurchin": ("radiometry_frame.tif", "dark_frame.tif", 125.0 / 7.4),
    "antleg": ("radiometry_frame.png", "dark_frame.tif", 125.0 / 4.55),
}


def examples_folder(work: Path) -> Path:
    """The wheel's ``napari_lf/examples`` folder, extracted into ``work`` (downloaded once)."""
    work.mkdir(parents=True, exist_ok=True)

    def wheels() -> list[Path]:
        return sorted(p for p in work.glob("*.whl") if p.name.lower().startswith("napari_lf-"))

    if not wheels():
        subprocess.run([sys.executable, "-m", "pip", "download", "--no-deps", WHEEL, "-d", str(work), "-q"], check=True)
    folder = work / "extracted"
    if not (folder / "napari_lf" / "examples").is_dir():
        with zipfile.ZipFile(wheels()[0]) as wheel:
            wheel.extractall(folder, [n for n in wheel.namelist() if "/examples/" in n])
    return folder / "napari_lf" / "examples"


def white_image(folder: Path, name: str) -> np.ndarray:
    """``radiometry - dark`` of example ``name``, clipped at 0, channels averaged."""
    white_name, dark_name, _ = EXAMPLES[name]
    white = iio.imread(folder / name / white_name, plugin="pillow").astype(np.float64)
    dark = iio.imread(folder / name / dark_name, plugin="pillow").astype(np.float64)
    image = np.clip(white - dark, 0.0, None)
    return image[..., :3].mean(axis=2) if image.ndim == 3 else image


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--work", type=Path, required=True, help="folder for the wheel and its examples")
    args = parser.parse_args()
    folder = examples_folder(args.work)
    print(
        "| example | image, px | grid | pitch, px | nominal, px | rotation, mrad | lenses used / on sensor | "
        "residual RMS / max, px | seconds |"
    )
    print("| --- | --- | --- | ---: | ---: | ---: | --- | --- | ---: |")
    for name, (_, _, nominal) in EXAMPLES.items():
        image = white_image(folder, name)
        start = time.perf_counter()
        cal = calibrate_mla(image)
        seconds = time.perf_counter() - start
        print(
            f"| {name} | {image.shape[1]} x {image.shape[0]} | {cal.grid} | {cal.pitch_px:.4f} | {nominal:.4f} | "
            f"{cal.rotation_rad * 1e3:.2f} | {int(cal.used.sum())} / {len(cal.indices)} | "
            f"{cal.residual_rms_px:.3f} / {cal.residual_max_px:.3f} | {seconds:.1f} |",
            flush=True,
        )
    print(json.dumps({"wheel": WHEEL}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
