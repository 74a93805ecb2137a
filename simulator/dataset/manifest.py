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

import hashlib
import json
import os
import shutil
from pathlib import Path

from lfrefract.io import FileFormatError, read_json

__all__ = [
    "DATASET_FILE",
    "MANIFEST_FILE",
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
        If it is missing, unreadable, or not a dataset description.
    """
    data = read_json(Path(root) / DATASET_FILE)
    if data.get("kind") != DATASET_KIND or not isinstance(data.get("samples"), list):
        raise FileFormatError(f"{str(Path(root) / DATASET_FILE)!r} is not an lfsim dataset description")
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
        If a complete line is not a JSON record with an ``id`` and a ``status``.
    """
    path = Path(path)
    if not path.is_file():
        return []
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
            record = json.loads(line)
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise FileFormatError(f"{str(path)!r} line {number} is not a JSON record: {exc}") from None
        if not isinstance(record, dict) or "id" not in record or record.get("status") not in ("done", "failed"):
            raise FileFormatError(f"{str(path)!r} line {number} is not a sample record: {line[:200]!r}")
        records.append(record)
    return records


def append_record(path: Path, record: dict) -> None:
    """Append one record as a JSON line, flushed and fsynced before returning."""
    line = json.dumps(record, separators=(",", ":"), allow_nan=False) + "\n"
    with Path(path).open("a", encoding="utf-8") as fh:
        fh.write(line)
        fh.flush()
        os.fsync(fh.fileno())


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
