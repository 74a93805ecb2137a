"""Verify a dataset against its manifest: every planned sample done, with every file intact, and
rendered from input files (meshes) that are still what they were when the run was planned."""

from __future__ import annotations

import os
from collections.abc import Iterable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

from tqdm.auto import tqdm

from lfrefract.errors import FileFormatError, ParameterError
from lfrefract.validate import positive_int
from simulator.dataset.manifest import (
    MANIFEST_FILE,
    DigestCache,
    file_digest,
    latest_records,
    read_dataset,
    read_manifest,
    staging_leftovers,
)
from simulator.dataset.spec import toml_digest

__all__ = ["PROBLEMS", "CheckReport", "SampleProblem", "check_dataset", "verify_folder", "verify_folders"]

#: Kinds of problem, in the order they are reported.
PROBLEMS = ("missing", "corrupt", "stale", "failed", "not run")


@dataclass(frozen=True)
class SampleProblem:
    """One sample that is not done and intact.

    Attributes
    ----------
    id : str
    kind : {"missing", "corrupt", "stale", "failed", "not run"}
        ``missing``: recorded done, but its folder or a file is gone. ``corrupt``: a file's size
        or SHA-256 differs from the record, a file is not in the record, or the record is not
        the planned sample's. ``stale``: done and intact, but an input file it was rendered from
        (a mesh, or its base scene's TOML content) has changed since the run was planned.
        ``failed``: its latest record is a failure. ``not run``: no record.
    detail : str
        What exactly (the file, the error).
    """

    id: str
    kind: str
    detail: str


@dataclass(frozen=True)
class CheckReport:
    """What :func:`check_dataset` found.

    Attributes
    ----------
    root : Path
    total : int
        Planned samples.
    verified : int
        Samples done with every file present and matching its size and SHA-256, and their input
        files unchanged.
    problems : tuple of SampleProblem
        The others, in sample order.
    leftovers : tuple of str
        Staging folders and temporary files of interrupted writes (the next run removes them).
    inputs_gone : tuple of str
        Input files (meshes) recorded in ``dataset.json`` that are not on this machine (a copied
        dataset, say): the samples that read them cannot be checked against them.
    """

    root: Path
    total: int
    verified: int
    problems: tuple[SampleProblem, ...]
    leftovers: tuple[str, ...]
    inputs_gone: tuple[str, ...] = ()

    @property
    def ok(self) -> bool:
        """Every planned sample is done and intact."""
        return not self.problems

    def count(self, kind: str) -> int:
        """Number of problems of one kind (see :data:`PROBLEMS`)."""
        return sum(p.kind == kind for p in self.problems)

    def summary(self) -> str:
        """One line: the counts."""
        counts = ", ".join(f"{self.count(kind)} {kind}" for kind in PROBLEMS)
        return f"{self.root}: {self.total} samples, {self.verified} verified; {counts}"


def verify_folder(folder: Path, record: dict, *, hashes: bool) -> SampleProblem | None:
    """The problem of a done sample's folder against its manifest record, or None if it holds
    exactly the recorded files with their sizes (and, with ``hashes``, their SHA-256s: every file,
    read to its end)."""
    sid = record["id"]
    if not folder.is_dir():
        return SampleProblem(sid, "missing", f"folder {folder.name}/ is missing")
    files = record.get("files") or {}
    present = {p.relative_to(folder).as_posix(): p for p in folder.rglob("*") if p.is_file()}
    gone = sorted(set(files) - set(present))
    if gone:
        return SampleProblem(sid, "missing", f"missing file(s) {gone}")
    extra = sorted(set(present) - set(files))
    if extra:
        return SampleProblem(sid, "corrupt", f"file(s) not in the manifest: {extra}")
    for name, entry in files.items():
        size = present[name].stat().st_size
        if size != entry["bytes"]:
            return SampleProblem(sid, "corrupt", f"{name}: {size} bytes, recorded {entry['bytes']}")
    if hashes:
        for name, entry in files.items():
            _, sha = file_digest(present[name])
            if sha != entry["sha256"]:
                recorded = entry["sha256"]
                return SampleProblem(sid, "corrupt", f"{name}: SHA-256 {sha[:12]}..., recorded {recorded[:12]}...")
    return None


