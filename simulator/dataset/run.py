"""Run a sweep: every sample rendered by Dask workers, recorded in the manifest, resumable.

The driver (this process) checks the whole spec first (:func:`simulator.dataset.spec.iter_samples`,
holding only each sample's small record), then creates the dataset folder with ``dataset.json``,
or, if the folder holds an earlier run of the same spec with the same samples (input files
included), resumes it. It holds a lock on the folder (``flock``) for the whole run, so a second run
on the same folder is refused instead of deleting the first one's work. On resume it drops an
unterminated last manifest line, removes staging leftovers, re-renders done samples whose files
went missing, changed size or changed their SHA-256 (every file is read to its end, on every resume:
see :func:`simulator.dataset.check.verify_folders`), removes the folders of samples that are not
recorded as done, and skips the done ones.
Each remaining sample is one Dask task that renders it into its folder
(:func:`simulator.dataset.sample.render_sample`) and returns its manifest record; the driver builds
the tasks as it goes, keeping a bounded number in flight, and alone appends records, as the tasks
complete. A task that raises is submitted again, up to ``retries`` more times, then recorded as
failed with its error and the attempt count; a later run tries failed samples again.

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
from lfrefract._memory import available_cpus
from lfrefract.errors import FileFormatError, ParameterError
from lfrefract.formats.jsonio import write_json
from lfrefract.formats.outputs import on_termination
from lfrefract.validate import one_of, positive_int
from simulator.backend import VARIANTS
from simulator.dataset.check import verify_folders
from simulator.dataset.manifest import (
    DATASET_FILE,
    DATASET_KIND,
    MANIFEST_FILE,
    DigestCache,
    append_record,
    latest_records,
    read_dataset,
    read_manifest,
    remove,
    staging_leftovers,
)
from simulator.dataset.sample import SampleTask, render_sample
from simulator.dataset.spec import SweepSpec, iter_samples, load_spec

__all__ = ["DatasetBusyError", "DatasetMismatchError", "RunReport", "check_run_options", "run_dataset"]


#: How long to try to reach a scheduler given by address before giving up.
SCHEDULER_TIMEOUT = "30s"
#: Seconds a Ctrl-C or SIGTERM waits for the local cluster's workers to stop before the process ends.
STOP_TIMEOUT_S = 10

#: Tasks kept in flight: this many per worker thread of the cluster, at least ``_IN_FLIGHT_MIN``
#: (the rest are built as these complete, so the driver never holds every sample's scene).
_IN_FLIGHT_PER_THREAD = 4
_IN_FLIGHT_MIN = 64


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
    damaged : tuple of str
        Samples recorded done by an earlier run whose folder failed the resume's verification
        (a file missing, of another size, or with another SHA-256): removed and rendered again.
    verification : str
        What the resume verified, how long the hashing took, and which file of each damaged sample
        differed (one sentence; empty when no sample was done before).
    """

    out_dir: Path
    total: int
    skipped: int
    rendered: int
    failed: tuple[tuple[str, str, int], ...]
    seconds: float
    damaged: tuple[str, ...] = ()
    verification: str = ""

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


def _plan(spec: SweepSpec, digests: DigestCache, progress: bool) -> tuple[list[dict], dict[str, dict]]:
    """Build and check every sample (one at a time); return their records (``dataset.json``'s
    ``samples``) and the input files they read (path -> ``{"bytes", "sha256"}``)."""
    planned = []
    inputs: dict[str, dict] = {}
    for sample in iter_samples(spec, progress=progress, digests=digests):
        planned.append(sample.record())
        for path, entry in sample.inputs.items():
            entry = dict(entry)
            if inputs.setdefault(path, entry) != entry:
                raise FileFormatError(
                    f"input file {path!r} changed while the sweep was being checked (SHA-256 {entry['sha256']}, "
                    f"earlier {inputs[path]['sha256']}): run again once it stays the same"
                )
    return planned, inputs


def _rejections(planned: list[dict]) -> dict:
    """The draws refused while planning (``[constraints]``, ``sweep.redraw_impossible``): in all,
    the samples drawn more than once, and by reason."""
    by_reason: dict[str, int] = {}
    for record in planned:
        for reason, count in record.get("rejected", {}).items():
            by_reason[reason] = by_reason.get(reason, 0) + count
    redrawn = sum(1 for record in planned if record.get("rejected"))
    return {"draws_refused": sum(by_reason.values()), "samples_redrawn": redrawn, "by_reason": by_reason}


