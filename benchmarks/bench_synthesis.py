"""Benchmark the refraction-free synthesis: warp-map build and per-frame apply.

    python benchmarks/bench_synthesis.py                 # illum, k = 1, 8, 32, 64, s = 2
    python benchmarks/bench_synthesis.py --camera tiny --k 32 --search kdtree
    python benchmarks/bench_synthesis.py --k 32 --model thin calibrated   # a calibrated camera beside the thin lens

Each configuration runs in a fresh process so its peak memory (max RSS) is its own: "build MB"
is the peak after building the map, "apply MB" the peak after applying it (map, raw frame and
output). The raw frame is random RGB float32 of the camera's sensor size (apply time does not
depend on content). The port is the paper's reference port (``simulator.experiments.fov.reference_port``).
``--model calibrated`` builds the map on a calibrated ray model (:data:`CALIBRATED`, the
correction the Illum pipeline fitted to its left camera) instead of the thin lens; list both
to compare them in one run (machines differ: compare ratios).
Targets (issue 3), Illum, k = 32, s = 2, 2 cores: apply <= 20 ms per frame, build <= 2 s.
Paper (Intel Xeon E5640, 4 cores, 2010): 53 ms per frame, 8.9 s for the map.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import time

import numpy as np

PAPER_APPLY_MS = 53.0
PAPER_BUILD_S = 8.9

#: A calibrated camera's departure from the thin lens: what ``calibrate camera`` fitted to the Illum
#: pipeline's left camera (docs/experiments.md, pipeline).
CALIBRATED = {"pupil_scale": 1.0015, "slope_scale": 1.0011, "k1": 0.083, "k2": 0.077, "pupil_drift_m": -0.0055}


def _worker(camera_name: str, k: int, supersample: int, frames: int, search: str, model: str) -> dict:
    from lfrefract import camera_preset
    from lfrefract.optics.ray_correction import RayCorrection
    from lfrefract.synthesis.warp_map import SynthesisOptions, build_warp_map
    from simulator.experiments.fov import reference_port

    camera = camera_preset(camera_name)
    # The reference port of the paper's implementation: normal (-0.0085, -0.5004, 1), 59.2 mm along the
    # optical axis (52.9 mm perpendicular), a single air/water interface (docs/conventions.md, the port).
    port = reference_port()
    correction = RayCorrection.from_dict(CALIBRATED) if model == "calibrated" else None
    options = SynthesisOptions(k=k, supersample=supersample, search=search, ray_correction=correction)
    build_warp_map(camera_preset("tiny"), port, options=options)  # compile / load the kernels
    start = time.perf_counter()
    warp = build_warp_map(camera, port, options=options)
    build_s = time.perf_counter() - start
    build_rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    raw = np.random.default_rng(0).random((camera.sensor.height_px, camera.sensor.width_px, 3), dtype=np.float32)
    warp.apply(raw)  # warm-up
    times = []
    for _ in range(frames):
        start = time.perf_counter()
        warp.apply(raw)
        times.append(time.perf_counter() - start)
    return {
        "camera": camera_name,
        "model": model,
        "k": k,
        "supersample": supersample,
        "output": [warp.output.width_px, warp.output.height_px],
        "nonzeros": len(warp.indices),
        "build_s": build_s,
        "apply_ms": 1e3 * float(np.median(times)),
        "build_rss_mb": build_rss_mb,
        "apply_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        "exact_fraction": float(warp.exact.mean()),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--camera", default="illum")
    parser.add_argument("--k", type=int, nargs="+", default=[1, 8, 32, 64])
    parser.add_argument("--search", choices=["auto", "analytic", "kdtree"], default="auto")
    parser.add_argument("--model", choices=["thin", "calibrated"], nargs="+", default=["thin"])
    parser.add_argument("--supersample", type=int, default=2)
    parser.add_argument("--frames", type=int, default=10)
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        print(json.dumps(_worker(args.camera, args.k[0], args.supersample, args.frames, args.search, args.model[0])))
        return 0
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, python {platform.python_version()}")
    print(
        f"{'camera':7} {'model':10} {'k':>3} {'s':>2} {'output':>10} {'nnz':>11} {'build s':>8} {'apply ms':>9} "
        f"{'build MB':>9} {'apply MB':>9} {'build/paper':>11} {'apply/paper':>11}"
    )
    for model, k in ((model, k) for model in args.model for k in args.k):
        cmd = [
            sys.executable,
            __file__,
            "--worker",
            "--camera",
            args.camera,
            "--k",
            str(k),
            "--supersample",
            str(args.supersample),
            "--frames",
            str(args.frames),
            "--search",
            args.search,
            "--model",
            model,
        ]
        r = json.loads(subprocess.run(cmd, capture_output=True, text=True, check=True).stdout.strip().splitlines()[-1])
        print(
            f"{r['camera']:7} {model:10} {k:>3} {r['supersample']:>2} {r['output'][0]:>4}x{r['output'][1]:<5} "
            f"{r['nonzeros']:>11,} {r['build_s']:8.2f} {r['apply_ms']:9.1f} "
            f"{r['build_rss_mb']:9.0f} {r['apply_rss_mb']:9.0f} "
            f"{r['build_s'] / PAPER_BUILD_S:11.2f} {r['apply_ms'] / PAPER_APPLY_MS:11.2f}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
