"""Benchmark what verifying a dataset's files costs: seconds per GB of SHA-256, as a resumed
``lfsim dataset run`` and ``lfsim dataset check`` do it (every file of every done sample, read to
its end; :func:`simulator.dataset.check.verify_folders`).

Writes ``--samples`` sample folders of random bytes (incompressible, as rendered EXR data is) of
``--mb`` MB each (an Illum sample's ``raw.exr`` is about 500 MB) with their manifest records into a
temporary folder (``--dir`` to put it on another disk), verifies them once to bring them into the
page cache, then times the verification with one thread and with one per core, and prints the
seconds per GB of each. Files read from a disk or network file system the first time go as fast as
it reads instead (100 MB/s: 10 s per GB).

    python benchmarks/bench_dataset_verify.py                  # 4 samples of 256 MB
    python benchmarks/bench_dataset_verify.py --samples 2 --mb 500 --dir /data/tmp
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time
from pathlib import Path

from simulator.dataset import check
from simulator.dataset.manifest import folder_files

_CHUNK = 1 << 24


def _make(root: Path, samples: int, megabytes: int) -> list[tuple[Path, dict]]:
    out = []
    for i in range(samples):
        folder = root / f"s{i:06d}"
        folder.mkdir()
        with (folder / "raw.exr").open("wb") as fh:
            left = megabytes * 1_000_000
            while left:
                block = os.urandom(min(left, _CHUNK))
                fh.write(block)
                left -= len(block)
        (folder / "sample.json").write_text('{"kind": "lfsim.dataset.sample"}\n')
        out.append((folder, {"id": folder.name, "files": folder_files(folder)}))
    return out


def _time(folders: list[tuple[Path, dict]], threads: int) -> float:
    start = time.perf_counter()
    problems = check.verify_folders(folders, hashes=True, threads=threads)
    seconds = time.perf_counter() - start
    if any(problems):
        raise SystemExit(f"verification failed: {problems}")
    return seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=4)
    parser.add_argument("--mb", type=int, default=256, help="MB of each sample's large file")
    parser.add_argument("--dir", default=None, help="where to write the temporary dataset")
    args = parser.parse_args()
    cores = check._cpus()
    with tempfile.TemporaryDirectory(dir=args.dir, prefix="bench-verify-") as tmp:
        folders = _make(Path(tmp), args.samples, args.mb)
        gigabytes = sum(e["bytes"] for _, r in folders for e in r["files"].values()) / 1e9
        _time(folders, cores)  # into the page cache
        machine = platform.processor() or platform.machine()
        print(f"{machine}, {cores} core(s); {args.samples} samples of {args.mb} MB, {gigabytes:.2f} GB")
        for threads in sorted({1, cores}):
            seconds = _time(folders, threads)
            print(f"{threads} thread(s): {seconds:.2f} s, {seconds / gigabytes:.2f} s per GB (page cache warm)")


if __name__ == "__main__":
    main()
