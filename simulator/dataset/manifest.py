"""The on-disk layout of a dataset: ``dataset.json``, ``manifest.jsonl`` and the sample folders.

::

    DIR/
      dataset.json        the spec, its hash, and every planned sample (id, index, seed, params, hash)
      manifest.jsonl      one JSON record per line, appended by the driver as samples finish
      s000000/            one folder per done sample (renamed into place when complete)
      s000001/
      ...

A manifest record is ``{"id", "index", "seed", "hash", "params", "status", "attempts",
"finished_at", ...}``: with ``status = "done"`` also ``files`` (relative path -> ``{"bytes",
"sha256"}``), ``seconds`` and ``worker``; with ``status = "failed"`` also ``error`` and
``traceback``. A sample's latest record is its state. A record counts once its line, newline
included, is on disk: an unterminated last line (a run killed while writing it) is ignored.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
from pathlib import Path

from lfrefract.errors import FileFormatError
from lfrefract.formats.jsonio import read_json

__all__ = [
    "DATASET_FILE",
    "MANIFEST_FILE",
    "DigestCache",
    "append_record",
    "file_digest",
    "folder_files",
    "latest_records",
    "read_dataset",
    "read_manifest",
    "staging_leftovers",
]

DATASET_FILE = "dataset.json"
MANIFEST_FILE = "manifest.jsonl"
#: ``kind`` of ``dataset.json``.
DATASET_KIND = "lfsim.dataset"
_CHUNK = 1 << 20


def file_digest(path: Path) -> tuple[int, str]:
    """Size in bytes and SHA-256 (hex) of a file, read in 1 MiB chunks."""
    digest = hashlib.sha256()
    size = 0
    with Path(path).open("rb") as fh:
        while chunk := fh.read(_CHUNK):
            digest.update(chunk)
            size += len(chunk)
    return size, digest.hexdigest()


class DigestCache:
    """Sizes and SHA-256s of files, each file read once while it stays the same file, unchanged: a
    mesh that many samples of a run use is hashed once.

    A file counts as unchanged while its path, device, inode, size, modification time and status
    change time (ns) all stay the same. Path, size and mtime alone are not enough: a same-size file
    copied over it with ``cp -p`` (or ``touch -d``) keeps the mtime, and one renamed into place keeps
    its own. The status change time (ctime) is set by the kernel on every write, rename and
    ``utime`` and cannot be set by a user, so such an edit is seen; a rename also changes the inode.
    The cache lives in one process (one run); nothing is kept between runs.
    """

    def __init__(self) -> None:
        self._known: dict[tuple[str, int, int, int, int, int], tuple[int, str]] = {}

    def digest(self, path: str | os.PathLike) -> tuple[int, str]:
        """Size in bytes and SHA-256 (hex) of the file at ``path`` (:func:`file_digest`).

        Raises
        ------
        OSError
            If it cannot be read.
        """
        path = Path(path)
        key = self._key(path)
        if key in self._known:
            return self._known[key]
        digest = file_digest(path)
        if self._key(path) == key:  # not kept if the file changed while it was read
            self._known[key] = digest
        return digest

    @staticmethod
    def _key(path: Path) -> tuple[str, int, int, int, int, int]:
        stat = path.stat()
        return (str(path), stat.st_dev, stat.st_ino, stat.st_size, stat.st_mtime_ns, stat.st_ctime_ns)


def folder_files(folder: Path) -> dict[str, dict]:
    """Every file under ``folder`` (relative POSIX path -> ``{"bytes", "sha256"}``), sorted."""
    folder = Path(folder)
    out = {}
    for path in sorted(p for p in folder.rglob("*") if p.is_file()):
        size, sha = file_digest(path)
        out[path.relative_to(folder).as_posix()] = {"bytes": size, "sha256": sha}
    return out


def read_dataset(root: Path) -> dict:
    """``dataset.json`` of the dataset at ``root``.

    Raises
    ------
    FileFormatError
        If it is missing, not UTF-8 JSON, or not a dataset description (``kind``, a list of
        ``samples`` with ``id``, ``index`` and ``hash``, and ``inputs``, if given, a table of
        files with their ``bytes`` and ``sha256``).
    """
    path = Path(root) / DATASET_FILE
    try:
        data = read_json(path)
    except UnicodeDecodeError as exc:
        raise FileFormatError(
            f"{str(path)!r} is not UTF-8 text (byte {exc.start} cannot be decoded): not a dataset description"
        ) from None
    samples = data.get("samples")
    if data.get("kind") != DATASET_KIND or not isinstance(samples, list):
        raise FileFormatError(f"{str(path)!r} is not an lfsim dataset description")
    for i, sample in enumerate(samples):
        if not isinstance(sample, dict) or not {"id", "index", "hash"} <= set(sample):
            raise FileFormatError(
                f"{str(path)!r}: samples[{i}] is not a planned sample (id, index, hash): {sample!r:.200}"
            )
    if not _file_table(data.get("inputs", {})):
        raise FileFormatError(f"{str(path)!r}: 'inputs' is not a table of files with their bytes and sha256")
    return data


def read_manifest(path: Path, *, repair: bool = False) -> list[dict]:
    """The records of a manifest, in file order (empty if the file does not exist).

    Parameters
    ----------
    path : Path
        ``manifest.jsonl``.
    repair : bool
        Cut an unterminated last line off the file (the driver does, before it appends).

    Raises
    ------
    FileFormatError
        If the path is not a regular file (a folder, say), or a complete line is not a UTF-8
        JSON record with an ``id`` and a ``status``.
    """
    path = Path(path)
    if not path.exists():
        return []
    if not path.is_file():
        raise FileFormatError(f"{str(path)!r} is not a file: a dataset manifest is a file of JSON lines")
    data = path.read_bytes()
    end = data.rfind(b"\n") + 1
    if end < len(data) and repair:
        with path.open("r+b") as fh:
            fh.truncate(end)
            fh.flush()
            os.fsync(fh.fileno())
    records = []
    for number, line in enumerate(data[:end].splitlines(), start=1):
        try:
            record = json.loads(line.decode("utf-8"))
        except UnicodeDecodeError as exc:
            raise FileFormatError(f"{str(path)!r} line {number} is not UTF-8 text (byte {exc.start})") from None
        except json.JSONDecodeError as exc:
            raise FileFormatError(f"{str(path)!r} line {number} is not a JSON record: {exc}") from None
        if not isinstance(record, dict) or "id" not in record or record.get("status") not in ("done", "failed"):
            raise FileFormatError(f"{str(path)!r} line {number} is not a sample record: {line[:200]!r}")
        if record["status"] == "done" and not _file_table(record.get("files")):
            raise FileFormatError(
                f"{str(path)!r} line {number}: a done record needs 'files', a table of paths with their bytes and "
                f"sha256: {line[:200]!r}"
            )
        records.append(record)
    return records


def _file_table(files: object) -> bool:
    """Whether ``files`` is a manifest's table of files: relative path -> ``{"bytes", "sha256"}``."""
    return isinstance(files, dict) and all(
        isinstance(name, str)
        and isinstance(entry, dict)
        and isinstance(entry.get("bytes"), int)
        and isinstance(entry.get("sha256"), str)
        for name, entry in files.items()
    )


