"""Benchmark dataset generation: samples per minute with 1 and 2 local Dask workers, and the ratio.

Renders a tilt sweep of the embedded default scene (tiny camera, ``--spp`` samples per pixel,
``--samples`` port tilts from 0 to 30 deg, the files of ``lfsim render`` per sample) with
``lfsim dataset run``'s engine (:func:`simulator.dataset.run_dataset`) into a fresh temporary
folder per worker count, and prints for each:

* ``overall``: samples per minute over the whole run, cluster start-up and the workers' first
  render (Mitsuba import, JIT compilation) included;
* ``steady``: samples per minute between the completion of the first sample of every worker and
  the last one (the rate of a long run), from the manifest's ``finished_at`` times;

then the ratios of the last worker count to the first. The sweep seed changes with every
invocation (``--seed`` fixes it), so every sample has a port that Dr.Jit has not compiled kernels
for yet, as in a random sweep: Dr.Jit caches compiled kernels on disk (``~/.drjit``), and a sweep
repeated with the same ports renders each sample about 0.12 s faster here.

    python benchmarks/bench_dataset.py                         # 1 and 2 workers, 16 samples, 4 spp
    python benchmarks/bench_dataset.py --workers 1 2 --threads 1 --samples 24
    python benchmarks/bench_dataset.py --scheduler tcp://host:8786 --out /shared/bench

With ``--scheduler`` the sweep runs once on that Dask cluster (start it with ``dask scheduler``
and ``dask worker tcp://host:8786 --nworkers N --nthreads 1`` on each machine); ``--out`` must
then be a folder every worker sees at the same path.
"""

from __future__ import annotations

import argparse
import datetime
import json
import platform
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from simulator.dataset import parse_spec, run_dataset


def _spec(samples: int, spp: int, seed: int):
    tilts = [round(float(t), 3) for t in np.linspace(0.0, 30.0, samples)]
    data = {
        "sweep": {"name": "bench", "seed": seed, "scene": "default", "spp": spp},
        "grid": {"port.tilt_x_deg": tilts},
        "random": {"port.tilt_y_deg": {"uniform": [-3.0, 3.0]}},
    }
    return parse_spec(data, source="benchmarks/bench_dataset.py")


def _finish_times(root: Path) -> np.ndarray:
    lines = (root / "manifest.jsonl").read_text().splitlines()
    stamps = [datetime.datetime.fromisoformat(json.loads(line)["finished_at"]).timestamp() for line in lines]
    return np.sort(np.asarray(stamps))


def _run(spec, out: Path, *, workers: int | None, scheduler: str | None, threads: int | None) -> dict:
    report = run_dataset(spec, out, workers=workers, scheduler=scheduler, threads_per_worker=threads, progress=False)
    if not report.ok:
        raise SystemExit(f"the benchmark run failed: {report.failed}")
    times = _finish_times(out)
    first = min(workers or 1, len(times)) - 1  # every worker has finished its first sample
    steady = (len(times) - 1 - first) / (times[-1] - times[first]) * 60.0 if len(times) - 1 > first else float("nan")
    return {"samples": report.rendered, "seconds": report.seconds, "overall": report.rendered / report.seconds * 60.0,
            "steady": steady}  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--samples", type=int, default=16, help="samples of the sweep (default 16)")
    parser.add_argument("--spp", type=int, default=4, help="samples per pixel (default 4)")
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2], help="local worker counts (default 1 2)")
    parser.add_argument("--threads", type=int, help="render threads per worker (default: cores / workers)")
    parser.add_argument("--scheduler", help="address of a Dask scheduler: run once on that cluster")
    parser.add_argument("--out", type=Path, help="folder for the datasets (default: a temporary folder)")
    parser.add_argument("--seed", type=int, help="sweep seed (default: new each time, so every port is new)")
    args = parser.parse_args()
    seed = int(time.time()) if args.seed is None else args.seed
    spec = _spec(args.samples, args.spp, seed)
    print(f"{platform.node()}: {platform.processor() or platform.machine()}, dataset of {args.samples} samples "
          f"(tiny camera, default scene, {args.spp} spp, tilt 0-30 deg, sweep seed {seed})")  # fmt: skip
    base = Path(tempfile.mkdtemp(prefix="bench_dataset_")) if args.out is None else args.out
    try:
        runs = [(None, args.scheduler)] if args.scheduler else [(w, None) for w in args.workers]
        results = []
        for workers, scheduler in runs:
            label = f"cluster {scheduler}" if scheduler else f"{workers} worker{'s' if workers > 1 else ''}"
            out = base / ("cluster" if scheduler else f"workers{workers}")
            shutil.rmtree(out, ignore_errors=True)
            r = _run(spec, out, workers=workers, scheduler=scheduler, threads=args.threads)
            results.append(r)
            print(f"  {label:>12}: {r['samples']} samples in {r['seconds']:6.1f} s: {r['overall']:6.1f} samples/min "
                  f"overall, {r['steady']:6.1f} samples/min steady")  # fmt: skip
        if len(results) > 1:
            first, last = results[0], results[-1]
            print(f"  scaling {runs[-1][0]} / {runs[0][0]} workers: {last['overall'] / first['overall']:.2f} overall, "
                  f"{last['steady'] / first['steady']:.2f} steady")  # fmt: skip
    finally:
        if args.out is None:
            shutil.rmtree(base, ignore_errors=True)


if __name__ == "__main__":
    main()
