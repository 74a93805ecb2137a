"""PlenoptiCam's micro-image centre detection on one white image (run by PlenoptiCam's interpreter).

A driver for ``benchmarks/measure_white_centres.py``: it imports only the standard library, numpy
and PlenoptiCam (https://github.com/hahnec/plenopticam, tested with 0.9.3), so that it runs in a
separate environment holding PlenoptiCam and its pinned dependencies (numpy < 2, scipy < 1.10).

It runs the stages of PlenoptiCam's ``LfpCalibrator.main`` one by one, as that method does, to
keep each stage's output (``LfpCalibrator`` itself returns only the last one and writes a
calibration JSON file):

1. ``PitchEstimator``: the micro-image size ``M`` (px) from a difference-of-Gaussians scale space
   (or ``--micro-image-px``).
2. ``CentroidExtractor``: a Laplacian of Gaussian of the white image and its local maxima on a
   2x down-sampled grid (integer, even pixel coordinates): the *peaks*.
3. ``CentroidRefiner``: each peak refined in a ``(2 (M // 2) + 1)`` px window of the LoG image
   (``area``: centroid of the window's pixels above its 75th percentile; ``peak``: LoG-weighted
   centroid): the *refined* centroids, its raw detections.
4. ``CentroidSorter``: rows and columns of the lattice, lattice indices; it averages several
   candidates and inserts missing centres: the *sorted* centres.
5. ``GridFitter`` (``--method grid-fit`` or ``vign-fit``): a projective (8-parameter) lattice fitted
   to the sorted centres by least squares: the *grid* centres.

PlenoptiCam addresses pixels as numpy ``(row, column)`` indices, so its pixel centres are at
integer coordinates, as ours are. Every output is converted to ``(u, v)`` = (column, row) pixels.

Outputs: ``OUT`` (N, 2) float64, the final centres (the grid fit if ``--method`` fits one, else the
sorted centres); ``--refined-out``, ``--peaks-out``, ``--sorted-out`` likewise for those stages;
``--summary`` a JSON file with the micro-image size, pattern, pitch, counts, timings and the error
of a stage that failed (then its output and every later one is an empty (0, 2) array).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import time
from pathlib import Path

import numpy as np

STAGES = ("peaks", "refined", "sorted", "grid")


def _uv_from_row_col(rows_cols: object) -> np.ndarray:
    """(N, >= 2) PlenoptiCam (row, column, ...) coordinates -> (N, 2) float64 (u, v) pixels."""
    array = np.asarray(rows_cols, dtype=np.float64)
    if array.size == 0:
        return np.zeros((0, 2))
    array = array.reshape(len(array), -1)
    return np.ascontiguousarray(array[:, [1, 0]])


def load_white(path: Path) -> np.ndarray:
    """Read a white image for PlenoptiCam.

    Parameters
    ----------
    path : Path
        ``.npy`` file, (H, W) or (H, W, 3) float in [0, 1].

    Returns
    -------
    ndarray of float64, shape (H, W)
        The image; a colour image is turned grey with PlenoptiCam's own ``rgb2gry`` (HDTV luma
        weights), as ``LfpCalibrator`` does.
    """
    from color_space_converter import rgb2gry

    image = np.load(path).astype(np.float64)
    if image.ndim == 3 and image.shape[-1] == 3:
        image = rgb2gry(image)[..., 0]
    if image.ndim != 2:
        raise ValueError(f"white image must be (H, W) or (H, W, 3), got {image.shape}")
    if not np.all(np.isfinite(image)):
        raise ValueError("white image has non-finite values")
    return image


def run_plenopticam(
    image: np.ndarray, *, method: str = "grid-fit", micro_image_px: int | None = None
) -> tuple[dict[str, np.ndarray], dict[str, object]]:
    """Run PlenoptiCam's calibration stages on a grey white image.

    Parameters
    ----------
    image : ndarray, shape (H, W)
        Grey white image, float.
    method : {"area", "peak", "grid-fit", "vign-fit"}
        PlenoptiCam's ``cal_meth``: ``area`` / ``peak`` choose the refinement and stop after
        sorting; ``grid-fit`` refines by area and fits a lattice; ``vign-fit`` adds its
        border penalty to that fit.
    micro_image_px : int, optional
        Micro-image size ``M`` (px) replacing ``PitchEstimator``'s estimate.

    Returns
    -------
    centres : dict of str to ndarray, shape (N, 2)
        ``peaks``, ``refined``, ``sorted``, ``grid`` as (u, v) pixels; a stage not run or failed
        gives (0, 2).
    summary : dict
        ``micro_image_px``, ``pattern``, ``pitch_px`` ((row, column) spacing), ``counts``,
        ``seconds`` per stage, ``status`` (PlenoptiCam's last message), ``error`` (None or
        ``"stage: message"``), ``log`` (its console output, truncated).
    """
    from plenopticam.cfg import PlenopticamConfig
    from plenopticam.lfp_calibrator import (
        CentroidExtractor,
        CentroidRefiner,
        CentroidSorter,
        GridFitter,
        PitchEstimator,
    )
    from plenopticam.misc.status import PlenopticamStatus

    cfg = PlenopticamConfig()
    cfg.params[cfg.cal_meth] = method
    cfg.params[cfg.opt_prnt] = False  # no console progress
    cfg.params[cfg.opt_dbug] = False  # no debug images written
    sta = PlenopticamStatus()

    centres = {stage: np.zeros((0, 2)) for stage in STAGES}
    summary: dict[str, object] = {
        "method": method,
        "image_shape": list(image.shape),
        "micro_image_px": None,
        "pattern": None,
        "pitch_px": None,
        "seconds": {},
        "error": None,
    }
    seconds: dict[str, float] = summary["seconds"]  # type: ignore[assignment]
    log = io.StringIO()
    stage = "pitch"
    try:
        with contextlib.redirect_stdout(log):
            start = time.perf_counter()
            if micro_image_px is None:
                estimator = PitchEstimator(image, cfg, sta)
                estimator.main()
                micro_px = int(estimator.M)
            else:
                micro_px = int(micro_image_px)
            summary["micro_image_px"] = micro_px
            seconds[stage] = time.perf_counter() - start

            stage = "peaks"
            start = time.perf_counter()
            extractor = CentroidExtractor(image, cfg, sta, micro_px)
            extractor.main()
            peaks = np.asarray(extractor.centroids)
            peak_img = extractor.peak_img
            centres["peaks"] = _uv_from_row_col(peaks)
            seconds[stage] = time.perf_counter() - start
            if len(peaks) == 0:
                raise RuntimeError("no local maxima above the LoG mean")

            stage = "refined"
            start = time.perf_counter()
            refiner = CentroidRefiner(peak_img, peaks, cfg, sta, micro_px)
            refiner.main()
            refined = np.asarray(refiner.centroids_refined)
            centres["refined"] = _uv_from_row_col(refined)
            seconds[stage] = time.perf_counter() - start

            stage = "sorted"
            start = time.perf_counter()
            sorter = CentroidSorter(refined, cfg, sta)
            sorter.main()
            if sta.error:
                raise RuntimeError(sta.stat_var or "CentroidSorter failed")
            mic_list = np.asarray(sorter.mic_list, dtype=np.float64)
            summary["pattern"] = sorter.pattern
            summary["pitch_px"] = [float(p) for p in sorter.pitch]
            centres["sorted"] = _uv_from_row_col(mic_list)
            seconds[stage] = time.perf_counter() - start

            if method in ("grid-fit", "vign-fit"):
                stage = "grid"
                start = time.perf_counter()
                fitter = GridFitter(
                    coords_list=mic_list,
                    cfg=cfg,
                    sta=sta,
                    arr_shape=image.shape,
                    pat_type=sorter.pattern,
                    penalty_enable=method == "vign-fit",
                )
                fitter.main()
                if sta.error:
                    raise RuntimeError(sta.stat_var or "GridFitter failed")
                centres["grid"] = _uv_from_row_col(fitter.grid_fit)
                seconds[stage] = time.perf_counter() - start
    except Exception as error:  # any PlenoptiCam failure (its own code) is a measured outcome
        summary["error"] = f"{stage}: {type(error).__name__}: {error}"
    summary["counts"] = {name: len(value) for name, value in centres.items()}
    summary["status"] = sta.stat_var
    summary["log"] = log.getvalue()[-2000:]
    return centres, summary


def main(argv: list[str] | None = None) -> int:
    """Command line: see ``--help``."""
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("white", type=Path, help="white image .npy, (H, W) or (H, W, 3) in [0, 1]")
    parser.add_argument("out", type=Path, help="final centres .npy, (N, 2) (u, v) pixels")
    parser.add_argument(
        "--method",
        choices=("area", "peak", "grid-fit", "vign-fit"),
        default="grid-fit",
        help="PlenoptiCam's calibration method, cal_meth (default: grid-fit)",
    )
    parser.add_argument("--micro-image-px", type=int, help="micro-image size M, px (default: estimated)")
    parser.add_argument("--peaks-out", type=Path, help="integer LoG maxima .npy, (u, v)")
    parser.add_argument("--refined-out", type=Path, help="refined centroids .npy, (u, v)")
    parser.add_argument("--sorted-out", type=Path, help="sorted lattice centres .npy, (u, v)")
    parser.add_argument("--summary", type=Path, help="JSON summary of the run")
    args = parser.parse_args(argv)

    image = load_white(args.white)
    centres, summary = run_plenopticam(image, method=args.method, micro_image_px=args.micro_image_px)
    final = centres["grid"] if args.method in ("grid-fit", "vign-fit") else centres["sorted"]
    np.save(args.out, final)
    for path, stage in (
        (args.peaks_out, "peaks"),
        (args.refined_out, "refined"),
        (args.sorted_out, "sorted"),
    ):
        if path is not None:
            np.save(path, centres[stage])
    if args.summary is not None:
        args.summary.write_text(json.dumps(summary, indent=2))
    print(json.dumps({key: summary[key] for key in summary if key != "log"}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
