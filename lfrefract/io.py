"""File I/O: float EXR images (OpenEXR), JSON sidecars with a schema version, atomic outputs, point
clouds (PLY), flat ports (Refractive COLMAP layout) and sub-aperture view stacks (HCI 4D light field
benchmark layout).

Nothing here leaves a half-written file or directory behind: files are written to a temporary
name beside their destination and renamed into place, and an output directory is assembled in
a staging directory that is renamed into place only when everything in it has been written.
"""

from __future__ import annotations

import json
import math
import os
import zipfile
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import OpenEXR

from lfrefract import __version__
from lfrefract._validate import ParameterError, as_points, one_of, positive_float, positive_int
from lfrefract.camera import LightFieldCamera
from lfrefract.outputs import atomic_file, staged_directory
from lfrefract.pinhole import PinholeCamera
from lfrefract.port import FlatPort
from lfrefract.views import ViewStack

__all__ = [
    "MAX_FLAT_PORT_BYTES",
    "PNG_WHITE_PERCENTILE",
    "SCHEMA_VERSION",
    "VIEW_STACK_FORMATS",
    "FileFormatError",
    "read_exr",
    "read_flat_port",
    "read_json",
    "read_ply",
    "read_view_stack",
    "view_file_names",
    "write_exr",
    "write_flat_port",
    "write_json",
    "write_ply",
    "write_text_atomically",
    "write_view_stack",
]

#: Largest flat-port file read, bytes: the format is one line of eight numbers and a comment.
MAX_FLAT_PORT_BYTES = 65536

#: Field order of a flat port in Refractive COLMAP and calibmar (``FLATPORT`` parameters).
FLAT_PORT_FIELDS = ("Nx", "Ny", "Nz", "int_dist", "int_thick", "na", "ng", "nw")

#: Version of the sidecar and directory layout written by this package.
SCHEMA_VERSION = 1

_ROLE_KEY = "lfrefract_role"
_SCHEMA_KEY = "lfrefract_schema_version"


class FileFormatError(ValueError):
    """A file is missing, of the wrong kind, or does not hold what it should."""


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
    with atomic_file(path) as tmp, OpenEXR.File(header, channels) as exr:
        exr.write(str(tmp))
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
    if not path.is_file():
        raise FileFormatError(f"no such file: {str(path)!r}")
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
    return write_text_atomically(Path(path), text)


def read_flat_port(path: str | os.PathLike) -> FlatPort:
    """Read a port written by :func:`write_flat_port` (or any file with that one line).

    Raises
    ------
    FileFormatError
        If the file is missing, larger than a port file can be (:data:`MAX_FLAT_PORT_BYTES`), not
        UTF-8 text, not one line of the eight fields, or its values are not a valid port (the
        normal not a unit vector, a value outside :class:`FlatPort`'s ranges).
    """
    path = Path(path)
    if not path.is_file():
        raise FileFormatError(f"no such file: {str(path)!r}")
    if path.stat().st_size > MAX_FLAT_PORT_BYTES:
        raise FileFormatError(
            f"{str(path)!r} is {path.stat().st_size} bytes: not a flat port (at most {MAX_FLAT_PORT_BYTES} bytes)"
        )
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as exc:
        raise FileFormatError(f"{str(path)!r} is not UTF-8 text (byte {exc.start}): not a flat port") from None
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    try:
        values = [float(v) for v in lines[0].split()] if len(lines) == 1 else []
    except ValueError:
        values = []
    if len(values) != len(FLAT_PORT_FIELDS):
        raise FileFormatError(f"{str(path)!r} is not a flat port ({' '.join(FLAT_PORT_FIELDS)} on one line)")
    nx, ny, nz, distance, thickness, n_air, n_glass, n_water = values
    if abs(np.hypot(np.hypot(nx, ny), nz) - 1.0) > 1e-6:
        raise FileFormatError(f"{str(path)!r}: the normal ({nx!r}, {ny!r}, {nz!r}) is not a unit vector")
    try:
        return FlatPort.from_normal(
            [nx, ny, nz], distance_m=distance, thickness_m=thickness, n_air=n_air, n_glass=n_glass, n_water=n_water
        )
    except ParameterError as exc:
        raise FileFormatError(f"{str(path)!r} is not a valid port: {exc}") from None


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


# =============================================================================== view stacks
#: Image formats of :func:`write_view_stack`.
VIEW_STACK_FORMATS = ("png", "exr")

