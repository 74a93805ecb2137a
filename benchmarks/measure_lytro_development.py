"""A Lytro capture through the core: developed and synthesized, against the render's ground truth.

Renders (into ``--work``, reused when present) the default scene through a camera with its sensor
model (``lfsim render --sensor --lfr``) and the camera's white images at two focus settings
(``lfsim whites``), then prints

* the developed capture (``read_capture(capture.lfr, white=...)``) over the noiseless ``raw.exr``,
  per colour, median inside the micro-images: with the white image, and without;
* the refraction-free image against the ideal image (``ideal.exr``, the ground truth) inside the
  exact coverage: PSNR (dB, peak = the ideal's maximum) and the chroma error (RMS of each colour's
  difference from the pixel's mean of colours, against the ideal's, over the ideal's mean), for the
  noiseless ``raw.exr``, the capture demosaiced then synthesized, and the capture synthesized colour
  by colour from its own Bayer sites (``--colour cfa``) at several k per colour.

    python benchmarks/measure_lytro_development.py --work /tmp/lytro [--camera tiny] [--spp 64]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import numpy as np

from lfrefract.formats.capture import mask_warp_map, read_capture
from lfrefract.formats.exr import read_exr
from lfrefract.formats.jsonio import read_json
from lfrefract.optics.port import FlatPort
from lfrefract.synthesis.warp_map import SynthesisOptions, apply_cfa, build_warp_map


def _run(*argv: str) -> None:
    subprocess.run(list(argv), check=True, stdout=subprocess.DEVNULL)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--work", type=Path, required=True)
    parser.add_argument("--camera", default="tiny")
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--frames", type=int, default=16)
    args = parser.parse_args()
    cap, whites = args.work / "cap", args.work / "whites"
    if not (cap / "capture.lfr").is_file():
        _run(
            "lfsim",
            "render",
            "--camera",
            args.camera,
            "--sensor",
            args.camera,
            "--lfr",
            "--spp",
            str(args.spp),
            "--out",
            str(cap),
            "--quiet",
            "--no-previews",
            "--overwrite",
        )
    if not (whites / "whites.json").is_file():
        _run(
            "lfsim",
            "whites",
            "--camera",
            args.camera,
            "--focus-m",
            "inf,0.3",
            "--frames",
            str(args.frames),
            "--spp",
            str(args.spp),
            "--out",
            str(whites),
            "--quiet",
            "--overwrite",
        )
    raw = read_exr(cap / "raw.exr")
    ideal = read_exr(cap / "ideal.exr")
    port = FlatPort.from_dict(read_json(cap / "meta.json")["port"] | {})
    developed = read_capture(cap / "capture.lfr", white=whites)
    plain = read_capture(cap / "capture.lfr")
    inner = np.isfinite(developed.raw).all(axis=2) & (raw.min(axis=2) > 0.2 * raw.max())
    for name, capture in (("with its white", developed), ("without a white", plain)):
        ratio = np.median(capture.raw[inner] / raw[inner], axis=0)
        print(f"developed {name}: R, G, B over raw.exr = {ratio[0]:.3f}, {ratio[1]:.3f}, {ratio[2]:.3f}")
    camera = developed.camera
    full = build_warp_map(camera, port)
    covered = full.exact

    def scores(image: np.ndarray) -> str:
        ok = covered & np.isfinite(image).all(axis=2)
        error = image[ok] - ideal[ok]
        psnr = 10 * np.log10(ideal[ok].max() ** 2 / np.mean(error**2))
        chroma = (image[ok] - image[ok].mean(axis=1, keepdims=True)) - (
            ideal[ok] - ideal[ok].mean(axis=1, keepdims=True)
        )
        return f"{psnr:.2f} dB, chroma {np.sqrt(np.mean(chroma**2)) / ideal[ok].mean():.4f}"

    print("| image | k | PSNR against ideal.exr, exact coverage | ")
    print("| --- | --- | --- |")
    print(f"| raw.exr (noiseless RGB) | 8 | {scores(full.apply(raw))} |")
    for k in (4, 8):
        warp = mask_warp_map(build_warp_map(camera, port, options=SynthesisOptions(k=k)), developed.recorded)
        print(f"| capture, demosaiced then synthesized | {k} | {scores(warp.apply(developed.raw))} |")
    dev = developed.developed
    for ks in ((8, 8, 8), (4, 8, 4), (2, 4, 2)):
        maps = {
            c: mask_warp_map(
                build_warp_map(camera, port, options=SynthesisOptions(k=k, cfa_pattern=dev.cfa_pattern, cfa_colour=c)),
                ~dev.flagged,
            )
            for c, k in zip("RGB", ks, strict=True)
        }
        image = apply_cfa(maps, dev.values) @ dev.color_matrix.T
        print(f"| capture, colour by colour (cfa) | {', '.join(map(str, ks))} | {scores(image)} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
