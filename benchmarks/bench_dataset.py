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

With ``--labels`` it renders the sweep twice with the first worker count instead: with no extra
output, then with every label on (``refraction_free``, ``views``, ``labels``, ``raw_truth``), and
prints both rates, their ratio, and the bytes per sample of each file kind (the image names of
``sample.json``, ``views/`` as one) in the dataset's format (``--image-format``).

    python benchmarks/bench_dataset.py --labels --workers 1 --samples 8 --image-format exr

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

#: Every optional output that is a label (``--labels``).
LABEL_OUTPUTS = ["refraction_free", "views", "labels", "raw_truth"]


def _spec(samples: int, spp: int, seed: int, *, outputs: list[str] | None = None, image_format: str = "exr"):
    tilts = [round(float(t), 3) for t in np.linspace(0.0, 30.0, samples)]
    sweep = {"name": "bench", "seed": seed, "scene": "default", "spp": spp, "image_format": image_format}
    data = {
        "sweep": sweep | ({"outputs": outputs} if outputs else {}),
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


def _bytes_per_sample(root: Path) -> dict[str, float]:
    """Mean bytes per sample of each image (by its name in ``sample.json``), ``views/`` and the rest."""
    totals: dict[str, float] = {}
    folders = sorted(p for p in root.iterdir() if p.is_dir())
    for folder in folders:
        images = json.loads((folder / "sample.json").read_text()).get("images", {})
        by_file = {entry["file"]: name for name, entry in images.items()}
        for path in folder.rglob("*"):
            if path.is_file():
                rel = path.relative_to(folder).as_posix()
                kind = "views/" if rel.startswith("views/") else by_file.get(rel, "other (sidecars, lenses.npz, port)")
                totals[kind] = totals.get(kind, 0.0) + path.stat().st_size
    return {kind: size / len(folders) for kind, size in totals.items()}


def _fresh(out: Path) -> None:
    """Refuse a run folder that holds anything: nothing under ``--out`` is removed, not even an earlier
    run of this benchmark (the user may have put files into it); name a new ``--out`` to run again."""
    if out.exists() and not (out.is_dir() and not any(out.iterdir())):
        raise SystemExit(f"{str(out)!r} exists and is not empty: name a new --out (nothing is removed)")


def _labels(args, seed: int, base: Path) -> None:
    """``--labels``: the sweep without and with every label, one worker count."""
    workers = args.workers[0]
    results = {}
    for label, outputs in (("no labels", None), ("all labels", LABEL_OUTPUTS)):
        spec = _spec(args.samples, args.spp, seed, outputs=outputs, image_format=args.image_format)
        out = base / label.replace(" ", "_")
        _fresh(out)
        results[label] = r = _run(spec, out, workers=workers, scheduler=None, threads=args.threads)
        print(f"  {label:>10}: {r['samples']} samples in {r['seconds']:6.1f} s: {r['overall']:6.1f} samples/min "
              f"overall, {r['steady']:6.1f} samples/min steady")  # fmt: skip
        if outputs:
            for kind, size in sorted(_bytes_per_sample(out).items(), key=lambda kv: -kv[1]):
                print(f"      {kind:>36}: {size / 1e6:8.3f} MB per sample")
    a, b = results["all labels"], results["no labels"]
    ratio = a["overall"] / b["overall"], a["steady"] / b["steady"]
    print(f"  all labels / no labels: {ratio[0]:.2f} overall, {ratio[1]:.2f} steady")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--samples", type=int, default=16, help="samples of the sweep (default 16)")
    parser.add_argument("--spp", type=int, default=4, help="samples per pixel (default 4)")
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2], help="local worker counts (default 1 2)")
    parser.add_argument("--threads", type=int, help="render threads per worker (default: cores / workers)")
    parser.add_argument("--scheduler", help="address of a Dask scheduler: run once on that cluster")
    parser.add_argument("--out", type=Path, help="folder for the datasets (default: a temporary folder)")
    parser.add_argument("--seed", type=int, help="sweep seed (default: new each time, so every port is new)")
    parser.add_argument("--labels", action="store_true", help="compare no labels with every label (one run each)")
    parser.add_argument("--image-format", default="exr", choices=["exr", "npz", "png16"], help="with --labels")
    args = parser.parse_args()
    seed = int(time.time()) if args.seed is None else args.seed
    spec = _spec(args.samples, args.spp, seed, image_format=args.image_format)
    print(f"{platform.node()}: {platform.processor() or platform.machine()}, dataset of {args.samples} samples "
          f"(tiny camera, default scene, {args.spp} spp, tilt 0-30 deg, sweep seed {seed})")  # fmt: skip
    base = Path(tempfile.mkdtemp(prefix="bench_dataset_")) if args.out is None else args.out
    try:
        if args.labels:
            _labels(args, seed, base)
            return
        runs = [(None, args.scheduler)] if args.scheduler else [(w, None) for w in args.workers]
        results = []
        for workers, scheduler in runs:
            label = f"cluster {scheduler}" if scheduler else f"{workers} worker{'s' if workers > 1 else ''}"
            out = base / ("cluster" if scheduler else f"workers{workers}")
            _fresh(out)
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