#: Percentile of the central view's finite values that the PNG encoding maps to white, by default.
PNG_WHITE_PERCENTILE = 99.5

_STACK_SIDECAR = "views.json"
_STACK_KIND = "lfrefract.view_stack"
_STACK_ARRAYS = "stack.npz"
_STACK_MASK = "valid_mask.png"
_STACK_PARAMETERS = "parameters.cfg"


def view_file_names(grid: int, image_format: str) -> list[str]:
    """File names of a ``grid x grid`` view stack in the HCI layout, in row-major order.

    ``input_Cam000.png`` is view ``[0, 0]`` (top left), ``input_Cam{r * grid + c}`` view
    ``[r, c]``; numbers have three digits (the benchmark's 9 x 9 grids), more only for grids
    beyond 31 x 31, so that sorting the names keeps the order.
    """
    positive_int("grid", grid)
    one_of("image_format", image_format, VIEW_STACK_FORMATS)
    digits = max(3, len(str(grid * grid - 1)))
    return [f"input_Cam{i:0{digits}d}.{image_format}" for i in range(grid * grid)]


def _srgb_8bit(view: np.ndarray, white_level: float) -> np.ndarray:
    """``round(255 * srgb(clip(view / white_level, 0, 1)))`` as uint8, NaN written as 0."""
    x = np.clip(np.nan_to_num(view.astype(np.float64) / white_level, nan=0.0), 0.0, 1.0)
    encoded = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)
    return np.round(encoded * 255.0).astype(np.uint8)


def _write_png(path: Path, image: np.ndarray) -> None:
    """An 8-bit grey (H, W) or RGB (H, W, 3) image as PNG (OpenCV wants BGR)."""
    ok, data = cv2.imencode(".png", image if image.ndim == 2 else np.ascontiguousarray(image[..., ::-1]))
    if not ok:
        raise OSError(f"OpenCV could not encode {str(path)!r} as PNG")
    path.write_bytes(data.tobytes())


def _hci_parameters(stack: ViewStack) -> str:
    """``parameters.cfg`` text: the HCI benchmark's fields that the stack states truthfully."""
    out = stack.output
    max_res = max(out.width_px, out.height_px)
    lines = [
        "# Sub-aperture view stack written by lfrefract, in the layout of the HCI 4D light field benchmark",
        "# (Honauer et al., ACCV 2016). Views input_CamNNN, NNN = row * num_cams_x + column, row 0 at the top,",
        "# column 0 at the left. Every view has the same K and orientation; the disparity between neighbouring",
        "# views is f_px * baseline / depth, zero at infinity (the views are not shifted to a focus plane).",
        "# Fields of the benchmark left out: fstop (a view's aperture is one pixel's square footprint on the main",
        "# lens), the centre camera's pose (the camera frame is the reference) and the [meta] disparity ranges",
        "# and depth map scale (no ground truth here). *_px keys other than the resolution are lfrefract's.",
        "",
        "[intrinsics]",
    ]
    if stack.camera is not None:
        image_distance_m = stack.camera.lens_to_mla_m
        lines += [
            f"focal_length_mm = {image_distance_m * 1e3!r}",
            f"sensor_size_mm = {max_res * image_distance_m / out.focal_px * 1e3!r}",
        ]
    lines += [
        f"image_resolution_x_px = {out.width_px}",
        f"image_resolution_y_px = {out.height_px}",
        f"focal_length_px = {out.focal_px!r}",
        f"principal_point_x_px = {out.cx_px!r}",
        f"principal_point_y_px = {out.cy_px!r}",
        "",
        "[extrinsics]",
        f"num_cams_x = {stack.grid}",
        f"num_cams_y = {stack.grid}",
        f"baseline_mm = {stack.baseline_m * 1e3!r}",
        "focus_distance_m = inf",
        f"spacing_px = {stack.spacing_px!r}",
        "",
        "[meta]",
        f"generator = lfrefract {__version__}",
        f"schema_version = {SCHEMA_VERSION}",
        "",
    ]
    return "\n".join(lines)


