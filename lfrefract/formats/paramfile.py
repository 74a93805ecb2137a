"""Camera, port and lens files: the parameters of your own camera, port and main lens, written and read in one place.

A camera file or a port file is one of (the format is chosen by the file's suffix):

* ``.toml``: a ``[camera]`` or ``[port]`` table and an optional ``schema_version = 1``, nothing
  else (``docs/cli.md``, "Camera and port files", lists every key with its unit and range). A port's
  orientation is given either by its tilt angles (``tilt_x_deg`` / ``tilt_y_deg``, or the ``_rad``
  pair) or by its ``normal`` (a 3-vector, camera frame, pointing into the water), exactly one of
  the two;
* ``.json``: lfrefract JSON (:func:`lfrefract.formats.jsonio.read_json`) holding a ``camera`` or
  ``port`` table, e.g. a render's ``meta.json``, ``lfrefract describe PRESET --json`` output,
  ``lfrefract calibrate mla`` / ``calibrate camera`` / ``calibrate port`` output; its ``kind`` must
  agree with its content (:func:`read_parameter_json`: a ray correction only in a camera
  calibration, and so on), other keys are not read. A file of any other suffix (but ``.txt`` for
  ports) is read as JSON too;
* ``.txt`` (ports only): the one-line flat-port layout of Refractive COLMAP / calibmar
  (:mod:`lfrefract.formats.flatport`).

A lens file (:func:`read_lens_file`) is a ``.toml`` file with a ``[lens]`` table (the table of
:meth:`lfrefract.optics.lens.LensPrescription.to_dict`: ``name``, ``source``, ``[[lens.surfaces]]``)
and an optional ``schema_version = 1``, else lfrefract JSON with a ``lens`` table (kind
:data:`LENS_FILE_KIND`, or none); ``scenes/lenses/`` holds a family of published designs as lens files.

The writers (:func:`write_camera_file`, :func:`write_port_file`, :func:`write_lens_file`) write
exactly what :meth:`LightFieldCamera.to_dict` / :meth:`FlatPort.to_dict` /
``LensPrescription.to_dict`` hold (ports in TOML by their tilt angles in radians, so the values read
back are the ones written, bit for bit), atomically; the readers give back an equal camera, port or
lens.

Every problem of a file (missing, not a regular file, larger than :data:`MAX_PARAMETER_FILE_BYTES`,
not UTF-8, not valid TOML / JSON, an unknown or missing key, a value of the wrong type or out of
range) is a :class:`lfrefract.errors.FileFormatError` naming the file and the key.
"""

from __future__ import annotations

import math
import os
import tomllib
from pathlib import Path

import numpy as np
import tomli_w

from lfrefract.errors import FileFormatError, ParameterError
from lfrefract.formats.flatport import read_flat_port, write_flat_port
from lfrefract.formats.jsonio import (
    CAMERA_CALIBRATION_KIND,
    MLA_CALIBRATION_KIND,
    PORT_CALIBRATION_KIND,
    SCHEMA_VERSION,
    read_json,
    write_json,
    write_text_atomically,
)
from lfrefract.optics.camera import LightFieldCamera
from lfrefract.optics.lens import LensPrescription, Surface
from lfrefract.optics.port import FlatPort
from lfrefract.validate import finite_vector, regular_file, reject_unknown_keys, require_keys, shown

__all__ = [
    "CAMERA_FILE_KIND",
    "CAMERA_SUFFIXES",
    "LENS_FILE_KIND",
    "LENS_SUFFIXES",
    "MAX_PARAMETER_FILE_BYTES",
    "MLA_CALIBRATION_KIND",
    "PORT_FILE_KIND",
    "PORT_SUFFIXES",
    "camera_from_json",
    "check_kind",
    "read_camera_file",
    "read_lens_file",
    "read_parameter_json",
    "read_port_file",
    "write_camera_file",
    "write_lens_file",
    "write_port_file",
]