def verify_folders(
    folders: Iterable[tuple[Path, dict]], *, hashes: bool, threads: int | None = None, progress: bool = False
) -> list[SampleProblem | None]:
    """:func:`verify_folder` of each ``(folder, record)``, in order, several at a time.

    Parameters
    ----------
    folders : iterable of (Path, dict)
        Each done sample's folder and its manifest record.
    hashes : bool
        Compare SHA-256s too (every file read to its end), not only the sizes.
    threads : int, optional
        Folders verified at once; default one per core (``hashlib`` and file reads release the GIL,
        so the hashing of a large dataset runs on every core, or as fast as the disk reads).
    progress : bool
        Show a progress bar (tqdm, stderr).

    Returns
    -------
    list of SampleProblem or None
        Each folder's problem, or None where it is intact.
    """
    folders = list(folders)
    if not folders:
        return []
    threads = _cpus() if threads is None else positive_int("threads", threads)
    with (
        ThreadPoolExecutor(max_workers=min(threads, len(folders))) as pool,
        tqdm(total=len(folders), desc="verifying", unit="sample", disable=not progress) as bar,
    ):

        def one(item: tuple[Path, dict]) -> SampleProblem | None:
            problem = verify_folder(item[0], item[1], hashes=hashes)
            bar.update()
            return problem

        return list(pool.map(one, folders))


def _cpus() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def check_dataset(root: str | os.PathLike, *, hashes: bool = True) -> CheckReport:
    """Check every planned sample of a dataset against the manifest.

    Parameters
    ----------
    root : path-like
        The dataset folder (``dataset.json``, ``manifest.jsonl``, sample folders).
    hashes : bool
        Re-hash every file (SHA-256), input files included; False compares sizes only.

    Returns
    -------
    CheckReport

    Raises
    ------
    FileFormatError
        If ``root`` holds no ``dataset.json``, or a complete manifest line is not a record.
    """
    root = Path(root)
    info = read_dataset(root)
    planned = info["samples"]
    recorded_inputs = info.get("inputs") or {}
    latest = latest_records(read_manifest(root / MANIFEST_FILE))
    changed_inputs, gone = _changed_inputs(recorded_inputs, hashes=hashes)
    problems = []
    to_verify = []
    verified = 0
    for sample in planned:
        sid = sample["id"]
        record = latest.get(sid)
        if record is None:
            on_disk = " (a folder exists but is not recorded)" if (root / sid).exists() else ""
            problems.append(SampleProblem(sid, "not run", f"no manifest record{on_disk}"))
            continue
        if record["status"] == "failed":
            error = record.get("error", "?")
            problems.append(SampleProblem(sid, "failed", f"after {record.get('attempts', '?')} attempt(s): {error}"))
            continue
        if record.get("hash") != sample["hash"] or record.get("index") != sample["index"]:
            problems.append(SampleProblem(sid, "corrupt", "its manifest record is not the planned sample's"))
            continue
        to_verify.append((sample, record))
    found = verify_folders(((root / sample["id"], record) for sample, record in to_verify), hashes=hashes)
    for (sample, _), problem in zip(to_verify, found, strict=True):
        sid = sample["id"]
        if problem is None:
            edited = [changed_inputs[p] for p in sample.get("inputs", ()) if p in changed_inputs]
            if edited:
                problem = SampleProblem(sid, "stale", f"rendered from an input file that changed since: {edited[0]}")
        if problem is None:
            verified += 1
        else:
            problems.append(problem)
    order = {sample["id"]: i for i, sample in enumerate(planned)}
    return CheckReport(
        root=root,
        total=len(planned),
        verified=verified,
        problems=tuple(sorted(problems, key=lambda problem: order[problem.id])),
        leftovers=tuple(p.name for p in staging_leftovers(root)),
        inputs_gone=tuple(gone),
    )


def _changed_inputs(recorded: dict, *, hashes: bool) -> tuple[dict[str, str], list[str]]:
    """Input files that differ from ``dataset.json``'s record (path -> what differs), and those
    that are gone."""
    digests = DigestCache()
    changed: dict[str, str] = {}
    gone = []
    for path, entry in sorted(recorded.items()):
        if not Path(path).is_file():
            gone.append(path)
            continue
        if "toml_sha256" in entry:  # a base scene: its TOML content counts, not its formatting
            try:
                now = toml_digest(path)
            except (FileFormatError, ParameterError) as exc:
                changed[path] = f"{path!r} (no longer a readable scene: {exc})"
                continue
            if now != entry["toml_sha256"]:
                changed[path] = f"{path!r} (its TOML content changed since the run was planned)"
            continue
        if hashes:
            size, sha = digests.digest(path)
        else:
            size, sha = Path(path).stat().st_size, entry["sha256"]
        if size != entry["bytes"] or sha != entry["sha256"]:
            changed[path] = (
                f"{path!r} ({size} bytes, SHA-256 {sha[:12]}...; when planned {entry['bytes']} bytes, "
                f"{entry['sha256'][:12]}...)"
            )
    return changed, gone
