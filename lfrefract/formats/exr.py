"""Float OpenEXR images (OpenEXR), tagged with the role they play and the schema version."""

from __future__ import annotations

import errno
import os
from pathlib import Path

import numpy as np
import OpenEXR

from lfrefract.errors import FileFormatError, ParameterError
from lfrefract.formats.jsonio import SCHEMA_VERSION
from lfrefract.formats.outputs import atomic_file
from lfrefract.validate import file_problem

_ROLE_KEY = "lfrefract_role"
_SCHEMA_KEY = "lfrefract_schema_version"

__all__ = ["read_exr", "write_exr"]


def write_exr(path: str | os.PathLike, image: np.ndarray, *, role: str) -> Path:
    """Write a float image as a ZIP-compressed float32 OpenEXR file, atomically.

    Parameters
    ----------
    path : path-like
        Destination ``.exr`` file.
    image : ndarray, shape (H, W) or (H, W, 3)
        Real-valued image; a single channel is stored as ``Y``, three as ``RGB``. NaN and
        +-inf are stored as they are (a depth map marks "no surface" with +inf).
    role : str
        What the image is (``"raw"``, ``"ideal"``, ``"depth"``, ...), stored in the header.

    Returns
    -------
    Path
        The written path.

    Raises
    ------
    OSError
        If the file cannot be written (a full disk, a read-only folder), naming ``path`` and the cause;
        OpenEXR's own failures (``RuntimeError``) become this too. Nothing is left at ``path``.
    """
    path = Path(path)
    arr = np.asarray(image)
    if not np.issubdtype(arr.dtype, np.floating) and not np.issubdtype(arr.dtype, np.integer):
        raise ParameterError(f"image must hold real numbers, got dtype {arr.dtype}")
    finite = arr[np.isfinite(arr)] if np.issubdtype(arr.dtype, np.floating) else arr
    if finite.size and np.max(np.abs(finite)) > np.finfo(np.float32).max:
        raise ParameterError(
            f"image holds finite values beyond float32's range, e.g. {float(np.max(np.abs(finite)))!r}"
        )
    if arr.ndim == 2:
        channels = {"Y": np.ascontiguousarray(arr, dtype=np.float32)}
    elif arr.ndim == 3 and arr.shape[2] == 3:
        channels = {"RGB": np.ascontiguousarray(arr, dtype=np.float32)}
    else:
        raise ParameterError(f"image must have shape (H, W) or (H, W, 3), got {arr.shape}")
    header = {
        "compression": OpenEXR.ZIP_COMPRESSION,
        "type": OpenEXR.scanlineimage,
        _ROLE_KEY: str(role),
        _SCHEMA_KEY: str(SCHEMA_VERSION),
    }
    with atomic_file(path) as tmp, OpenEXR.File(header, channels) as exr:
        try:
            exr.write(str(tmp))
        except RuntimeError as exc:  # OpenEXR reports a failed write (a full disk: ENOSPC) in words only
            raise _write_error(path, str(exc)) from None
    return path


def _write_error(path: Path, message: str) -> OSError:
    """An OSError naming ``path`` for OpenEXR's failure ``message``: with the errno whose text it quotes
    (``No space left on device``), else with the message itself."""
    for code in sorted(errno.errorcode):
        if os.strerror(code) in message:
            return OSError(code, os.strerror(code), str(path))
    return OSError(f"could not write the OpenEXR file {str(path)!r}: {message}")


def read_exr(path: str | os.PathLike, *, role: str | None = None) -> np.ndarray:
    """Read an image written by :func:`write_exr` (or any RGB / single-channel float EXR).

    Parameters
    ----------
    path : path-like
        An OpenEXR file.
    role : str, optional
        If given, the header's role must match (an image written for another purpose is an error).

    Returns
    -------
    ndarray, float32, shape (H, W) or (H, W, 3)

    Raises
    ------
    FileFormatError
        If the file is missing, not an OpenEXR file, or holds other channels or another role.
    """
    path = Path(path)
    if (problem := file_problem(path)) is not None:
        raise FileFormatError(problem)
    with path.open("rb") as fh:
        magic = fh.read(4)
    if magic != b"\x76\x2f\x31\x01":
        raise FileFormatError(f"{str(path)!r} is not an OpenEXR file (magic bytes {magic!r})")
    try:
        with OpenEXR.File(str(path)) as exr:
            # Copy inside the block: closing the file empties the mappings it returned.
            header = dict(exr.header())
            channels = {name: np.array(ch.pixels) for name, ch in exr.channels().items()}
    except (RuntimeError, ValueError, OSError) as exc:
        raise FileFormatError(f"{str(path)!r} is not a readable OpenEXR file: {exc}") from None
    version = header.get(_SCHEMA_KEY)
    if version is not None and version != str(SCHEMA_VERSION):
        raise FileFormatError(f"{str(path)!r} has schema version {version!r}, this lfrefract reads {SCHEMA_VERSION}")
    if role is not None and header.get(_ROLE_KEY) != role:
        raise FileFormatError(f"{str(path)!r} holds a {header.get(_ROLE_KEY)!r} image, expected {role!r}")
    names = sorted(channels)
    if names == ["RGB"] or names == ["Y"] or names == ["Z"]:
        return np.asarray(channels[names[0]], dtype=np.float32)
    if set("RGB") <= set(names):
        return np.stack([np.asarray(channels[c], dtype=np.float32) for c in "RGB"], axis=-1)
    raise FileFormatError(f"{str(path)!r} has channels {names}; expected RGB or a single Y channel")