#: Largest camera or port file read, bytes. A camera file is under 1 KiB and a render's ``meta.json`` a few
#: KiB, but ``lfrefract calibrate mla`` output keeps every lens's measured centre: 31 MiB for the Illum's
#: 233 603 lenses (measured on the pipeline experiment's Illum white), so the limit is twice that.
MAX_PARAMETER_FILE_BYTES = 64 * 2**20

#: Suffixes :func:`write_camera_file` writes.
CAMERA_SUFFIXES = (".toml", ".json")
#: Suffixes :func:`write_port_file` writes.
PORT_SUFFIXES = (".toml", ".json", ".txt")
#: Suffixes :func:`write_lens_file` writes.
LENS_SUFFIXES = (".toml", ".json")

#: ``kind`` of the JSON camera and port files written here.
CAMERA_FILE_KIND = "lfrefract.camera"
PORT_FILE_KIND = "lfrefract.port"
#: ``kind`` of the JSON lens files written here.
LENS_FILE_KIND = "lfrefract.lens"


_PORT_SCALARS = ("distance_m", "thickness_m", "n_air", "n_glass", "n_water")
_DEG_ANGLES = ("tilt_x_deg", "tilt_y_deg")
_RAD_ANGLES = ("tilt_x_rad", "tilt_y_rad")


# =============================================================================== cameras
def read_camera_file(path: str | os.PathLike) -> LightFieldCamera:
    """The camera of a camera file (``.toml``, else lfrefract JSON with a ``camera`` table).

    Raises
    ------
    FileFormatError
        If the file is missing, too large, not UTF-8 TOML / JSON, has no ``camera`` table, or a
        key of it is unknown, missing, of the wrong type or out of range (named with the file);
        if a JSON file's ``kind`` disagrees with its content (:func:`read_parameter_json`) or it
        holds a ``lens`` table (a real main lens, which the camera model does not read).
    """
    path = Path(path)
    table = _toml_table(path, "camera") if _is_toml(path) else _json_table(path, "camera")
    return _parsed(path, "camera", table, LightFieldCamera.from_dict)


def camera_from_json(path: str | os.PathLike, data: dict) -> LightFieldCamera:
    """The camera of a JSON camera file's content ``data``, read from ``path`` by
    :func:`read_parameter_json` (so that a caller reading other tables of it reads the file once);
    checked as :func:`read_camera_file` checks it, every message naming ``path`` and the key.

    Raises
    ------
    FileFormatError
        As :func:`read_camera_file`.
    """
    path = Path(path)
    return _parsed(path, "camera", _json_table(path, "camera", data), LightFieldCamera.from_dict)


def read_parameter_json(path: str | os.PathLike) -> dict:
    """The content of an lfrefract JSON parameter file (a camera, port or MLA file), its ``kind``
    checked against its content: what the file is, its content decides.

    The tables that carry a model of the camera or of its rays belong to one kind of file each:
    ``correction`` and ``correction_covariance`` to a camera calibration (``lfrefract calibrate
    camera``), ``mla`` to an MLA calibration, ``ray_model`` to a port calibration. A file that holds
    one of them under another ``kind`` (or none) was edited or mixed up; it would be read as if the
    table were not there, so it is refused. A camera or MLA calibration must hold its own table, and the files
    :func:`write_camera_file` / :func:`write_port_file` write (kinds :data:`CAMERA_FILE_KIND`,
    :data:`PORT_FILE_KIND`) hold their one table only. Other files (a render's ``meta.json``,
    ``lfrefract describe --json`` output) may hold any other key.

    Raises
    ------
    FileFormatError
        If the file is missing, too large, not lfrefract JSON, or its kind and content disagree
        (naming the file, the key and its value).
    """
    path = Path(path)
    _check_size(path)
    data = read_json(path)
    check_kind(path, data)
    return data


def _model_tables() -> dict[str, tuple[str, str]]:
    """Top-level tables of a camera or ray model: table -> (what holds it, the one kind that may)."""
    calibration = ("a camera calibration (lfrefract calibrate camera output)", CAMERA_CALIBRATION_KIND)
    return {
        "correction": calibration,
        "correction_covariance": calibration,
        "correction_spread": calibration,
        "mla": ("an MLA calibration (lfrefract calibrate mla output)", MLA_CALIBRATION_KIND),
        "ray_model": ("a port calibration (lfrefract calibrate port output)", PORT_CALIBRATION_KIND),
    }