def write_view_stack(
    out_dir: str | os.PathLike,
    stack: ViewStack,
    *,
    overwrite: bool = False,
    image_format: str = "png",
    white_level: float | None = None,
    metadata: dict | None = None,
    inputs: Iterable[str | os.PathLike] = (),
) -> Path:
    """Write a sub-aperture view stack in the HCI 4D light field benchmark layout, atomically.

    The directory holds, for a ``grid x grid`` stack (``docs/synthesis.md``, "Sub-aperture view
    stacks"):

    * ``input_Cam000.<ext>`` ... one file per view in row-major order (:func:`view_file_names`):
      ``Cam000`` is view ``[0, 0]``, the top-left centre of projection (camera frame -x, -y),
      the central view is ``Cam{h * grid + h}``;
    * ``parameters.cfg``: the benchmark's INI fields that can be stated (resolution, number of
      cameras, baseline, focal length in mm and pixels, sensor size, focus distance ``inf``);
    * ``valid_mask.png``: 255 where every view has a finite value in every channel, else 0;
    * ``stack.npz``: ``views`` (float32, NaN kept), ``offsets_px``, ``centres_m``, ``K``, the
      camera as JSON, ``schema_version`` (:func:`read_view_stack`);
    * ``views.json``: the sidecar (layout, ordering, encoding, disparity relation, geometry).

    PNG views are 8-bit sRGB: ``round(255 * srgb(clip(value / white_level, 0, 1)))`` with the
    IEC 61966-2-1 transfer curve, one ``white_level`` for all views (so they stay photometrically
    consistent), NaN written as 0. EXR views are float32 linear, NaN kept (:func:`write_exr`).

    Parameters
    ----------
    out_dir : path-like
        The directory to create (assembled beside it and renamed into place).
    stack : ViewStack
        Grey views or views with 1 or 3 channels.
    overwrite : bool
        Replace an earlier view stack that holds only its own files
        (:func:`lfrefract.outputs.staged_directory`).
    image_format : {"png", "exr"}
    white_level : float, optional
        Linear value written as white in PNG views, > 0. Default: the
        :data:`PNG_WHITE_PERCENTILE` th percentile of the central view's finite values, or 1.0
        if that is not positive (a black view). Recorded in ``views.json``.
    metadata : dict, optional
        Plain data stored under ``"metadata"`` in ``views.json`` (e.g. the source raw image).
    inputs : iterable of path-like
        Files the caller read the stack from: ``out_dir`` may not hold one.

    Returns
    -------
    Path
        ``out_dir``.

    Raises
    ------
    ParameterError
        If ``stack`` is not a ViewStack, has another number of channels, or an option is invalid.
    FileExistsError
        See :func:`lfrefract.outputs.staged_directory`.
    """
    if not isinstance(stack, ViewStack):
        raise ParameterError(f"stack must be a ViewStack, got {type(stack).__name__}")
    one_of("image_format", image_format, VIEW_STACK_FORMATS)
    views = stack.views
    if views.ndim == 5:
        if views.shape[4] not in (1, 3):
            raise ParameterError(
                f"stack.views must be grey or have 1 or 3 channels for image files, got {views.shape[4]} channels"
            )
        if views.shape[4] == 1:
            views = views[..., 0]
    if metadata is not None and not isinstance(metadata, dict):
        raise ParameterError(f"metadata must be a dict or None, got {type(metadata).__name__}")
    finite = stack.central_view[np.isfinite(stack.central_view)]
    if white_level is None:
        white = float(np.percentile(finite, PNG_WHITE_PERCENTILE)) if finite.size else 0.0
        rule = f"{PNG_WHITE_PERCENTILE}th percentile of the central view's finite values"
        if not white > 0.0:
            white, rule = 1.0, "1.0 (the central view has no positive values)"
    else:
        white, rule = positive_float("white_level", white_level), "given"
    valid = np.all(np.isfinite(views), axis=(0, 1) if views.ndim == 4 else (0, 1, 4))
    names = view_file_names(stack.grid, image_format)
    grid, h = stack.grid, stack.centre_index
    if image_format == "png":
        encoding = {
            "bits": 8,
            "transfer": "sRGB (IEC 61966-2-1)",
            "formula": "round(255 * srgb(clip(value / white_level, 0, 1))); NaN written as 0 (see valid_mask.png)",
            "white_level": white,
            "white_level_rule": rule,
        }
    else:
        encoding = {"type": "float32 OpenEXR, linear radiance as in the raw image", "nan": "kept (no value)"}
    out = Path(out_dir)
    with staged_directory(out, kind=_STACK_KIND, overwrite=overwrite, inputs=inputs) as stage:
        for index, name in enumerate(names):
            view = views[index // grid, index % grid]
            if image_format == "png":
                _write_png(stage / name, _srgb_8bit(view, white))
            else:
                write_exr(stage / name, view, role="subaperture_view")
        _write_png(stage / _STACK_MASK, valid.astype(np.uint8) * 255)
        (stage / _STACK_PARAMETERS).write_text(_hci_parameters(stack))
        with (stage / _STACK_ARRAYS).open("wb") as fh:
            np.savez(
                fh,
                views=stack.views,
                offsets_px=stack.offsets_px,
                centres_m=stack.centres_m,
                K=stack.K,
                camera=np.asarray(json.dumps(stack.camera.to_dict()) if stack.camera is not None else ""),
                schema_version=np.asarray(SCHEMA_VERSION),
            )
        write_json(
            stage / _STACK_SIDECAR,
            {
                "kind": _STACK_KIND,
                "layout": "HCI 4D light field benchmark (Honauer et al., ACCV 2016)",
                "ordering": (
                    "input_CamNNN, NNN = row * grid + column; row 0 at the top (camera frame -y), column 0 at the "
                    "left (-x); stack.npz views[row, column]"
                ),
                "grid": grid,
                "central_view": names[h * grid + h],
                "files": {
                    "views": names,
                    "mask": _STACK_MASK,
                    "parameters": _STACK_PARAMETERS,
                    "arrays": _STACK_ARRAYS,
                },
                "image_format": image_format,
                "encoding": encoding,
                "valid_fraction": float(valid.mean()),
                "K": stack.K,
                "width_px": stack.output.width_px,
                "height_px": stack.output.height_px,
                "spacing_px": stack.spacing_px,
                "baseline_m": stack.baseline_m,
                "disparity": {
                    "rule": (
                        "between neighbouring views d = focal_px * baseline_m / depth_m pixels, depth the camera-frame "
                        "z; views[r, c + 1] at (u - d, v) and views[r + 1, c] at (u, v - d) show what views[r, c] "
                        "shows at (u, v); zero at infinity"
                    ),
                    "focal_px_times_baseline_m": stack.output.focal_px * stack.baseline_m,
                },
                "offsets_px": stack.offsets_px,
                "centres_m": stack.centres_m,
                "camera": stack.camera.to_dict() if stack.camera is not None else None,
                "metadata": metadata,
            },
        )
    return out


def read_view_stack(path: str | os.PathLike) -> ViewStack:
    """Read the :class:`ViewStack` of a directory written by :func:`write_view_stack` (its ``stack.npz``).

    Raises
    ------
    FileFormatError
        If ``stack.npz`` is missing, unreadable, of another schema version, lacks an array, or
        does not hold a valid view stack.
    """
    path = Path(path)
    file = path / _STACK_ARRAYS if path.is_dir() else path
    if not file.is_file():
        raise FileFormatError(f"no such file: {str(file)!r}")
    try:
        # Our own handle: np.load leaks the one it opens when the zip directory is unreadable.
        with file.open("rb") as fh, np.load(fh, allow_pickle=False) as data:
            arrays = {key: data[key] for key in data.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise FileFormatError(f"{str(file)!r} is not a readable .npz file: {exc}") from None
    missing = sorted({"views", "offsets_px", "centres_m", "K", "camera", "schema_version"} - set(arrays))
    if missing:
        raise FileFormatError(f"{str(file)!r} is not a view stack: it lacks {missing}")
    version = arrays["schema_version"]
    if version.shape != () or version.dtype.kind not in "iu" or int(version) != SCHEMA_VERSION:
        raise FileFormatError(
            f"{str(file)!r} has schema version {version.tolist()!r}, this lfrefract reads {SCHEMA_VERSION}"
        )
    views = arrays["views"]
    try:
        if views.ndim not in (4, 5):
            raise ParameterError(f"views must have 4 or 5 dimensions, got shape {views.shape}")
        camera_text = str(arrays["camera"])
        camera = LightFieldCamera.from_dict(json.loads(camera_text)) if camera_text else None
        output = PinholeCamera.from_K(arrays["K"], int(views.shape[3]), int(views.shape[2]))
        return ViewStack(
            views=views,
            offsets_px=arrays["offsets_px"],
            centres_m=arrays["centres_m"],
            output=output,
            camera=camera,
        )
    except (ValueError, TypeError) as exc:  # ParameterError, JSONDecodeError, a K of strings
        raise FileFormatError(f"{str(file)!r} does not hold a valid view stack: {exc}") from None
