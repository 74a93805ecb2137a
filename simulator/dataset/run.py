"""Run a sweep: every sample rendered by Dask workers, recorded in the manifest, resumable.

The driver (this process) checks the whole spec first (:func:`simulator.dataset.spec.expand`),
then creates the dataset folder with ``dataset.json``, or, if the folder holds an earlier run of
the same spec, resumes it. It holds a lock on the folder (``flock``) for the whole run, so a
second run on the same folder is refused instead of deleting the first one's work. On resume it
drops an unterminated last manifest line, removes staging leftovers, re-renders done samples whose
files went missing or changed size, removes the folders of samples that are not recorded as done,
and skips the done ones. Each remaining sample is one Dask task that
renders it into its folder (:func:`simulator.dataset.sample.render_sample`) and returns its
manifest record; the driver alone appends records, as the tasks complete. A task that raises is
submitted again, up to ``retries`` more times, then recorded as failed with its error and the
attempt count; a later run tries failed samples again.

Locally (the default) a Dask ``LocalCluster`` of ``workers`` processes with one task thread each
runs the tasks, and each worker's Dr.Jit and numba use ``cores / workers`` threads. With
``scheduler`` the tasks go to an existing cluster instead (``dask scheduler`` and ``dask worker``);
every worker must then see the dataset folder at the same path (a shared file system) and have
this package installed.
"""

from __future__ import annotations

import contextlib
import datetime
import fcntl
import logging
import os
import time
import traceback
import uuid
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from tqdm.auto import tqdm

import lfrefract
from lfrefract._validate import ParameterError, one_of, positive_int
from lfrefract.io import FileFormatError, write_json
from simulator.backend import VARIANTS
from simulator.dataset.check import verify_folder
from simulator.dataset.manifest import (
    DATASET_FILE,
    DATASET_KIND,
    MANIFEST_FILE,
    append_record,
    latest_records,
    read_dataset,
    read_manifest,
    remove,
    staging_leftovers,
)
from simulator.dataset.sample import SampleTask, render_sample
from simulator.dataset.spec import SweepSample, SweepSpec, expand, load_spec

__all__ = ["DatasetBusyError", "DatasetMismatchError", "RunReport", "run_dataset"]


#: How long to try to reach a scheduler given by address before giving up.
SCHEDULER_TIMEOUT = "30s"


class DatasetMismatchError(FileExistsError):
    """The output folder holds something other than an earlier run of this spec."""


class DatasetBusyError(FileExistsError):
    """Another run is using the output folder."""


@dataclass(frozen=True)
class RunReport:
    """What :func:`run_dataset` did.

    Attributes
    ----------
    out_dir : Path
    total : int
        Samples in the sweep.
    skipped : int
        Samples already done by an earlier run.
    rendered : int
        Samples rendered (and recorded done) by this run.
    failed : tuple of (str, str, int)
        ``(id, error, attempts)`` of the samples that failed every attempt in this run.
    seconds : float
        Wall time of this run, seconds.
    """

    out_dir: Path
    total: int
    skipped: int
    rendered: int
    failed: tuple[tuple[str, str, int], ...]
    seconds: float

    @property
    def ok(self) -> bool:
        """Every sample of the sweep is done."""
        return not self.failed and self.skipped + self.rendered == self.total


def _now() -> str:
    return datetime.datetime.now(datetime.UTC).isoformat(timespec="milliseconds")


def _cpus() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def _check_target(out: Path, spec: SweepSpec, samples: tuple[SweepSample, ...]) -> None:
    """Raise unless ``out`` is absent, empty, or a dataset of this spec with these samples (reads only)."""
    if out.exists() and not out.is_dir():
        raise DatasetMismatchError(f"output {str(out)!r} exists and is not a directory")
    leftovers = set(staging_leftovers(out))  # e.g. dataset.json's temporary file: killed while creating it
    if out.is_dir() and any(p not in leftovers for p in out.iterdir()):
        try:
            earlier = read_dataset(out)
        except FileFormatError as exc:
            raise DatasetMismatchError(
                f"output directory {str(out)!r} is not empty and is not an lfsim dataset ({exc}); refusing to use it"
            ) from None
        if earlier.get("spec_hash") != spec.hash:
            raise DatasetMismatchError(
                f"{str(out)!r} holds a dataset of another spec (spec hash {earlier.get('spec_hash')!r}, this spec "
                f"{spec.hash!r}): refusing to mix datasets; use another --out, or the spec it was made with"
            )
        known = {s["id"]: s.get("hash") for s in earlier["samples"]}
        changed = [s.id for s in samples if known.get(s.id) != s.hash]
        if changed or len(known) != len(samples):
            raise DatasetMismatchError(
                f"{str(out)!r} was made from this spec but its samples differ now ({len(changed)} of {len(samples)} "
                f"changed, e.g. {changed[:3]}; a base scene or a mesh path may have changed): refusing to mix datasets"
            )