def check_kind(path: str | os.PathLike, data: dict) -> None:
    """Refuse the content ``data`` of an lfrefract JSON file ``path`` (a parameter file or a
    capture's sidecar) if its ``kind`` and its content disagree (see :func:`read_parameter_json`).

    Raises
    ------
    FileFormatError
        Naming the file, the key and its value.
    """
    path = Path(path)
    kind = data.get("kind")
    if kind is not None and not isinstance(kind, str):
        raise FileFormatError(f"{str(path)!r}: key 'kind' must be a string, got {shown(kind)}")
    tables = _model_tables()
    for table, (holder, holder_kind) in tables.items():
        if table in data and kind != holder_kind:
            raise FileFormatError(
                f"{str(path)!r}: key 'kind' is {shown(kind)}, but the file holds a {table!r} table, which only "
                f"{holder} holds (kind {holder_kind!r}): the file was edited or mixed up. Give it back its kind "
                "if it is such a file, or remove the table; it is not read as if the table were not there"
            )
    required = {tables["correction"][1]: "correction", MLA_CALIBRATION_KIND: "mla"}
    if kind in required and required[kind] not in data:
        holder = tables[required[kind]][0].split(" (")[0]
        raise FileFormatError(
            f"{str(path)!r} is {holder} (key 'kind' is {kind!r}) but has no {required[kind]!r} table: the file "
            "is damaged or its kind was edited; write it again with the command that makes it"
        )
    own = {CAMERA_FILE_KIND: "camera", PORT_FILE_KIND: "port", LENS_FILE_KIND: "lens"}
    if kind in own:
        extra = sorted(set(data) - {"schema_version", "kind", own[kind]})
        if extra:
            raise FileFormatError(
                f"{str(path)!r}: key 'kind' is {kind!r}, but the file holds {extra} as well as its {own[kind]!r} "
                f"table: a file of this kind holds that table only. Remove the other keys, or give the file the "
                "kind of what wrote them"
            )


def write_camera_file(path: str | os.PathLike, camera: LightFieldCamera) -> Path:
    """Write ``camera`` as a camera file, atomically: TOML or JSON by the suffix of ``path``.

    Returns
    -------
    Path

    Raises
    ------
    ParameterError
        If ``camera`` is not a LightFieldCamera, or the suffix is not one of :data:`CAMERA_SUFFIXES`.
    """
    if not isinstance(camera, LightFieldCamera):
        raise ParameterError(f"camera must be a LightFieldCamera, got {shown(camera)}")
    path = Path(path)
    suffix = _suffix(path, CAMERA_SUFFIXES, "camera file")
    if suffix == ".json":
        return write_json(path, {"kind": CAMERA_FILE_KIND, "camera": camera.to_dict()})
    header = [
        f"# lfrefract camera file: {camera.name!r}, a plenoptic 1.0 camera (thin main lens, microlens array, sensor).",
        "# Lengths in metres, angles in radians; keys, units and ranges: docs/cli.md, 'Camera and port files'.",
        f"# Derived: micro-image pitch {camera.micro_image_pitch_px:.6g} px, main-lens aperture radius "
        f"{camera.aperture_radius_m * 1e3:.6g} mm.",
    ]
    return _write_toml(path, header, {"schema_version": SCHEMA_VERSION, "camera": camera.to_dict()})