def _check_target(out: Path, spec: SweepSpec, planned: list[dict], inputs: dict[str, dict]) -> None:
    """Raise unless ``out`` is absent, empty, or a dataset of this spec with these samples and
    input files (reads only)."""
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
        changed = [s["id"] for s in planned if known.get(s["id"]) != s["hash"]]
        if changed or len(known) != len(planned):
            before = earlier.get("inputs") if isinstance(earlier.get("inputs"), dict) else {}
            edited = sorted(p for p, entry in inputs.items() if p in before and before[p] != entry)
            why = (
                f"input file(s) edited since: {edited[:3]}"
                if edited
                else "a base scene or an input file (mesh, hashed by content) may have changed"
            )
            raise DatasetMismatchError(
                f"{str(out)!r} was made from this spec but its samples differ now ({len(changed)} of {len(planned)} "
                f"changed, e.g. {changed[:3]}; {why}): refusing to mix datasets; use another --out, or restore "
                "the files it was made with"
            )


def _prepare(
    out: Path, spec: SweepSpec, planned: list[dict], inputs: dict[str, dict], *, progress: bool = False
) -> tuple[dict[str, dict], list[str], str]:
    """Create the dataset folder, or tidy an earlier run of the same spec (see the module
    docstring); return the latest manifest record of every sample that is done and intact, the
    ids of done samples that failed verification (removed), and what was verified (a sentence)."""
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
                "set": {key: value for key, value in spec.to_dict().get("set", {}).items()},
                "image_format": spec.image_format,
                "rejections": _rejections(planned),
                "created": _now(),
                "lfrefract": lfrefract.__version__,
                "inputs": inputs,
                "samples": planned,
            },
        )
    for leftover in staging_leftovers(out):
        remove(leftover)
    latest = latest_records(read_manifest(out / MANIFEST_FILE, repair=True))
    recorded = []  # (sample id, record) of the samples recorded done, for the planned sample
    for sample in planned:
        sid = sample["id"]
        record = latest.get(sid)
        if record is not None and record["status"] == "done" and record.get("hash") == sample["hash"]:
            recorded.append((sid, record))
        elif (out / sid).exists():  # rendered but never recorded (killed in between), or failed since
            remove(out / sid)
    start = time.perf_counter()
    found = verify_folders(((out / sid, record) for sid, record in recorded), hashes=True, progress=progress)
    seconds = time.perf_counter() - start
    done = {}
    damaged = []
    why = []
    files = size = 0
    for (sid, record), problem in zip(recorded, found, strict=True):
        files += len(record["files"])
        size += sum(entry["bytes"] for entry in record["files"].values())
        if problem is None:
            done[sid] = record
            continue
        damaged.append(sid)
        why.append(f"{sid}: {problem.detail}")
        if (out / sid).exists():
            remove(out / sid)
    verification = ""
    if recorded:
        per_gb = f": {seconds / (size / 1e9):.1f} s per GB" if size else ""
        verification = (
            f"resume verified {len(recorded)} done sample(s) by the SHA-256 of every file ({files} files, "
            f"{size / 1e6:.1f} MB, in {seconds:.3g} s{per_gb}); {len(damaged)} failed and "
            f"{'were' if len(damaged) != 1 else 'was'} rendered again"
            + (f" ({'; '.join(why[:5])}{'; ...' if len(why) > 5 else ''})" if why else "")
        )
    return done, damaged, verification


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
    with _ignoring_sigint():  # the workers inherit it: Ctrl-C reaches them too, and the driver stops them
        cluster = LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            # A port of the system's choosing: with None the scheduler's web server still takes 8787, and a
            # second cluster on the machine (another run, another test worker) then warns and fails under
            # warnings-as-errors.
            dashboard_address=":0",
            silence_logs=logging.CRITICAL,  # task errors reach the manifest and the report; no worker log noise
        )
    try:
        with Client(cluster) as client, on_termination(lambda: _stop_cluster(client, cluster)):
            yield client
    finally:
        cluster.close()


