"""Point clouds as binary little-endian PLY files."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from lfrefract.errors import FileFormatError, ParameterError
from lfrefract.formats.outputs import atomic_file
from lfrefract.validate import as_points

_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "<i2", "int16": "<i2",
    "ushort": "<u2", "uint16": "<u2", "int": "<i4", "int32": "<i4", "uint": "<u4", "uint32": "<u4",
    "float": "<f4", "float32": "<f4", "double": "<f8", "float64": "<f8",
}  # fmt: skip

__all__ = ["read_ply", "write_ply"]


def write_ply(path: str | os.PathLike, points_m: np.ndarray, colors: np.ndarray | None = None) -> Path:
    """Write a point cloud as a binary little-endian PLY file, atomically.

    The header declares ``element vertex N`` with ``float x, y, z`` and, when ``colors`` is given,
    ``uchar red, green, blue``. The file is written to a temporary name beside ``path`` and renamed
    into place.

    Parameters
    ----------
    path : path-like
        Destination ``.ply`` file (its directory is created if needed; an existing file is replaced).
    points_m : ndarray, shape (N, 3)
        Finite points, metres (stored as float32; N may be 0).
    colors : ndarray, shape (N, 3), optional
        Integer RGB values in 0..255 (stored as uint8). Floating-point colours are refused
        rather than guessed at: scale and convert them first.

    Returns
    -------
    Path
        The written path.

    Raises
    ------
    ParameterError
        If an array has the wrong shape or type, holds non-finite points, points beyond float32's
        range, or colours outside 0..255.
    """
    path = Path(path)
    pts = as_points("points_m", points_m, 3)
    if pts.size and np.max(np.abs(pts)) > np.finfo(np.float32).max:
        raise ParameterError(f"points_m holds values beyond float32's range, e.g. {float(np.max(np.abs(pts)))!r}")
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    rgb = None
    if colors is not None:
        rgb = np.asarray(colors)
        if rgb.shape != (len(pts), 3):
            raise ParameterError(f"colors must have shape ({len(pts)}, 3), got {rgb.shape}")
        if rgb.dtype.kind not in "iu":
            raise ParameterError(f"colors must hold integers in 0..255, got dtype {rgb.dtype}")
        if rgb.size and (rgb.min() < 0 or rgb.max() > 255):
            raise ParameterError(f"colors must lie in 0..255, got values in [{int(rgb.min())}, {int(rgb.max())}]")
        fields += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
    record = np.empty(len(pts), dtype=np.dtype(fields))
    for k, axis in enumerate("xyz"):
        record[axis] = pts[:, k]
    if rgb is not None:
        for k, channel in enumerate(("red", "green", "blue")):
            record[channel] = rgb[:, k]
    header = ["ply", "format binary_little_endian 1.0", "comment written by lfrefract", f"element vertex {len(pts)}"]
    header += [f"property {'float' if kind == '<f4' else 'uchar'} {name}" for name, kind in fields]
    header.append("end_header")
    with atomic_file(path) as tmp, tmp.open("wb") as fh:
        fh.write(("\n".join(header) + "\n").encode("ascii"))
        fh.write(record.tobytes())
    return path


def read_ply(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray | None]:
    """Read the vertices of a binary little-endian PLY file (as :func:`write_ply` writes them).

    Parameters
    ----------
    path : path-like
        A PLY file whose first element is ``vertex`` with scalar ``x, y, z`` properties (others,
        and later elements, are skipped).

    Returns
    -------
    points : ndarray, float64, shape (N, 3)
        The stored ``x, y, z`` values.
    colors : ndarray, uint8, shape (N, 3), or None
        ``red, green, blue`` when the vertices have all three as ``uchar``, else None.

    Raises
    ------
    FileFormatError
        If the file is missing, not a PLY file, not binary little-endian, lacks ``x, y, z`` vertices,
        or is shorter than its header says.
    """
    path = Path(path)
    if not path.is_file():
        raise FileFormatError(f"no such file: {str(path)!r}")
    data = path.read_bytes()
    if not data.startswith(b"ply\n") and not data.startswith(b"ply\r\n"):
        raise FileFormatError(f"{str(path)!r} is not a PLY file (it does not start with 'ply')")
    end = data.find(b"end_header")
    newline = data.find(b"\n", end) if end >= 0 else -1
    if newline < 0:
        raise FileFormatError(f"{str(path)!r} has no complete PLY header (no end_header line)")
    try:
        lines = data[:end].decode("ascii").splitlines()
    except UnicodeDecodeError:
        raise FileFormatError(f"{str(path)!r} has a PLY header that is not ASCII") from None
    words = [ln.split() for ln in lines[1:] if ln.strip() and not ln.startswith(("comment", "obj_info"))]
    if not words or words[0] != ["format", "binary_little_endian", "1.0"]:
        raise FileFormatError(f"{str(path)!r} is not a binary little-endian PLY file (got {lines[1:2]!r})")
    elements = [w for w in words[1:] if w[0] == "element"]
    if not elements or len(elements[0]) != 3 or elements[0][1] != "vertex" or not elements[0][2].isdigit():
        raise FileFormatError(f"{str(path)!r}: the first PLY element must be 'element vertex N'")
    count = int(elements[0][2])
    fields = []
    for w in words[words.index(elements[0]) + 1 :]:
        if w[0] == "element":
            break
        if w[0] != "property" or len(w) != 3 or w[1] not in _PLY_TYPES:
            raise FileFormatError(f"{str(path)!r}: unsupported vertex property {' '.join(w)!r}")
        fields.append((w[2], _PLY_TYPES[w[1]]))
    names = [name for name, _ in fields]
    if not {"x", "y", "z"} <= set(names) or len(set(names)) != len(names):
        raise FileFormatError(f"{str(path)!r}: the vertices must have x, y and z (once each), got {names}")
    dtype = np.dtype(fields)
    body = data[newline + 1 :]
    if len(body) < count * dtype.itemsize:
        raise FileFormatError(
            f"{str(path)!r} is truncated: {count} vertices need {count * dtype.itemsize} bytes, got {len(body)}"
        )
    record = np.frombuffer(body, dtype=dtype, count=count)
    points = np.stack([record[axis].astype(np.float64) for axis in "xyz"], axis=1).reshape(count, 3)
    colors = None
    if all(c in names and dtype[c] == np.uint8 for c in ("red", "green", "blue")):
        colors = np.stack([record[c] for c in ("red", "green", "blue")], axis=1).reshape(count, 3)
    return points, colors