# =============================================================================== ports
def read_port_file(path: str | os.PathLike) -> FlatPort:
    """The port of a port file: ``.toml``, ``.txt`` (flat-port layout), else lfrefract JSON with a
    ``port`` table.

    A TOML ``[port]`` table holds ``distance_m`` (required), ``thickness_m``, ``n_air``,
    ``n_glass``, ``n_water``, and the orientation: either tilt angles (``tilt_x_deg`` /
    ``tilt_y_deg`` or ``tilt_x_rad`` / ``tilt_y_rad``; one absent is 0) or ``normal``, not both.

    Raises
    ------
    FileFormatError
        If the file is missing, too large, not of its format, has no ``port`` table, gives both
        or neither of angles and normal, or a key is unknown, of the wrong type or out of range.
    """
    path = Path(path)
    if path.suffix.lower() == ".txt":
        _check_size(path)
        return read_flat_port(path)
    if not _is_toml(path):
        return _parsed(path, "port", _json_table(path, "port"), FlatPort.from_dict)
    table = dict(_toml_table(path, "port"))
    angles = sorted(k for k in table if k in _DEG_ANGLES + _RAD_ANGLES)
    if angles and "normal" in table:
        raise FileFormatError(
            f"{str(path)!r}: key 'port' gives its orientation twice, by {angles} and by 'normal': keep one of the two"
        )
    if not angles and "normal" not in table:
        raise FileFormatError(
            f"{str(path)!r}: key 'port' gives no orientation: add 'tilt_x_deg' and 'tilt_y_deg' (degrees) or "
            "'normal' (a 3-vector, camera frame, into the water)"
        )
    if any(k in _DEG_ANGLES for k in angles) and any(k in _RAD_ANGLES for k in angles):
        raise FileFormatError(
            f"{str(path)!r}: key 'port' mixes degrees and radians ({angles}): give both tilts in one unit"
        )
    if angles:
        return _parsed(path, "port", table, _port_from_angles)
    return _parsed(path, "port", table, _port_from_normal)


def _port_from_angles(table: dict) -> FlatPort:
    reject_unknown_keys("port", table, {*_PORT_SCALARS, *_DEG_ANGLES, *_RAD_ANGLES})
    return FlatPort.from_dict(table)


def _port_from_normal(table: dict) -> FlatPort:
    reject_unknown_keys("port", table, {*_PORT_SCALARS, "normal"})
    require_keys("port", table, {"distance_m"})
    normal = np.asarray(finite_vector("port.normal", table.pop("normal"), 3))
    return FlatPort.from_normal(normal, **table)


def write_port_file(path: str | os.PathLike, port: FlatPort) -> Path:
    """Write ``port`` as a port file, atomically: TOML, JSON or the flat-port text by the suffix of ``path``.

    TOML gives the orientation by the tilt angles in radians (read back bit for bit); a comment
    gives them in degrees, with the normal and the total tilt.

    Raises
    ------
    ParameterError
        If ``port`` is not a FlatPort, or the suffix is not one of :data:`PORT_SUFFIXES`.
    """
    if not isinstance(port, FlatPort):
        raise ParameterError(f"port must be a FlatPort, got {shown(port)}")
    path = Path(path)
    suffix = _suffix(path, PORT_SUFFIXES, "port file")
    if suffix == ".txt":
        return write_flat_port(path, port)
    if suffix == ".json":
        return write_json(path, {"kind": PORT_FILE_KIND, "port": port.to_dict()})
    data = {k: v for k, v in port.to_dict().items() if k in (*_PORT_SCALARS, *_RAD_ANGLES)}
    normal = ", ".join(f"{v:.9g}" for v in port.normal)
    header = [
        "# lfrefract port file: a flat port (glass slab between air and water), camera frame (OpenCV axes).",
        "# Lengths in metres, angles in radians; keys, units and ranges: docs/cli.md, 'Camera and port files'.",
        f"# Tilt: x {math.degrees(port.tilt_x_rad):.9g} deg, y {math.degrees(port.tilt_y_rad):.9g} deg "
        f"(total {math.degrees(port.total_tilt_rad):.9g} deg); normal [{normal}].",
    ]
    return _write_toml(path, header, {"schema_version": SCHEMA_VERSION, "port": data})