def _prepare(out: Path, spec: SweepSpec, samples: tuple[SweepSample, ...]) -> dict[str, dict]:
    """Create the dataset folder, or tidy an earlier run of the same spec (see the module
    docstring); return the latest manifest record of every sample that is done and intact."""
    if not (out / DATASET_FILE).is_file():
        out.mkdir(parents=True, exist_ok=True)
        write_json(
            out / DATASET_FILE,
            {
                "kind": DATASET_KIND,
                "name": spec.name,
                "spec": spec.to_dict(),
                "spec_hash": spec.hash,
                "spec_source": spec.source,
                "outputs": list(spec.outputs),
                "swept_keys": list(spec.swept_keys),
                "created": _now(),
                "lfrefract": lfrefract.__version__,
                "samples": [s.record() for s in samples],
            },
        )
    for leftover in staging_leftovers(out):
        remove(leftover)
    latest = latest_records(read_manifest(out / MANIFEST_FILE, repair=True))
    done = {}
    for sample in samples:
        record = latest.get(sample.id)
        folder = out / sample.id
        intact = record is not None and record["status"] == "done" and record.get("hash") == sample.hash
        if intact and verify_folder(folder, record, hashes=False) is None:
            done[sample.id] = record
        elif folder.exists():  # rendered but never recorded (killed in between), or damaged since
            remove(folder)
    return done


@contextlib.contextmanager
def _locked(out: Path) -> Iterator[None]:
    """Create ``out`` and hold an exclusive lock on it (``flock`` of the folder) until the block ends.

    Raises DatasetBusyError if another process holds it. A file system without locks is used
    unlocked.
    """
    out.mkdir(parents=True, exist_ok=True)
    fd = os.open(out, os.O_RDONLY)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise DatasetBusyError(
                f"{str(out)!r} is in use by another lfsim dataset run; wait for it to end (or kill it) and run again"
            ) from None
        except OSError:  # no locks on this file system
            pass
        yield
    finally:
        os.close(fd)


@contextlib.contextmanager
def _dask_client(workers: int, scheduler: str | None) -> Iterator:
    from dask.distributed import Client, LocalCluster

    if scheduler is not None:
        try:
            client = Client(scheduler, timeout=SCHEDULER_TIMEOUT)
        except (OSError, ValueError) as exc:  # unreachable, no scheduler there, or a malformed address
            raise ParameterError(f"scheduler={scheduler!r}: cannot reach a Dask scheduler there ({exc})") from None
        with client:
            yield client
        return
    cluster = LocalCluster(
        n_workers=workers,
        threads_per_worker=1,
        processes=True,
        dashboard_address=None,
        silence_logs=logging.CRITICAL,  # task errors reach the manifest and the report; no worker log noise
    )
    try:
        with Client(cluster) as client:
            yield client
    finally:
        cluster.close()