@contextlib.contextmanager
def _ignoring_sigint() -> Iterator[None]:
    """SIGINT ignored while the block runs (in the main thread; elsewhere the block runs unchanged).

    A Ctrl-C in a terminal goes to every process of the foreground group: the local cluster's worker
    processes, started in this block, inherit the ignoring (Python keeps an inherited SIG_IGN), so they
    print no KeyboardInterrupt traceback of their own; the driver's handler (terminate_cleanly) stops them.
    """
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _stop_cluster(client, cluster) -> None:
    """Stop the local cluster's workers from a signal handler (Ctrl-C, SIGTERM), so that none writes on
    once the handler removes the unfinished samples. The cluster runs its own event loop in a thread,
    which does the closing; after STOP_TIMEOUT_S the process ends anyway. Its worker processes (the
    nannies and their workers) are waited for, and killed if still running then: closing the cluster
    returns once the nannies report, while a worker may still be ending, and the handler removes the
    unfinished samples as soon as this returns."""
    import threading

    import psutil

    workers = psutil.Process().children(recursive=True)
    started = time.monotonic()

    def close() -> None:
        with contextlib.suppress(Exception):
            client.close(timeout=STOP_TIMEOUT_S)
        with contextlib.suppress(Exception):
            cluster.close(timeout=STOP_TIMEOUT_S)

    closer = threading.Thread(target=close, daemon=True)
    closer.start()
    closer.join(STOP_TIMEOUT_S)
    end_processes(workers, timeout_s=max(STOP_TIMEOUT_S - (time.monotonic() - started), 1.0))
    # The process ends with os._exit, which skips the exit handlers: release multiprocessing's named
    # semaphores as a normal exit would (else its resource tracker warns of them on standard error).
    from multiprocessing import util

    with contextlib.suppress(Exception):
        util._run_finalizers(0)


def end_processes(processes: list, *, timeout_s: float) -> None:
    """Wait up to ``timeout_s`` seconds for ``processes`` (``psutil.Process``) to exit, then kill the ones
    still running and reap them, so that none outlives the call. Processes already gone are skipped."""
    import psutil

    _, alive = psutil.wait_procs(processes, timeout=timeout_s)
    for process in alive:
        with contextlib.suppress(psutil.NoSuchProcess):
            process.kill()
    psutil.wait_procs(alive, timeout=STOP_TIMEOUT_S)


def _remove_leftovers(out: Path) -> None:
    """Remove the half-written entries of ``out`` (the staging folders of samples being rendered)."""
    for leftover in staging_leftovers(out):
        with contextlib.suppress(OSError):
            remove(leftover)