# =============================================================================== lenses
def read_lens_file(
    path: str | os.PathLike, *, focal_length_m: float | None = None, f_number: float | None = None
) -> LensPrescription:
    """The main lens of a lens file (``.toml``, else lfrefract JSON with a ``lens`` table), optionally
    scaled to a camera as :func:`lfrefract.optics.lens.lens_preset` scales a preset.

    The ``lens`` table holds ``name``, ``source`` (optional: book and page, patent) and ``surfaces``,
    a list of surface tables (``radius_m``, ``thickness_m``, ``medium``, ``semi_aperture_m``,
    ``stop``; :meth:`lfrefract.optics.lens.Surface.from_dict`), metres; in TOML, ``[[lens.surfaces]]``.

    Parameters
    ----------
    path : path-like
        The lens file.
    focal_length_m : float, optional
        Scale the design to this d-line effective focal length (a camera's ``focal_length_m``).
    f_number : float, optional
        Resize the stop to this f-number; the other clear apertures stay, so opening a design beyond
        its own f-number makes them cut the axial beam
        (:meth:`lfrefract.optics.lens.LensPrescription.with_f_number`).

    Raises
    ------
    FileFormatError
        If the file is missing, too large, not UTF-8 TOML or lfrefract JSON, has no ``lens`` table, or
        does not hold a valid prescription; the message names the file and the key
        (``lens.surfaces[2]``: the third surface table).
    ParameterError
        If the lens cannot be scaled or stopped as asked (a negative focal length, a stop larger
        than its surface); the message names the file.
    """
    path = Path(path)
    table = _toml_table(path, "lens") if _is_toml(path) else _json_table(path, "lens")
    unknown = sorted(set(table) - {"name", "source", "surfaces"})
    if unknown:
        raise FileFormatError(f"{str(path)!r}: key 'lens' holds unknown keys {unknown} (name, source, surfaces)")
    if "name" not in table:
        raise FileFormatError(f"{str(path)!r}: key 'lens.name' is missing")
    name, source, rows = table["name"], table.get("source", ""), table.get("surfaces")
    for key, value in (("name", name), ("source", source)):
        if not isinstance(value, str):
            raise FileFormatError(f"{str(path)!r}: key 'lens.{key}' must be a string, got {shown(value)}")
    if not isinstance(rows, list) or not rows:
        raise FileFormatError(
            f"{str(path)!r}: key 'lens.surfaces' must be a non-empty list of surface tables, got {shown(rows)}"
        )
    surfaces = []
    for i, row in enumerate(rows):
        try:
            surfaces.append(Surface.from_dict(row))
        except ParameterError as exc:
            raise FileFormatError(f"{str(path)!r}: key 'lens.surfaces[{i}]': {exc}") from None
    try:
        lens = LensPrescription(name=name, source=source, surfaces=tuple(surfaces))
    except ParameterError as exc:
        key = "lens.name" if not name.strip() else "lens.surfaces"
        raise FileFormatError(f"{str(path)!r}: key {key!r}: {exc}") from None
    try:
        if focal_length_m is not None:
            lens = lens.scaled_to_focal_length(focal_length_m)
        if f_number is not None:
            lens = lens.with_f_number(f_number)
    except ParameterError as exc:
        raise ParameterError(f"lens file {str(path)!r}: {exc}") from None
    return lens


def write_lens_file(path: str | os.PathLike, lens: LensPrescription) -> Path:
    """Write ``lens`` as a lens file, atomically: TOML or JSON by the suffix of ``path``.

    Raises
    ------
    ParameterError
        If ``lens`` is not a LensPrescription, or the suffix is not one of :data:`LENS_SUFFIXES`.
    """
    if not isinstance(lens, LensPrescription):
        raise ParameterError(f"lens must be a LensPrescription, got {shown(lens)}")
    path = Path(path)
    suffix = _suffix(path, LENS_SUFFIXES, "lens file")
    if suffix == ".json":
        return write_json(path, {"kind": LENS_FILE_KIND, "lens": lens.to_dict()})
    first = lens.first_order()
    header = [
        f"# lfrefract lens file: {lens.name!r}, {len(lens.surfaces)} surfaces in order from the object side.",
        "# Lengths in metres; keys: docs/lenses.md, 'Lens files'.",
        f"# First-order data (d line): f = {first.efl_m * 1e3:.6g} mm, f/{first.f_number:.4g}.",
    ]
    return _write_toml(path, header, {"schema_version": SCHEMA_VERSION, "lens": lens.to_dict()})