def run_dataset(
    spec: SweepSpec | str | os.PathLike,
    out_dir: str | os.PathLike,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    threads_per_worker: int | None = None,
    retries: int = 2,
    variant: str | None = None,
    progress: bool = True,
) -> RunReport:
    """Render every sample of a sweep into ``out_dir``, or complete an interrupted run.

    Parameters
    ----------
    spec : SweepSpec or path-like
        The sweep, or its TOML file (or the name of an embedded sweep).
    out_dir : path-like
        Dataset folder: absent, empty, or an earlier (possibly interrupted) run of the same spec.
    workers : int, optional
        Worker processes of the local Dask cluster (default 1). Not with ``scheduler``.
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:8786``) to use instead of a local cluster.
    threads_per_worker : int, optional
        Dr.Jit and numba threads per worker process. Default: ``cores // workers`` locally (so
        the workers do not oversubscribe the cores), the libraries' own default on a cluster.
    retries : int
        Extra attempts of a sample whose task raised (>= 0).
    variant : str, optional
        Mitsuba variant of the workers.
    progress : bool
        Show progress bars (tqdm, stderr).

    Returns
    -------
    RunReport

    Raises
    ------
    ParameterError
        If the spec or an option is invalid, or ``scheduler`` cannot be reached (before anything
        is written).
    DatasetMismatchError
        If ``out_dir`` holds anything but an earlier run of this same spec.
    DatasetBusyError
        If another run is using ``out_dir``.
    """
    start = time.perf_counter()
    if not isinstance(spec, SweepSpec):
        spec = load_spec(spec)
    if scheduler is not None and workers is not None:
        raise ParameterError(f"workers={workers!r} is for the local cluster; with scheduler={scheduler!r} leave it out")
    if scheduler is not None and (not isinstance(scheduler, str) or not scheduler):
        raise ParameterError(f"scheduler must be an address such as 'tcp://host:8786', got {scheduler!r}")
    workers = 1 if workers is None else positive_int("workers", workers)
    if isinstance(retries, bool) or not isinstance(retries, int) or retries < 0:
        raise ParameterError(f"retries must be an integer >= 0, got {retries!r}")
    if variant is not None:
        one_of("variant", variant, VARIANTS)
    if threads_per_worker is not None:
        threads_per_worker = positive_int("threads_per_worker", threads_per_worker)
    elif scheduler is None:
        threads_per_worker = max(1, _cpus() // workers)
    samples = expand(spec, progress=progress and spec.size >= 100)
    out = Path(out_dir).resolve()
    _check_target(out, spec, samples)
    failed: list[tuple[str, str, int]] = []
    rendered = 0
    with contextlib.ExitStack() as stack:
        # A cluster given by address is reached before anything is written; a local one is
        # started only if there is work.
        client = None if scheduler is None else stack.enter_context(_dask_client(workers, scheduler))
        stack.enter_context(_locked(out))  # one run at a time: a second one would delete this one's work
        _check_target(out, spec, samples)  # again, under the lock
        done = _prepare(out, spec, samples)
        pending = [s for s in samples if s.id not in done]
        if pending and client is None:
            client = stack.enter_context(_dask_client(workers, None))
        tasks = {
            s.id: SampleTask(
                id=s.id,
                index=s.index,
                seed=s.seed,
                hash=s.hash,
                params=dict(s.params),
                config=s.config,
                dataset_dir=str(out),
                outputs=spec.outputs,
                synthesis=spec.synthesis,
                views=dict(spec.views),
                threads=threads_per_worker,
                variant=variant,
            )
            for s in pending
        }
        if tasks:
            rendered, failed = _execute(out, tasks, client, retries, progress)
            for leftover in staging_leftovers(out):  # from attempts that died mid-write
                remove(leftover)
    return RunReport(
        out_dir=out,
        total=len(samples),
        skipped=len(done),
        rendered=rendered,
        failed=tuple(failed),
        seconds=time.perf_counter() - start,
    )


def _execute(
    out: Path, tasks: dict[str, SampleTask], client, retries: int, progress: bool
) -> tuple[int, list[tuple[str, str, int]]]:
    """Submit every task to ``client``, record each as it completes, retry failures; return
    (rendered, failed)."""
    from dask.distributed import as_completed

    manifest = out / MANIFEST_FILE
    rendered = 0
    failed: list[tuple[str, str, int]] = []
    run = uuid.uuid4().hex[:8]

    def submit(task: SampleTask, attempt: int):
        return client.submit(render_sample, task, key=f"lfsim-{task.id}-{run}-a{attempt}", pure=False, retries=0)

    attempts = {}
    futures = []
    for task in tasks.values():
        future = submit(task, 1)
        attempts[future.key] = (task, 1)
        futures.append(future)
    queue = as_completed(futures)
    with tqdm(total=len(tasks), desc="samples", unit="sample", disable=not progress) as bar:
        for future in queue:
            task, attempt = attempts.pop(future.key)
            if future.status == "finished":
                record = {**future.result(), "attempts": attempt, "finished_at": _now()}
                append_record(manifest, record)
                rendered += 1
                bar.update()
            else:
                error = _error_text(future)
                if attempt <= retries:
                    retry = submit(task, attempt + 1)
                    attempts[retry.key] = (task, attempt + 1)
                    queue.add(retry)
                else:
                    append_record(
                        manifest,
                        {
                            "id": task.id,
                            "index": task.index,
                            "seed": task.seed,
                            "hash": task.hash,
                            "params": task.params,
                            "status": "failed",
                            "attempts": attempt,
                            "error": error,
                            "traceback": _traceback_text(future),
                            "finished_at": _now(),
                        },
                    )
                    failed.append((task.id, error, attempt))
                    bar.update()
                    bar.set_postfix(failed=len(failed))
            future.release()
    return rendered, failed


def _error_text(future) -> str:
    if future.status == "cancelled":  # the scheduler lost the task: it has no exception to give
        return "CancelledError: the task was cancelled (scheduler or workers lost)"
    exc = future.exception()
    return f"{type(exc).__name__}: {exc}"


def _traceback_text(future) -> str:
    tb = None if future.status == "cancelled" else future.traceback()
    return "".join(traceback.format_tb(tb)) if tb is not None else ""
