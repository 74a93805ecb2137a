"""JSON sidecars: a schema version on every file, non-finite values kept standard, atomic writes."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from lfrefract.errors import FileFormatError, ParameterError
from lfrefract.formats.outputs import atomic_file
from lfrefract.validate import file_problem

#: Version of the sidecar and directory layout written by this package.
SCHEMA_VERSION = 1

__all__ = [
    "CAMERA_CALIBRATION_KIND",
    "MLA_CALIBRATION_KIND",
    "PORT_CALIBRATION_KIND",
    "SCHEMA_VERSION",
    "read_json",
    "write_json",
    "write_text_atomically",
]

#: ``kind`` of the JSON files the calibrations write (``lfrefract calibrate camera``, ``mla`` and
#: ``port``): kept here, below both the calibrations that write them and the readers of camera and
#: port files that tell them apart (:mod:`lfrefract.formats.paramfile`).
CAMERA_CALIBRATION_KIND = "lfrefract.calibrate.camera"
#: An MLA calibration: its ``mla`` table and, when the camera was known, the camera it calibrates.
MLA_CALIBRATION_KIND = "lfrefract.calibrate.mla"
PORT_CALIBRATION_KIND = "lfrefract.calibrate.port"


def _json_default(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.floating, np.integer, np.bool_)):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"cannot write {type(value).__name__} to JSON")


def _finite_json(value: Any) -> Any:
    """Replace non-finite floats by strings so the JSON stays standard."""
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    if isinstance(value, dict):
        return {k: _finite_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite_json(v) for v in value]
    return value


def write_json(path: str | os.PathLike, data: dict) -> Path:
    """Write a sidecar ``data`` (with ``schema_version`` added) as indented JSON, atomically."""
    path = Path(path)
    if "schema_version" in data:
        raise ParameterError(f"data must not set schema_version (got {data['schema_version']!r}); it is added here")
    payload = {"schema_version": SCHEMA_VERSION, **data}
    text = json.dumps(_finite_json(json.loads(json.dumps(payload, default=_json_default))), indent=2)
    return write_text_atomically(path, text + "\n")


def write_text_atomically(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` (UTF-8) to a temporary file beside ``path``, then rename it over ``path``."""
    path = Path(path)
    with atomic_file(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return path


def read_json(path: str | os.PathLike) -> dict:
    """Read a sidecar written by :func:`write_json`, checking its schema version.

    Parameters
    ----------
    path : path-like
        A JSON file, UTF-8 (RFC 8259), whose top level is an object with ``schema_version``
        :data:`SCHEMA_VERSION`.

    Returns
    -------
    dict

    Raises
    ------
    FileFormatError
        If the file is missing, not UTF-8 text (e.g. UTF-16), not JSON (or nested too deeply to
        parse), or not of this schema version; the message names the file.
    """
    path = Path(path)
    if (problem := file_problem(path)) is not None:
        raise FileFormatError(problem)
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as exc:
        raise FileFormatError(
            f"{str(path)!r} is not UTF-8 text (JSON files must be UTF-8; byte {exc.start}: {exc.reason})"
        ) from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise FileFormatError(f"{str(path)!r} is not valid JSON: {exc}") from None
    except RecursionError:
        raise FileFormatError(f"{str(path)!r} is nested too deeply to be an lfrefract JSON file") from None
    version = data.get("schema_version") if isinstance(data, dict) else None
    if version != SCHEMA_VERSION:
        raise FileFormatError(f"{str(path)!r} has schema_version {version!r}, this lfrefract reads {SCHEMA_VERSION}")
    return data