# =============================================================================== common
def _is_toml(path: Path) -> bool:
    return path.suffix.lower() == ".toml"


def _suffix(path: Path, allowed: tuple[str, ...], what: str) -> str:
    suffix = path.suffix.lower()
    if suffix not in allowed:
        raise ParameterError(f"a {what} must end in {', '.join(allowed)} (the format), got {str(path)!r}")
    return suffix


def _write_toml(path: Path, header: list[str], data: dict) -> Path:
    return write_text_atomically(path, "\n".join(header) + "\n\n" + tomli_w.dumps(data))


def _check_size(path: Path) -> None:
    """Refuse a path that is not a regular file of at most :data:`MAX_PARAMETER_FILE_BYTES` (by its metadata)."""
    try:
        regular_file("parameter file", path, max_bytes=MAX_PARAMETER_FILE_BYTES)
    except ParameterError as exc:
        if not path.exists():
            raise FileFormatError(f"no such file: {str(path)!r}") from None
        raise FileFormatError(str(exc)) from None


def _toml_table(path: Path, key: str) -> dict:
    """The ``key`` table of the TOML camera or port file ``path``, its top level checked."""
    _check_size(path)
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as exc:
        raise FileFormatError(
            f"{str(path)!r} is not UTF-8 text (TOML files must be UTF-8; byte {exc.start}: {exc.reason})"
        ) from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise FileFormatError(f"{str(path)!r} is not valid TOML: {exc}") from None
    except RecursionError:
        raise FileFormatError(f"{str(path)!r} is nested too deeply to be an lfrefract TOML file") from None
    unknown = sorted(set(data) - {"schema_version", key})
    if unknown:
        raise FileFormatError(
            f"{str(path)!r} has unknown top-level keys {unknown} (a {key} file holds a [{key}] table and "
            "schema_version only)"
        )
    version = data.get("schema_version", SCHEMA_VERSION)
    if not isinstance(version, int) or isinstance(version, bool) or version != SCHEMA_VERSION:
        raise FileFormatError(
            f"{str(path)!r}: key 'schema_version' is {shown(version)}, this lfrefract reads {SCHEMA_VERSION}"
        )
    if key not in data:
        raise FileFormatError(f"{str(path)!r} has no key {key!r} (a [{key}] table): it is not a {key} file")
    if not isinstance(data[key], dict):
        raise FileFormatError(f"{str(path)!r}: key {key!r} must be a table ([{key}]), got {shown(data[key])}")
    return data[key]


def _json_table(path: Path, key: str, data: dict | None = None) -> dict:
    """The ``key`` table of the lfrefract JSON file ``path`` (:func:`read_parameter_json`; ``data``: its
    content, if it was read already)."""
    data = read_parameter_json(path) if data is None else data
    if key == "camera" and "lens" in data:
        raise FileFormatError(
            f"{str(path)!r} holds a 'lens' table (a real main lens, {shown(data['lens'])}), which lfrefract's camera "
            "model does not read: its 'camera' table is only the lens's thin-lens equivalent. Calibrate the "
            "camera's rays from in-air boards (lfrefract calibrate camera) and pass that file as --camera, or "
            "remove the table to use the thin lens"
        )
    if key not in data:
        raise FileFormatError(f"{str(path)!r} has no key {key!r}: it is not a {key} file")
    value = data[key]
    if not isinstance(value, dict):
        raise FileFormatError(f"{str(path)!r}: key {key!r} must be a table (a JSON object), got {shown(value)}")
    return value


def _parsed(path: Path, key: str, table: dict, parser):
    """``parser(table)``, its ParameterError a FileFormatError naming the file and the key."""
    try:
        return parser(table)
    except ParameterError as exc:
        raise FileFormatError(f"{str(path)!r}: key {key!r}: {exc}") from None
