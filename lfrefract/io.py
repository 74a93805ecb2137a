"""File I/O: float EXR images (OpenEXR), JSON sidecars with a schema version, atomic outputs.

Nothing here leaves a half-written file or directory behind: files are written to a temporary
name beside their destination and renamed into place, and an output directory is assembled in
a staging directory that is renamed into place only when everything in it has been written.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import OpenEXR

from lfrefract._validate import ParameterError, as_points
from lfrefract.port import FlatPort

__all__ = [
    "SCHEMA_VERSION",
    "FileFormatError",
    "read_exr",
    "read_flat_port",
    "read_json",
    "read_ply",
    "staged_directory",
    "write_exr",
    "write_flat_port",
    "write_json",
    "write_ply",
]

#: Field order of a flat port in Refractive COLMAP and calibmar (``FLATPORT`` parameters).
FLAT_PORT_FIELDS = ("Nx", "Ny", "Nz", "int_dist", "int_thick", "na", "ng", "nw")

#: Version of the sidecar and directory layout written by this package.
SCHEMA_VERSION = 1

_ROLE_KEY = "lfrefract_role"
_SCHEMA_KEY = "lfrefract_schema_version"


class FileFormatError(ValueError):
    """A file is missing, of the wrong kind, or does not hold what it should."""


def _atomic_target(path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    return Path(tmp)


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
    tmp = _atomic_target(path)
    try:
        with OpenEXR.File(header, channels) as exr:
            exr.write(str(tmp))
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


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
    if not path.is_file():
        raise FileFormatError(f"no such file: {str(path)!r}")
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
    return _write_text_atomically(path, text + "\n")


def _write_text_atomically(path: Path, text: str) -> Path:
    """Write ``text`` to a temporary file beside ``path``, then rename it over ``path``."""
    tmp = _atomic_target(path)
    try:
        tmp.write_text(text)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def read_json(path: str | os.PathLike) -> dict:
    """Read a sidecar written by :func:`write_json`, checking its schema version."""
    path = Path(path)
    if not path.is_file():
        raise FileFormatError(f"no such file: {str(path)!r}")
    try:
        data = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise FileFormatError(f"{str(path)!r} is not valid JSON: {exc}") from None
    version = data.get("schema_version") if isinstance(data, dict) else None
    if version != SCHEMA_VERSION:
        raise FileFormatError(f"{str(path)!r} has schema_version {version!r}, this lfrefract reads {SCHEMA_VERSION}")
    return data


@contextlib.contextmanager
def staged_directory(out_dir: str | os.PathLike, *, overwrite: bool = False) -> Iterator[Path]:
    """Assemble an output directory atomically.

    Yields a fresh staging directory beside ``out_dir``. When the block finishes without an
    exception the staging directory replaces ``out_dir``; on any exception it is deleted and
    ``out_dir`` is left as it was.

    Raises
    ------
    FileExistsError
        If ``out_dir`` exists and is not empty, unless ``overwrite`` is given and it is an
        earlier output of this package (it holds a readable ``meta.json`` sidecar): a directory
        of anything else is never deleted.
    """
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise FileExistsError(f"output {str(out)!r} exists and is not a directory")
    if out.is_dir() and any(out.iterdir()):
        if not overwrite:
            raise FileExistsError(f"output directory {str(out)!r} is not empty (pass overwrite to replace it)")
        try:
            read_json(out / "meta.json")
        except FileFormatError:
            raise FileExistsError(
                f"output directory {str(out)!r} is not empty and holds no lfrefract meta.json: refusing to replace it"
            ) from None
    out.parent.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".partial", dir=out.parent))
    try:
        yield stage
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise
    if out.exists():
        shutil.rmtree(out)
    os.replace(stage, out)


def write_flat_port(path: str | os.PathLike, port: FlatPort) -> Path:
    """Write a port in the flat-port layout of Refractive COLMAP / calibmar, atomically.

    One comment line naming the fields, then ``Nx Ny Nz int_dist int_thick na ng nw``: the unit
    normal (camera frame, into the water), the distance of the air-side face from the camera
    centre and the glass thickness (metres), and the refractive indices of air, glass and water.
    """
    if not isinstance(port, FlatPort):
        raise ParameterError(f"port must be a FlatPort, got {port!r}")
    values = [*port.normal, port.distance_m, port.thickness_m, port.n_air, port.n_glass, port.n_water]
    text = "# " + " ".join(FLAT_PORT_FIELDS) + "\n" + " ".join(repr(float(v)) for v in values) + "\n"
    return _write_text_atomically(Path(path), text)


def read_flat_port(path: str | os.PathLike) -> FlatPort:
    """Read a port written by :func:`write_flat_port` (or any file with that one line)."""
    path = Path(path)
    if not path.is_file():
        raise FileFormatError(f"no such file: {str(path)!r}")
    lines = [ln for ln in path.read_text().splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    try:
        values = [float(v) for v in lines[0].split()] if len(lines) == 1 else []
    except ValueError:
        values = []
    if len(values) != len(FLAT_PORT_FIELDS):
        raise FileFormatError(f"{str(path)!r} is not a flat port ({' '.join(FLAT_PORT_FIELDS)} on one line)")
    nx, ny, nz, distance, thickness, n_air, n_glass, n_water = values
    if abs(np.hypot(np.hypot(nx, ny), nz) - 1.0) > 1e-6:
        raise FileFormatError(f"{str(path)!r}: the normal ({nx!r}, {ny!r}, {nz!r}) is not a unit vector")
    return FlatPort.from_normal(
        [nx, ny, nz], distance_m=distance, thickness_m=thickness, n_air=n_air, n_glass=n_glass, n_water=n_water
    )


_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "<i2", "int16": "<i2",
    "ushort": "<u2", "uint16": "<u2", "int": "<i4", "int32": "<i4", "uint": "<u4", "uint32": "<u4",
    "float": "<f4", "float32": "<f4", "double": "<f8", "float64": "<f8",
}  # fmt: skip


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
    header = ["ply", "format binary_little_endian 1.0", "comment written by lfrefract.io", f"element vertex {len(pts)}"]
    header += [f"property {'float' if kind == '<f4' else 'uchar'} {name}" for name, kind in fields]
    header.append("end_header")
    tmp = _atomic_target(path)
    try:
        with tmp.open("wb") as fh:
            fh.write(("\n".join(header) + "\n").encode("ascii"))
            fh.write(record.tobytes())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
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