def check_run_options(
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    threads_per_worker: int | None = None,
    retries: int = 2,
    variant: str | None = None,
) -> None:
    """Check the options of :func:`run_dataset` (but the spec and the output) as it does, before
    any work; ``lfsim dataset run`` checks each alone to name its flag.

    Raises
    ------
    ParameterError
        For ``workers`` together with ``scheduler``, an empty scheduler address, ``workers`` or
        ``threads_per_worker`` not a positive integer, ``workers`` beyond the CPUs this process may
        use, ``retries`` not an integer >= 0, or an
        unknown ``variant``; the message names the parameter and its value.
    """
    if scheduler is not None and workers is not None:
        raise ParameterError(f"workers={workers!r} is for the local cluster; with scheduler={scheduler!r} leave it out")
    if scheduler is not None and (not isinstance(scheduler, str) or not scheduler):
        raise ParameterError(f"scheduler must be an address such as 'tcp://host:8786', got {scheduler!r}")
    if workers is not None:
        positive_int("workers", workers)
        cpus = available_cpus()
        if workers > cpus:
            raise ParameterError(
                f"workers={workers} worker processes for a local cluster on {cpus} CPU(s): each renders on every CPU "
                "it is given, so more processes than CPUs only add memory (a Mitsuba process each); give at most "
                f"{cpus}, or start a cluster of more machines and give its scheduler"
            )
    if isinstance(retries, bool) or not isinstance(retries, int) or retries < 0:
        raise ParameterError(f"retries must be an integer >= 0, got {retries!r}")
    if variant is not None:
        one_of("variant", variant, VARIANTS)
    if threads_per_worker is not None:
        positive_int("threads_per_worker", threads_per_worker)


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
    check_run_options(
        workers=workers, scheduler=scheduler, threads_per_worker=threads_per_worker, retries=retries, variant=variant
    )
    workers = 1 if workers is None else int(workers)
    if threads_per_worker is not None:
        threads_per_worker = int(threads_per_worker)
    elif scheduler is None:
        threads_per_worker = max(1, _cpus() // workers)
    digests = DigestCache()  # an input file many samples read is hashed once per run
    planned, inputs = _plan(spec, digests, progress and spec.size >= 100)
    out = Path(out_dir).resolve()
    _check_target(out, spec, planned, inputs)
    failed: list[tuple[str, str, int]] = []
    rendered = 0
    with contextlib.ExitStack() as stack:
        # A cluster given by address is reached before anything is written; a local one is
        # started only if there is work.
        client = None if scheduler is None else stack.enter_context(_dask_client(workers, scheduler))
        stack.enter_context(_locked(out))  # one run at a time: a second one would delete this one's work
        if scheduler is None:
            # Ctrl-C or SIGTERM (terminate_cleanly): after the local workers stop (registered later, so run
            # first), the samples they left half-written go. A scheduler's workers are not ours to stop:
            # what they leave, the next run removes.
            stack.enter_context(on_termination(lambda: _remove_leftovers(out)))
        _check_target(out, spec, planned, inputs)  # again, under the lock
        done, damaged, verification = _prepare(out, spec, planned, inputs, progress=progress)
        pending = [r for r in planned if r["id"] not in done]
        if pending and client is None:
            client = stack.enter_context(_dask_client(workers, None))

        def tasks() -> Iterator[SampleTask]:
            """The pending samples' tasks, built one at a time (again from the spec: each must
            still be the planned sample, its input files unchanged)."""
            hashes = {r["index"]: r["hash"] for r in pending}
            for s in iter_samples(spec, indices=sorted(hashes), digests=digests):
                if s.hash != hashes[s.index]:
                    raise DatasetMismatchError(
                        f"sample {s.id} differs from the one planned at the start of this run (a base scene or an "
                        f"input file such as {sorted(s.inputs)[:2]} changed during the run): nothing more is "
                        "submitted; the samples recorded so far are kept, and a new run on this folder is refused "
                        "until the files are restored"
                    )
                yield SampleTask(
                    id=s.id,
                    index=s.index,
                    seed=s.seed,
                    hash=s.hash,
                    params=dict(s.params),
                    config=s.config,
                    dataset_dir=str(out),
                    outputs=spec.outputs,
                    synthesis=spec.synthesis,
                    views=spec.views,
                    image_format=spec.image_format,
                    inputs={path: entry["sha256"] for path, entry in s.inputs.items()},
                    threads=threads_per_worker,
                    variant=variant,
                )

        if pending:
            rendered, failed = _execute(out, tasks(), len(pending), client, retries, progress)
            for leftover in staging_leftovers(out):  # from attempts that died mid-write
                remove(leftover)
    return RunReport(
        out_dir=out,
        total=len(planned),
        skipped=len(done),
        rendered=rendered,
        failed=tuple(failed),
        seconds=time.perf_counter() - start,
        damaged=tuple(damaged),
        verification=verification,
    )


def _in_flight(client) -> int:
    """How many tasks to keep submitted: a few per worker thread of the cluster."""
    threads = sum(client.nthreads().values())
    return max(_IN_FLIGHT_MIN, _IN_FLIGHT_PER_THREAD * threads)


def _execute(
    out: Path, tasks: Iterator[SampleTask], total: int, client, retries: int, progress: bool
) -> tuple[int, list[tuple[str, str, int]]]:
    """Submit the tasks to ``client`` (a bounded number at a time), record each as it completes,
    retry failures; return (rendered, failed)."""
    from dask.distributed import as_completed

    manifest = out / MANIFEST_FILE
    rendered = 0
    failed: list[tuple[str, str, int]] = []
    run = uuid.uuid4().hex[:8]
    window = _in_flight(client)
    attempts: dict[str, tuple[SampleTask, int]] = {}
    queue = as_completed()

    def submit(task: SampleTask, attempt: int) -> None:
        future = client.submit(render_sample, task, key=f"lfsim-{task.id}-{run}-a{attempt}", pure=False, retries=0)
        attempts[future.key] = (task, attempt)
        queue.add(future)

    def top_up() -> None:
        while len(attempts) < window and (task := next(tasks, None)) is not None:
            submit(task, 1)

    top_up()
    with tqdm(total=total, desc="samples", unit="sample", disable=not progress) as bar:
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
                    submit(task, attempt + 1)
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
            top_up()
    return rendered, failed


def _error_text(future) -> str:
    if future.status == "cancelled":  # the scheduler lost the task: it has no exception to give
        return "CancelledError: the task was cancelled (scheduler or workers lost)"
    exc = future.exception()
    return f"{type(exc).__name__}: {exc}"


def _traceback_text(future) -> str:
    tb = None if future.status == "cancelled" else future.traceback()
    return "".join(traceback.format_tb(tb)) if tb is not None else ""