def append_record(path: Path, record: dict) -> None:
    """Append one record as a JSON line, flushed and fsynced before returning.

    Raises
    ------
    OSError
        If the line cannot be written (disk full, file too large, read-only, ...): the file is
        first cut back to its earlier length, so no part of the line stays (if that cut fails
        too, the next run drops the unterminated line).
    """
    line = (json.dumps(record, separators=(",", ":"), allow_nan=False) + "\n").encode("utf-8")
    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o666)
    try:
        end = os.lseek(fd, 0, os.SEEK_END)
        try:
            view = memoryview(line)
            while view:
                view = view[os.write(fd, view) :]
            os.fsync(fd)
        except OSError as exc:
            with contextlib.suppress(OSError):  # the write's error is the one to report
                os.ftruncate(fd, end)
            if exc.filename is None:  # os.write and os.fsync do not name the file
                exc.filename = str(path)
            raise
    finally:
        os.close(fd)


def latest_records(records: list[dict]) -> dict[str, dict]:
    """Each sample's latest record, by id."""
    out: dict[str, dict] = {}
    for record in records:
        out[record["id"]] = record
    return out


def staging_leftovers(root: Path) -> list[Path]:
    """Half-written entries at the top of ``root``: staging folders (``.*.partial``) and temporary
    files (``.*.tmp``) of writes that were interrupted."""
    root = Path(root)
    if not root.is_dir():
        return []
    return sorted(p for p in root.iterdir() if p.name.startswith(".") and p.name.endswith((".partial", ".tmp")))


def remove(path: Path) -> None:
    """Remove a file or a folder tree."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    else:
        path.unlink(missing_ok=True)
