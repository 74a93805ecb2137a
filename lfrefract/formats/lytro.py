"""Lytro's own files: the Illum's LFR container and the first-generation camera's (F01) raw frame.

Writers of what a Lytro camera writes, from an integer sensor mosaic and a
:class:`~lfrefract.optics.camera.LightFieldCamera`, and readers of those files (for round trips, and
for real files of the same layout). ``docs/lytro-files.md`` describes every field written and why.

* **Illum LFR** (:func:`write_lfr`, :func:`read_lfr`): the LFP magic header, eleven data sections
  (``LFC``) each named by the SHA-1 of its data, then the table of contents (``LFM``, JSON) naming the
  metadata, private metadata, raw image and thumbnail sections by those names. The raw image is
  10-bit packed little-endian: every 4 pixels of a row in 5 bytes, the 8 high bits of each in the
  first four, their 2 low bits in the fifth (first pixel in its lowest bits).
* **Illum RAW** (:func:`write_illum_raw`): the same packed image as a bare file with its metadata JSON
  beside it, as the Illum's factory white images are shipped.
* **F01 RAW** (:func:`write_f01_raw`, :func:`read_f01_raw`): 12-bit packed big-endian (every 2 pixels in
  3 bytes, high bits first) with the frame metadata JSON beside it (``<stem>.json`` or ``.txt``).

Mosaics are :class:`~lfrefract.formats.mosaic.RawMosaic` (re-exported here): digital numbers (H, W)
uint16 with their bit depth, black and white levels and colour-filter pattern (``"GRBG"``: the
upper-left 2 x 2 tile is G R / B G).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from lfrefract.errors import FileFormatError, ParameterError
from lfrefract.formats.mosaic import CFA_PATTERNS, RawMosaic
from lfrefract.formats.outputs import atomic_file
from lfrefract.optics.camera import GridType, LightFieldCamera, MicrolensArray, SensorGeometry
from lfrefract.validate import bounded_float, bounded_int, finite_float, one_of, shown, text

__all__ = [
    "CFA_PATTERNS",
    "ILLUM_DATA_SECTIONS",
    "LFC_MAGIC",
    "LFM_MAGIC",
    "LFP_MAGIC",
    "LytroCapture",
    "LytroSettings",
    "RawMosaic",
    "camera_from_metadata",
    "colour_from_metadata",
    "colour_matrix",
    "f01_metadata",
    "illum_metadata",
    "pack_10bit",
    "pack_12bit",
    "read_f01_raw",
    "read_illum_raw",
    "read_lfr",
    "unpack_10bit",
    "unpack_12bit",
    "write_f01_raw",
    "write_illum_raw",
    "write_lfr",
]

#: First 12 bytes of an LFP/LFR file; a 4-byte big-endian length (0) follows.
LFP_MAGIC = b"\x89LFP\r\n\x1a\n\x00\x00\x00\x01"
#: Magic of the table-of-contents section (JSON).
LFM_MAGIC = b"\x89LFM\r\n\x1a\n\x00\x00\x00\x00"
#: Magic of a content section.
LFC_MAGIC = b"\x89LFC\r\n\x1a\n\x00\x00\x00\x00"
#: Data sections in an Illum LFR, before its table of contents. imageio's reader walks exactly this many.
ILLUM_DATA_SECTIONS = 11

# Lytro names the pattern by its canonical tile "r,gr:gb,b" and the colour of the upper-left pixel.
_UPPER_LEFT = {"GRBG": "gr", "RGGB": "r", "GBRG": "gb", "BGGR": "b"}
_TILE = "r,gr:gb,b"
_CHANNELS = ("r", "gr", "gb", "b")
_TILINGS: dict[GridType, str] = {"hex": "hexUniformRowMajor", "square": "squareUniformRowMajor"}

_SHA1_NAME = re.compile(rb"sha1-[0-9a-f]{40}")
_NON_ZERO = re.compile(rb"[^\0]")
_SECTION_HEADER = 12 + 4 + 45 + 35  # magic, size, name, padding
_ALIGN = 16  # sections start on 16-byte boundaries; the gap is zeros
_MAX_FILE_BYTES = 2**31 - 1  # the section size is a signed 32-bit integer
_ILLUM_BITS = 10
_F01_BITS = 12


@dataclass(frozen=True, kw_only=True)
class LytroSettings:
    """What a Lytro file records beyond the camera geometry and the mosaic's levels.

    Parameters
    ----------
    color_matrix : tuple of 9 float
        The colour-correction matrix from the sensor's RGB to linear sRGB, row-major (``ccm``).
        The default identity is exact for a simulator whose channels are the renderer's linear RGB.
    white_balance_gain : tuple of 4 float
        Gains of the r, gr, gb, b channels (positive).
    exit_pupil_offset_m : float or None
        Distance from the MLA to the main lens's exit pupil, metres, positive forwards. ``None``:
        the thin lens's, whose exit pupil is the lens itself (``camera.lens_to_mla_m``).
    zoom_step, focus_step : int
        The lens motors' positions (a simulated lens has none: 0 unless told).
    iso : int
        The sensitivity recorded (Illum base ISO 80).
    base_iso : int
        The sensor's base ISO; the metadata's ``analogGain`` is ``iso / base_iso`` (1 at the base ISO).
    serial_number : str
        The camera's serial (printable ASCII). Decoders tell the Illum from the F01 by its first
        letter (Illum ``B``, F01 ``A``): the writers prefix ``"B-"`` or ``"A-"`` to one that lacks it.

    Raises
    ------
    ParameterError
        If a value is non-finite or out of range; the message names the parameter.
    """

    color_matrix: tuple[float, ...] = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    white_balance_gain: tuple[float, ...] = (1.0, 1.0, 1.0, 1.0)
    exit_pupil_offset_m: float | None = None
    zoom_step: int = 0
    focus_step: int = 0
    iso: int = 80
    base_iso: int = 80
    serial_number: str = "lfrefract-simulated"

    def __post_init__(self) -> None:
        ccm = tuple(
            finite_float(f"color_matrix[{i}]", v) for i, v in enumerate(_sequence("color_matrix", self.color_matrix, 9))
        )
        colour_matrix("color_matrix", ccm)
        gains = tuple(
            bounded_float(f"white_balance_gain[{i}]", v, 0.0, 1e3, low_open=True)
            for i, v in enumerate(_sequence("white_balance_gain", self.white_balance_gain, 4))
        )
        object.__setattr__(self, "color_matrix", ccm)
        object.__setattr__(self, "white_balance_gain", gains)
        if self.exit_pupil_offset_m is not None:
            epo = bounded_float("exit_pupil_offset_m", self.exit_pupil_offset_m, 0.0, 1e3, low_open=True, unit="m")
            object.__setattr__(self, "exit_pupil_offset_m", epo)
        object.__setattr__(self, "zoom_step", bounded_int("zoom_step", self.zoom_step, -(2**31), 2**31 - 1))
        object.__setattr__(self, "focus_step", bounded_int("focus_step", self.focus_step, -(2**31), 2**31 - 1))
        object.__setattr__(self, "iso", bounded_int("iso", self.iso, 1, 10**6))
        object.__setattr__(self, "base_iso", bounded_int("base_iso", self.base_iso, 1, 10**6))
        serial = text("serial_number", self.serial_number)
        if not serial.isprintable() or not serial.isascii():
            raise ParameterError(f"serial_number must be printable ASCII, got {shown(serial)}")

    def serial_for(self, prefix: str) -> str:
        """The serial as written for a camera whose serials begin with ``prefix`` (``"B"`` or ``"A"``)."""
        return self.serial_number if self.serial_number.startswith(prefix) else f"{prefix}-{self.serial_number}"


#: Largest condition number of a colour matrix: beyond it the matrix is singular in float arithmetic (an
#: all-zero ``ccm`` made every image black). Real matrices are near 2-10.
_MAX_CCM_CONDITION = 1e6
#: Largest magnitude of a colour matrix's entry (real ones lie within +-5): it bounds the developed image
#: (at most 65535 DN / a tenth of a bright white / 1e3 gain, times 3 entries) far inside float32.
_MAX_CCM_ENTRY = 100.0


def colour_matrix(name: str, value: Any) -> np.ndarray:
    """``value`` as a colour matrix (9 numbers row-major, or 3 x 3) from camera RGB to linear RGB, checked.

    Raises
    ------
    ParameterError
        Naming ``name``, unless it is 9 finite numbers within +-100 whose matrix is invertible (a
        singular one loses a colour: all zeros make every image black) and takes white (1, 1, 1) to
        light in every colour (each row sums to more than 0).
    """
    if isinstance(value, (str, bytes, dict)) or not hasattr(value, "__len__"):
        raise ParameterError(f"{name} must be 9 numbers (a 3 x 3 matrix, row by row), got {shown(value)}")
    array = np.asarray(value, dtype=object).reshape(-1) if len(value) else np.zeros(0, dtype=object)
    if array.size != 9 or any(isinstance(v, bool) or not isinstance(v, (int, float, np.number)) for v in array):
        raise ParameterError(f"{name} must be 9 numbers (a 3 x 3 matrix, row by row), got {shown(value)}")
    matrix = array.astype(np.float64).reshape(3, 3)
    if not np.all(np.isfinite(matrix)):
        raise ParameterError(f"{name} must hold finite numbers, got {matrix.reshape(-1).tolist()}")
    if np.abs(matrix).max() > _MAX_CCM_ENTRY:
        raise ParameterError(
            f"{name} {matrix.reshape(-1).tolist()} has an entry beyond +-{_MAX_CCM_ENTRY:g} (real colour matrices "
            "lie within +-5)"
        )
    rows = matrix.sum(axis=1)
    if np.linalg.cond(matrix) > _MAX_CCM_CONDITION:
        raise ParameterError(
            f"{name} {matrix.reshape(-1).tolist()} is singular: it loses colours (all zeros makes every image black)"
        )
    if not np.all(rows > 0.0):
        row = int(np.argmin(rows))
        raise ParameterError(
            f"{name} {matrix.reshape(-1).tolist()}: row {row} sums to {rows[row]:g}, so white gets no light in that "
            "colour; each row of a colour matrix sums to more than 0 (about 1)"
        )
    return matrix


def _sequence(name: str, value: Any, length: int) -> tuple:
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != length:
        raise ParameterError(f"{name} must be a sequence of {length} numbers, got {shown(value)}")
    return tuple(value)


@dataclass(frozen=True, eq=False, kw_only=True)
class LytroCapture:
    """What a Lytro file holds, as read back.

    Parameters
    ----------
    mosaic : RawMosaic
        The raw image and its levels and pattern.
    camera : LightFieldCamera
        The camera the metadata describes (:func:`camera_from_metadata`), or for files written by
        lfrefract the exact camera of the ``lfrefractCamera`` section.
    metadata : dict
        The frame's metadata JSON, as written.
    private_metadata : dict
        The private metadata (serial numbers); empty for a bare RAW file.
    thumbnail_jpeg : bytes
        The thumbnail, a JPEG file's bytes; empty for a bare RAW file.
    """

    mosaic: RawMosaic
    camera: LightFieldCamera
    metadata: dict
    private_metadata: dict = field(default_factory=dict)
    thumbnail_jpeg: bytes = field(default=b"", repr=False)


# =============================================================================== bit packing
def pack_10bit(counts: np.ndarray) -> bytes:
    """Pack digital numbers as the Illum does: 10 bits, 4 pixels in 5 bytes, little-endian low bits.

    Pixels are taken row by row. Bytes 0-3 of a group hold the 8 high bits of pixels 0-3; byte 4
    holds their 2 low bits, pixel 0 in bits 0-1, pixel 1 in bits 2-3, pixel 2 in 4-5, pixel 3 in 6-7.

    Parameters
    ----------
    counts : numpy.ndarray
        Values in [0, 1023], shape (H, W) with ``H * W`` a multiple of 4.

    Returns
    -------
    bytes
        ``H * W * 5 / 4`` bytes.
    """
    flat = _packable(counts, 10)
    if flat.size % 4:
        raise ParameterError(f"10-bit packing needs a pixel count divisible by 4, got {flat.size}")
    groups = flat.reshape(-1, 4)
    out = np.empty((groups.shape[0], 5), dtype=np.uint8)
    out[:, :4] = groups >> 2
    low = groups & 3
    out[:, 4] = low[:, 0] | (low[:, 1] << 2) | (low[:, 2] << 4) | (low[:, 3] << 6)
    return out.tobytes()


def _packable(counts: np.ndarray, bits: int) -> np.ndarray:
    """``counts`` flattened to uint16, after checking they are integers in [0, 2**bits - 1]: a float
    or out-of-range value is refused, never rounded or wrapped by the cast."""
    arr = np.asarray(counts)
    if arr.dtype.kind not in "iu":
        raise ParameterError(f"{bits}-bit packing needs integer counts, got dtype {arr.dtype}")
    top = 2**bits - 1
    if arr.size and (int(arr.min()) < 0 or int(arr.max()) > top):
        raise ParameterError(f"{bits}-bit packing needs values in [0, {top}], got [{int(arr.min())}, {int(arr.max())}]")
    return np.ascontiguousarray(arr, dtype=np.uint16).reshape(-1)


def _packed_groups(data: bytes | memoryview, shape: tuple[int, int], bits: int, pixels: int, size: int) -> np.ndarray:
    """The bytes of a ``bits``-bit packed (H, W) image as (groups, ``size``) uint16, ``pixels`` pixels a group.

    Raises
    ------
    FileFormatError
        If the size is not positive, or the byte count does not match it.
    """
    height, width = shape
    if height <= 0 or width <= 0:
        raise FileFormatError(f"an image of {width} x {height} pixels: its size must be positive")
    expected = height * width * size // pixels
    if (height * width) % pixels or len(data) != expected:
        raise FileFormatError(f"a {bits}-bit {width} x {height} image takes {expected} bytes, got {len(data)}")
    return np.frombuffer(data, dtype=np.uint8).reshape(-1, size).astype(np.uint16)


def unpack_10bit(data: bytes | memoryview, shape: tuple[int, int]) -> np.ndarray:
    """Inverse of :func:`pack_10bit`: (H, W) uint16 from ``H * W * 5 / 4`` bytes.

    Raises
    ------
    FileFormatError
        If the byte count does not match the shape.
    """
    groups = _packed_groups(data, shape, 10, 4, 5)
    out = np.empty((groups.shape[0], 4), dtype=np.uint16)
    for k in range(4):
        out[:, k] = (groups[:, k] << 2) | ((groups[:, 4] >> (2 * k)) & 3)
    return out.reshape(shape)


def pack_12bit(counts: np.ndarray) -> bytes:
    """Pack digital numbers as the F01 does: 12 bits, 2 pixels in 3 bytes, big-endian.

    Byte 0 holds the 8 high bits of pixel 0; byte 1 its 4 low bits (high nibble) and the 4 high bits
    of pixel 1 (low nibble); byte 2 the 8 low bits of pixel 1.

    Parameters
    ----------
    counts : numpy.ndarray
        Values in [0, 4095], shape (H, W) with ``H * W`` even.
    """
    flat = _packable(counts, 12)
    if flat.size % 2:
        raise ParameterError(f"12-bit packing needs an even pixel count, got {flat.size}")
    pairs = flat.reshape(-1, 2)
    out = np.empty((pairs.shape[0], 3), dtype=np.uint8)
    out[:, 0] = pairs[:, 0] >> 4
    out[:, 1] = ((pairs[:, 0] & 15) << 4) | (pairs[:, 1] >> 8)
    out[:, 2] = pairs[:, 1] & 255
    return out.tobytes()


def unpack_12bit(data: bytes | memoryview, shape: tuple[int, int]) -> np.ndarray:
    """Inverse of :func:`pack_12bit`: (H, W) uint16 from ``H * W * 3 / 2`` bytes.

    Raises
    ------
    FileFormatError
        If the byte count does not match the shape.
    """
    triples = _packed_groups(data, shape, 12, 2, 3)
    out = np.empty((triples.shape[0], 2), dtype=np.uint16)
    out[:, 0] = (triples[:, 0] << 4) | (triples[:, 1] >> 4)
    out[:, 1] = ((triples[:, 1] & 15) << 8) | triples[:, 2]
    return out.reshape(shape)


# =============================================================================== metadata
def _per_channel(value: float | int) -> dict:
    return dict.fromkeys(_CHANNELS, value)


def _mla_and_lens(camera: LightFieldCamera, settings: LytroSettings) -> tuple[dict, dict]:
    mla = camera.mla
    exit_pupil = camera.lens_to_mla_m if settings.exit_pupil_offset_m is None else settings.exit_pupil_offset_m
    mla_table = {
        "tiling": _TILINGS[mla.grid],
        "lensPitch": mla.pitch_m,
        "rotation": mla.rotation_rad,
        "scaleFactor": {"x": 1.0, "y": 1.0},
        "sensorOffset": {"x": mla.offset_m[0], "y": mla.offset_m[1], "z": mla.focal_length_m},
        "config": "lfrefract",
    }
    lens_table = {
        "focalLength": camera.focal_length_m,
        "fNumber": camera.f_number,
        "exitPupilOffset": {"z": exit_pupil},
        "zoomStep": settings.zoom_step,
        "focusStep": settings.focus_step,
        "opticalCenterOffset": {"x": 0.0, "y": 0.0},
    }
    return mla_table, lens_table


def _check_mosaic(mosaic: RawMosaic, camera: LightFieldCamera, bits: int, what: str) -> None:
    if not isinstance(mosaic, RawMosaic):
        raise ParameterError(f"mosaic must be a RawMosaic, got {type(mosaic).__name__}")
    if not isinstance(camera, LightFieldCamera):
        raise ParameterError(f"camera must be a LightFieldCamera, got {type(camera).__name__}")
    if mosaic.bit_depth != bits:
        raise ParameterError(f"the {what} stores {bits}-bit pixels, got a mosaic of bit_depth={mosaic.bit_depth}")
    sensor = camera.sensor
    if mosaic.shape != (sensor.height_px, sensor.width_px):
        raise ParameterError(
            f"mosaic of shape {mosaic.shape} does not match the camera's "
            f"{sensor.width_px} x {sensor.height_px} px sensor"
        )
    if sensor.height_px < 2 or sensor.width_px < 2:
        raise ParameterError(f"a Bayer mosaic has at least 2 x 2 pixels, got {sensor.width_px} x {sensor.height_px}")
    group = 4 if bits == _ILLUM_BITS else 2
    if sensor.width_px % group:
        raise ParameterError(
            f"the {what} packs {group} pixels of a row together: width {sensor.width_px} px is not a multiple"
        )


def illum_metadata(mosaic: RawMosaic, camera: LightFieldCamera, settings: LytroSettings | None = None) -> dict:
    """The Illum frame metadata (the LFR's ``metadataRef`` section, the RAW's JSON), as decoders read it.

    Parameters
    ----------
    mosaic : RawMosaic
        A 10-bit mosaic of the camera's sensor size.
    camera : LightFieldCamera
        Its geometry: pixel pitch, MLA pitch, rotation, offset and gap, focal length, f-number.
    settings : LytroSettings, optional
        Colour matrix, white balance, exit pupil, zoom/focus steps, ISO, serial.

    Returns
    -------
    dict
        Lengths in metres, angles in radians (Lytro's units); see ``docs/lytro-files.md``.
    """
    settings = LytroSettings() if settings is None else settings
    _check_mosaic(mosaic, camera, _ILLUM_BITS, "Illum LFR")
    height, width = mosaic.shape
    mosaic_table = {"tile": _TILE, "upperLeftPixel": _UPPER_LEFT[mosaic.cfa_pattern]}
    gains = dict(zip(_CHANNELS, settings.white_balance_gain, strict=True))
    mla_table, lens_table = _mla_and_lens(camera, settings)
    return {
        "generator": "lfrefract",
        "camera": {"make": "lfrefract (simulated)", "model": "ILLUM"},
        "image": {
            "width": width,
            "height": height,
            "orientation": 1,
            "pixelPacking": {"bitsPerPixel": _ILLUM_BITS, "endianness": "little"},
            "pixelFormat": {
                "black": _per_channel(mosaic.black_level_dn),
                "white": _per_channel(mosaic.white_level_dn),
                "rightShift": 0,
            },
            "mosaic": mosaic_table,
            "color": {"ccm": list(settings.color_matrix), "whiteBalanceGain": gains},
            "iso": settings.iso,
            "originOnSensor": {"x": 0, "y": 0},
            "modulationExposureBias": 0.0,
            "limitExposureBias": 0.0,
        },
        "devices": {
            "sensor": {
                "pixelPitch": camera.sensor.pixel_pitch_m,
                "pixelWidth": width,
                "pixelHeight": height,
                "bitsPerPixel": _ILLUM_BITS,
                "mosaic": mosaic_table,
                "analogGain": _per_channel(settings.iso / settings.base_iso),
                "baseIso": settings.base_iso,
            },
            "mla": mla_table,
            "lens": lens_table,
        },
        "algorithms": {"awb": {"computed": {"gain": gains}}},
        "picture": {"totalFrames": 1, "frameIndex": 0},
    }


def f01_metadata(mosaic: RawMosaic, camera: LightFieldCamera, settings: LytroSettings | None = None) -> dict:
    """The F01 frame metadata (the JSON beside its ``.raw``), laid out as the F01 writes it.

    Parameters are those of :func:`illum_metadata`, for a 12-bit mosaic. The F01 keeps the packing,
    levels and pattern under ``image.rawDetails`` and names its colour matrix ``ccmRgbToSrgbArray``.
    """
    settings = LytroSettings() if settings is None else settings
    _check_mosaic(mosaic, camera, _F01_BITS, "F01 RAW")
    height, width = mosaic.shape
    mosaic_table = {"tile": _TILE, "upperLeftPixel": _UPPER_LEFT[mosaic.cfa_pattern]}
    gains = dict(zip(_CHANNELS, settings.white_balance_gain, strict=True))
    mla_table, lens_table = _mla_and_lens(camera, settings)
    return {
        "type": "lightField",
        "generator": "lfrefract",
        "camera": {"make": "lfrefract (simulated)", "model": "F01", "serialNumber": settings.serial_for("A")},
        "image": {
            "width": width,
            "height": height,
            "orientation": 1,
            "representation": "rawPacked",
            "rawDetails": {
                "pixelFormat": {
                    "rightShift": 0,
                    "black": _per_channel(mosaic.black_level_dn),
                    "white": _per_channel(mosaic.white_level_dn),
                },
                "pixelPacking": {"endianness": "big", "bitsPerPixel": _F01_BITS},
                "mosaic": mosaic_table,
            },
            "color": {"ccmRgbToSrgbArray": list(settings.color_matrix), "whiteBalanceGain": gains},
            "modulationExposureBias": 0.0,
            "limitExposureBias": 0.0,
        },
        "devices": {
            "sensor": {
                "bitsPerPixel": _F01_BITS,
                "mosaic": mosaic_table,
                "iso": settings.iso,
                "analogGain": _per_channel(settings.iso / settings.base_iso),
                "pixelPitch": camera.sensor.pixel_pitch_m,
            },
            "lens": lens_table,
            "mla": mla_table,
        },
    }


def _get(metadata: Any, path: str, where: str) -> Any:
    node = metadata
    for key in path.split("."):
        if not isinstance(node, dict) or key not in node:
            raise FileFormatError(f"{where}: the metadata has no {path!r}")
        node = node[key]
    return node


def _number(metadata: dict, path: str, where: str) -> float:
    value = _get(metadata, path, where)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise FileFormatError(f"{where}: metadata {path!r} must be a finite number, got {shown(value)}")
    return float(value)


def _integer(metadata: dict, path: str, where: str) -> int:
    value = _get(metadata, path, where)
    if isinstance(value, bool) or not isinstance(value, int):
        raise FileFormatError(f"{where}: metadata {path!r} must be an integer, got {shown(value)}")
    return value


def colour_from_metadata(metadata: dict, *, where: str = "metadata") -> tuple[np.ndarray, tuple[float, float, float]]:
    """The colour matrix and the R, G, B white-balance gains of a Lytro frame's metadata.

    The matrix is ``image.color.ccm`` (Illum) or ``image.color.ccmRgbToSrgbArray`` (F01), checked by
    :func:`colour_matrix`; where a file has both they must agree. The gains are
    ``image.color.whiteBalanceGain`` (``r``, ``gr``, ``gb``, ``b``, each finite and in (0, 1000]), G the
    mean of the two greens. Both cameras write both keys: a file without them is refused, never read
    as identity and 1.

    Returns
    -------
    (ndarray of shape (3, 3), (float, float, float))

    Raises
    ------
    FileFormatError
        Naming ``where`` and the key, for a missing, malformed, non-finite or contradictory value.
    """
    color = _get(metadata, "image.color", where)
    if not isinstance(color, dict):
        raise FileFormatError(f"{where}: metadata 'image.color' must be a table, got {shown(color)}")
    keys = [key for key in ("ccm", "ccmRgbToSrgbArray") if key in color]
    if not keys:
        raise FileFormatError(
            f"{where}: the metadata has no 'image.color.ccm' (Illum) or 'image.color.ccmRgbToSrgbArray' (F01)"
        )
    matrices = []
    for key in keys:
        try:
            matrices.append(colour_matrix(f"metadata 'image.color.{key}'", color[key]))
        except ParameterError as exc:
            raise FileFormatError(f"{where}: {exc}") from None
    if len(matrices) == 2 and not np.array_equal(matrices[0], matrices[1]):
        raise FileFormatError(f"{where}: metadata 'image.color.ccm' and 'image.color.ccmRgbToSrgbArray' differ")
    gains = _get(metadata, "image.color.whiteBalanceGain", where)
    if not isinstance(gains, dict):
        raise FileFormatError(
            f"{where}: metadata 'image.color.whiteBalanceGain' must be a table of r, gr, gb, b, got {shown(gains)}"
        )
    missing = [c for c in _CHANNELS if c not in gains]
    if missing:
        raise FileFormatError(
            f"{where}: metadata 'image.color.whiteBalanceGain' has no {', '.join(map(repr, missing))}"
        )
    values = {}
    for c in _CHANNELS:
        try:
            values[c] = bounded_float(f"metadata 'image.color.whiteBalanceGain.{c}'", gains[c], 0.0, 1e3, low_open=True)
        except ParameterError as exc:
            raise FileFormatError(f"{where}: {exc}") from None
    return matrices[0], (values["r"], 0.5 * (values["gr"] + values["gb"]), values["b"])


def _check_layout(metadata: dict, format_table: str, shape: tuple[int, int], bits: int, where: str) -> None:
    """Refuse metadata whose keys contradict the image's size, packing and pattern (``format_table``:
    ``image`` or ``image.rawDetails``), or ask for a shift lfrefract does not apply.

    ``devices.sensor.pixelWidth``, ``pixelHeight`` (the Illum writes them, the F01 does not),
    ``bitsPerPixel`` and ``mosaic``, and ``pixelFormat.rightShift`` are checked where the file has them.
    """
    sensor = metadata.get("devices", {}).get("sensor") if isinstance(metadata.get("devices"), dict) else None
    sensor = sensor if isinstance(sensor, dict) else {}
    expected = {"pixelWidth": ("image.width", shape[1]), "pixelHeight": ("image.height", shape[0])}
    expected["bitsPerPixel"] = (f"{format_table}.pixelPacking.bitsPerPixel", bits)
    for key, (other, value) in expected.items():
        if key in sensor:
            found = _integer(metadata, f"devices.sensor.{key}", where)
            if found != value:
                raise FileFormatError(
                    f"{where}: metadata {other!r} is {value} but 'devices.sensor.{key}' is {found}: the metadata "
                    "contradicts itself (swapped or edited?)"
                )
    if "mosaic" in sensor and sensor["mosaic"] != _get(metadata, f"{format_table}.mosaic", where):
        raise FileFormatError(
            f"{where}: metadata 'devices.sensor.mosaic' {shown(sensor['mosaic'])} contradicts "
            f"'{format_table}.mosaic' {shown(_get(metadata, f'{format_table}.mosaic', where))}"
        )
    shift_key = f"{format_table}.pixelFormat.rightShift"
    try:
        _get(metadata, shift_key, where)
    except FileFormatError:
        return  # absent: no shift
    shift = _integer(metadata, shift_key, where)
    if shift != 0:
        raise FileFormatError(f"{where}: metadata {shift_key!r} is {shift}; lfrefract reads unshifted counts only (0)")


def camera_from_metadata(metadata: dict, *, where: str = "metadata") -> LightFieldCamera:
    """The thin-lens camera a Lytro frame's metadata describes (Illum or F01 layout).

    The main lens is placed at the exit pupil (``lens_to_mla_m = exitPupilOffset.z``, exact for the
    files lfrefract writes of a thin lens); the MLA is ``devices.mla`` (``sensorOffset.z`` is its gap
    to the sensor, taken as its focal length), the sensor ``image.width`` x ``image.height`` pixels of
    ``devices.sensor.pixelPitch``.

    The metadata gives the lens's f-number on the object side (``fNumber``), not its exit pupil's
    diameter. A thin lens at the exit pupil with that f-number has the exit pupil of the entrance
    pupil's size; where that would make the micro-images overlap (image-side f-number
    ``exitPupilOffset.z * fNumber / focalLength`` below the microlenses', as for a lens whose exit
    pupil is smaller than its entrance pupil, e.g. a telephoto or Petzval design close to the MLA)
    the camera it describes has no such pupil: its f-number is then taken as the one that fills the
    microlenses exactly (image-side f-number the microlenses'), the largest exit pupil a camera whose
    micro-images do not overlap can have.

    Raises
    ------
    FileFormatError
        If a field is missing or not a number, or the values are no camera; the message names
        ``where`` and the field.
    """
    tiling = _get(metadata, "devices.mla.tiling", where)
    grids = {v: k for k, v in _TILINGS.items()}
    if tiling not in grids:
        raise FileFormatError(f"{where}: devices.mla.tiling {shown(tiling)} is none of {sorted(grids)}")
    try:
        mla = MicrolensArray(
            grid=grids[tiling],
            pitch_m=_number(metadata, "devices.mla.lensPitch", where),
            focal_length_m=_number(metadata, "devices.mla.sensorOffset.z", where),
            rotation_rad=_number(metadata, "devices.mla.rotation", where),
            offset_m=(
                _number(metadata, "devices.mla.sensorOffset.x", where),
                _number(metadata, "devices.mla.sensorOffset.y", where),
            ),
        )
        focal_length = _number(metadata, "devices.lens.focalLength", where)
        exit_pupil = _number(metadata, "devices.lens.exitPupilOffset.z", where)
        f_number = _number(metadata, "devices.lens.fNumber", where)
        if focal_length > 0.0 and exit_pupil > 0.0 and f_number > 0.0:  # else LightFieldCamera names the value
            f_number = max(f_number, mla.f_number * focal_length / exit_pupil)
        return LightFieldCamera(
            name="lytro-metadata",
            focal_length_m=focal_length,
            lens_to_mla_m=exit_pupil,
            f_number=f_number,
            mla=mla,
            sensor=SensorGeometry(
                width_px=_integer(metadata, "image.width", where),
                height_px=_integer(metadata, "image.height", where),
                pixel_pitch_m=_number(metadata, "devices.sensor.pixelPitch", where),
            ),
        )
    except ParameterError as exc:
        raise FileFormatError(f"{where}: the metadata describes no camera: {exc}") from None


def _mosaic_from_metadata(counts: np.ndarray, metadata: dict, format_table: str, bits: int, where: str) -> RawMosaic:
    """The levels and pattern of ``metadata`` (under ``format_table``: ``image`` or ``image.rawDetails``)."""
    levels = {}
    for kind in ("black", "white"):
        values = {_integer(metadata, f"{format_table}.pixelFormat.{kind}.{c}", where) for c in _CHANNELS}
        if len(values) != 1:
            raise FileFormatError(
                f"{where}: per-channel {kind} levels {sorted(values)} differ; lfrefract reads one level"
            )
        levels[kind] = values.pop()
    upper_left = _get(metadata, f"{format_table}.mosaic.upperLeftPixel", where)
    patterns = {v: k for k, v in _UPPER_LEFT.items()}
    if _get(metadata, f"{format_table}.mosaic.tile", where) != _TILE or upper_left not in patterns:
        raise FileFormatError(
            f"{where}: mosaic {shown(_get(metadata, f'{format_table}.mosaic', where))} is not a Bayer pattern"
        )
    try:
        return RawMosaic(
            counts=counts,
            bit_depth=bits,
            black_level_dn=levels["black"],
            white_level_dn=levels["white"],
            cfa_pattern=patterns[upper_left],
        )
    except ParameterError as exc:
        raise FileFormatError(f"{where}: {exc}") from None


# =============================================================================== thumbnail
def _thumbnail_jpeg(mosaic: RawMosaic, settings: LytroSettings, *, max_side_px: int = 640) -> tuple[bytes, int, int]:
    """A display preview, JPEG: each colour's sites area-averaged to at most ``max_side_px`` a side,
    black-subtracted, white-balanced, colour-corrected, clipped to white, gamma 1/2.2."""
    import cv2

    counts = mosaic.counts
    cells = (mosaic.shape[0] // 2, mosaic.shape[1] // 2)  # 2 x 2 tiles
    factor = max(1, math.ceil(max(cells) / max_side_px))
    # Per axis: a long, narrow sensor has fewer tiles across than the long side's factor.
    fy, fx = min(factor, cells[0]), min(factor, cells[1])
    size = (cells[1] // fx, cells[0] // fy)  # (width, height), as OpenCV takes it
    scale = 1.0 / float(mosaic.white_level_dn - mosaic.black_level_dn)
    gains = dict(zip(_CHANNELS, settings.white_balance_gain, strict=True))
    # The pattern's four sites in tile order (0, 0), (0, 1), (1, 0), (1, 1); a green is named by its row's other colour.
    plane = {}
    for k, letter in enumerate(mosaic.cfa_pattern):
        row, col = divmod(k, 2)
        row_partner = mosaic.cfa_pattern[2 * row + (1 - col)]
        channel = {"R": "r", "B": "b"}.get(letter) or ("gr" if row_partner == "R" else "gb")
        # Mean of factor x factor blocks of this colour's sites (the last partial blocks are left out).
        sites = counts[row : 2 * size[1] * fy : 2, col : 2 * size[0] * fx : 2]
        sums = sites.reshape(size[1], fy, size[0], fx).sum(axis=(1, 3), dtype=np.uint32)
        mean = sums.astype(np.float32) / float(fy * fx)
        plane[channel] = (mean - mosaic.black_level_dn) * (scale * gains[channel])
    rgb = np.stack([plane["r"], 0.5 * (plane["gr"] + plane["gb"]), plane["b"]], axis=-1)
    rgb = rgb @ np.asarray(settings.color_matrix, dtype=np.float32).reshape(3, 3).T
    display = np.clip(rgb, 0.0, 1.0) ** (1.0 / 2.2)
    bgr = np.ascontiguousarray((display[..., ::-1] * 255.0 + 0.5).astype(np.uint8))
    ok, buffer = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, 90])
    if not ok:  # OpenCV reports failure by its return value
        raise ParameterError(f"OpenCV could not encode a {size[0]} x {size[1]} thumbnail")
    return buffer.tobytes(), size[0], size[1]


# =============================================================================== LFR
def _sha1_name(data: bytes | memoryview) -> str:
    return "sha1-" + hashlib.sha1(data).hexdigest()


def _section(magic: bytes, data: bytes, name: str) -> list[bytes]:
    header = magic + len(data).to_bytes(4, "big") + name.encode("ascii") + b"\0" * 35
    gap = (-len(data)) % _ALIGN
    return [header, data, b"\0" * gap]


def _json_bytes(data: dict) -> bytes:
    return json.dumps(data, indent=2, allow_nan=False).encode("ascii")


def write_lfr(
    path: str | os.PathLike,
    mosaic: RawMosaic,
    camera: LightFieldCamera,
    *,
    settings: LytroSettings | None = None,
) -> Path:
    """Write an Illum LFR file, atomically.

    Layout: the LFP header (magic, length 0); :data:`ILLUM_DATA_SECTIONS` ``LFC`` sections: the
    metadata (:func:`illum_metadata`), the private metadata (serial numbers), the 10-bit packed raw
    image, a JPEG thumbnail, the exact camera (``lfrefractCamera``, lfrefract's own) where the
    metadata describes it exactly, and ``reserved`` JSON sections that hold the count at the Illum's
    eleven; then the ``LFM`` table of
    contents naming each section by the SHA-1 of its data. Each section has a 96-byte header
    (magic, big-endian length, name, zeros) and its data zero-padded to 16 bytes.

    Parameters
    ----------
    path : path-like
        The file (``.lfr`` for readers that go by the extension, as imageio does).
    mosaic : RawMosaic
        10-bit digital numbers of the camera's sensor size (width a multiple of 4).
    camera : LightFieldCamera
        The camera whose geometry the metadata records.
    settings : LytroSettings, optional
        Colour, white balance, exit pupil, lens steps, ISO, serial (``B``-prefixed if it is not).
        An exit pupil other than ``camera.lens_to_mla_m`` (a real main lens's) leaves the
        ``lfrefractCamera`` section out: the thin-lens ``camera`` would then contradict the
        metadata's micro-image geometry (the exit pupil sets where the micro-images lie), so a
        reader takes the camera the metadata describes (:func:`camera_from_metadata`), as it does
        for a camera's own file and for white images.

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    ParameterError
        If the mosaic is not 10-bit, does not match the sensor, or the file would pass 2 GiB.
    """
    settings = LytroSettings() if settings is None else settings
    exact = settings.exit_pupil_offset_m is None or settings.exit_pupil_offset_m == camera.lens_to_mla_m
    metadata = illum_metadata(mosaic, camera, settings)
    private = {"generator": "lfrefract", "camera": {"serialNumber": settings.serial_for("B")}}
    image = pack_10bit(mosaic.counts)
    thumbnail, thumb_w, thumb_h = _thumbnail_jpeg(mosaic, settings)
    payloads: dict[str, bytes] = {
        "metadataRef": _json_bytes(metadata),
        "privateMetadataRef": _json_bytes(private),
        "imageRef": image,
        "thumbnailRef": thumbnail,
    }
    if exact:
        payloads["cameraRef"] = _json_bytes({"lfrefractCamera": camera.to_dict()})
    reserved = ILLUM_DATA_SECTIONS - len(payloads)
    for k in range(reserved):
        payloads[f"reserved{k}"] = _json_bytes({"lfrefractReserved": k})
    names = {key: _sha1_name(data) for key, data in payloads.items()}
    toc = {
        "generator": "lfrefract",
        "frames": [
            {
                "frame": {
                    "metadataRef": names["metadataRef"],
                    "privateMetadataRef": names["privateMetadataRef"],
                    "imageRef": names["imageRef"],
                }
            }
        ],
        "thumbnails": [
            {"imageRef": names["thumbnailRef"], "width": thumb_w, "height": thumb_h, "representation": "jpeg"}
        ],
        "lfrefract": {
            **({"cameraRef": names["cameraRef"]} if exact else {}),
            "reservedRefs": [names[f"reserved{k}"] for k in range(reserved)],
        },
    }
    toc_bytes = _json_bytes(toc)
    parts = [LFP_MAGIC, (0).to_bytes(4, "big")]
    for key, data in payloads.items():
        parts += _section(LFC_MAGIC, data, names[key])
    parts += _section(LFM_MAGIC, toc_bytes, _sha1_name(toc_bytes))
    total = sum(len(p) for p in parts)
    if total > _MAX_FILE_BYTES:
        raise ParameterError(f"an LFR file of {total} bytes would pass the format's 2 GiB limit")
    with atomic_file(path) as tmp, open(tmp, "wb") as out:
        for part in parts:
            out.write(part)
    return Path(path)


def _read_bytes(path: Path, what: str) -> bytes:
    try:
        with open(path, "rb") as handle:
            return handle.read(_MAX_FILE_BYTES + 1)
    except FileNotFoundError:
        raise FileFormatError(f"no such file: {str(path)!r}") from None
    except IsADirectoryError:
        raise FileFormatError(f"{str(path)!r} is a directory, not {what}") from None
    except OSError as exc:
        raise FileFormatError(f"{str(path)!r} cannot be read: {exc.strerror or exc}") from None


def _sections(data: bytes, where: str) -> list[tuple[bytes, str, memoryview, int]]:
    """(magic, name, data, offset) of every section after the LFP header, each hash checked."""
    view = memoryview(data)
    if len(data) < 16 and len(data) > 0 and LFP_MAGIC.startswith(bytes(data[:12])):
        raise FileFormatError(
            f"{where} is truncated: {len(data)} bytes, too short for the 16-byte LFP header its first bytes begin"
        )
    if len(data) < 16 or data[:12] != LFP_MAGIC:
        raise FileFormatError(f"{where} is not a Lytro LFP/LFR file (it begins {bytes(data[:12])!r})")
    if data[12:16] != b"\0\0\0\0":
        raise FileFormatError(f"{where}: header length {int.from_bytes(data[12:16], 'big')} is not 0")
    out: list[tuple[bytes, str, memoryview, int]] = []
    pos = 16
    while pos < len(data):
        magic = data[pos : pos + 12]
        begins_a_section = any(m.startswith(magic) for m in (LFC_MAGIC, LFM_MAGIC))
        if out and not begins_a_section:
            raise FileFormatError(
                f"{where}: {len(data) - pos} bytes after the last section (from byte {pos}) are no section; "
                "data appended to the file?"
            )
        if len(data) - pos < _SECTION_HEADER:
            raise FileFormatError(
                f"{where} is truncated: {len(data) - pos} bytes at byte {pos} are too few for a "
                f"{_SECTION_HEADER}-byte section header"
            )
        if magic not in (LFC_MAGIC, LFM_MAGIC):
            raise FileFormatError(f"{where}: the section at byte {pos} has magic {magic!r}, neither LFC nor LFM")
        size = int.from_bytes(data[pos + 12 : pos + 16], "big", signed=True)
        name = data[pos + 16 : pos + 61]
        if not _SHA1_NAME.fullmatch(name) or data[pos + 61 : pos + 96].strip(b"\0"):
            raise FileFormatError(f"{where}: the section at byte {pos} has no sha1 name ({name!r})")
        start = pos + _SECTION_HEADER
        if size < 0 or start + size > len(data):
            raise FileFormatError(
                f"{where} is truncated: the section at byte {pos} declares {size} bytes, {len(data) - start} remain"
            )
        body = view[start : start + size]
        actual = _sha1_name(body)
        if actual.encode("ascii") != name:
            raise FileFormatError(
                f"{where}: the section at byte {pos} is named {name.decode()} but its data is {actual}"
            )
        out.append((bytes(magic), name.decode("ascii"), body, pos))
        # Zeros pad a section to the next boundary (16 bytes in the files written here; any count is read).
        following = _NON_ZERO.search(data, start + size)
        pos = len(data) if following is None else following.start()
    return out


def _json_section(body: memoryview, what: str, where: str) -> dict:
    try:
        value = json.loads(bytes(body).decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
        raise FileFormatError(f"{where}: the {what} section is not JSON: {exc}") from None
    if not isinstance(value, dict):
        raise FileFormatError(f"{where}: the {what} section is not a JSON object")
    return value


def read_lfr(path: str | os.PathLike) -> LytroCapture:
    """Read an Illum LFR file: its mosaic, camera, metadata and thumbnail.

    Every section's SHA-1 is checked against its name. The camera is the ``lfrefractCamera``
    section's where the file has one, else :func:`camera_from_metadata`.

    Raises
    ------
    FileFormatError
        If the file is missing, not an LFP file (magic), truncated, a section's data does not match
        its SHA-1 name, the table of contents or metadata is missing or malformed, or the image
        section's size does not match the metadata's width, height and 10-bit packing; the message
        names the file.
    """
    path = Path(path)
    where = repr(str(path))
    sections = _sections(_read_bytes(path, "an LFR file"), where)
    tocs = [s for s in sections if s[0] == LFM_MAGIC]
    if len(tocs) != 1:
        raise FileFormatError(f"{where} has {len(tocs)} table-of-contents (LFM) sections, expected 1 (truncated?)")
    toc = _json_section(tocs[0][2], "table-of-contents", where)
    by_name = {name: body for magic, name, body, _ in sections if magic == LFC_MAGIC}
    try:
        frame = toc["frames"][0]["frame"]
        refs = {key: frame[key] for key in ("metadataRef", "privateMetadataRef", "imageRef")}
    except (KeyError, IndexError, TypeError):
        raise FileFormatError(f"{where}: the table of contents names no frame (frames[0].frame)") from None
    missing = [key for key, ref in refs.items() if not isinstance(ref, str) or ref not in by_name]
    if missing:
        raise FileFormatError(f"{where}: the table of contents names sections the file lacks: {missing}")
    metadata = _json_section(by_name[refs["metadataRef"]], "metadata", where)
    private = _json_section(by_name[refs["privateMetadataRef"]], "private metadata", where)
    bits = _integer(metadata, "image.pixelPacking.bitsPerPixel", where)
    endianness = _get(metadata, "image.pixelPacking.endianness", where)
    if bits != _ILLUM_BITS or endianness != "little":
        raise FileFormatError(f"{where}: pixel packing {bits} bits {endianness!r}; the Illum's is 10 bits 'little'")
    shape = (_integer(metadata, "image.height", where), _integer(metadata, "image.width", where))
    if shape[0] <= 0 or shape[1] <= 0:
        raise FileFormatError(f"{where}: image size {shape[1]} x {shape[0]} is empty")
    try:
        counts = unpack_10bit(by_name[refs["imageRef"]], shape)
    except FileFormatError as exc:
        raise FileFormatError(f"{where}: wrong image size: {exc}") from None
    _check_layout(metadata, "image", shape, bits, where)
    mosaic = _mosaic_from_metadata(counts, metadata, "image", bits, where)
    camera = camera_from_metadata(metadata, where=where)
    camera_ref = toc.get("lfrefract", {}).get("cameraRef") if isinstance(toc.get("lfrefract"), dict) else None
    if camera_ref is not None:
        if camera_ref not in by_name:
            raise FileFormatError(f"{where}: the table of contents names a camera section the file lacks")
        table = _json_section(by_name[camera_ref], "camera", where)
        try:
            camera = LightFieldCamera.from_dict(table["lfrefractCamera"])
        except (KeyError, ParameterError) as exc:
            raise FileFormatError(f"{where}: the lfrefractCamera section holds no camera: {exc}") from None
        sensor = (camera.sensor.width_px, camera.sensor.height_px)
        if sensor != (shape[1], shape[0]):
            raise FileFormatError(
                f"{where}: the lfrefractCamera section's sensor is {sensor[0]} x {sensor[1]} px but the image is "
                f"{shape[1]} x {shape[0]} px (metadata 'image.width', 'image.height'): the file contradicts itself"
            )
    thumbnail = b""
    thumbs = toc.get("thumbnails")
    if isinstance(thumbs, list) and thumbs and isinstance(thumbs[0], dict) and thumbs[0].get("imageRef") in by_name:
        thumbnail = bytes(by_name[thumbs[0]["imageRef"]])
    return LytroCapture(
        mosaic=mosaic, camera=camera, metadata=metadata, private_metadata=private, thumbnail_jpeg=thumbnail
    )


# =============================================================================== bare RAW files
def _metadata_path(raw_path: Path, suffix: str) -> Path:
    return raw_path.with_suffix(one_of("metadata_suffix", suffix, (".json", ".txt")))


def _write_raw_pair(raw_path: Path, packed: bytes, metadata: dict, suffix: str) -> tuple[Path, Path]:
    meta_path = _metadata_path(raw_path, suffix)
    if meta_path == raw_path:
        raise ParameterError(f"raw path {str(raw_path)!r} must not end in {suffix!r}, the metadata's suffix")
    with atomic_file(meta_path) as tmp:
        tmp.write_bytes(_json_bytes(metadata))
    with atomic_file(raw_path) as tmp:
        tmp.write_bytes(packed)
    return raw_path, meta_path


def write_f01_raw(
    path: str | os.PathLike,
    mosaic: RawMosaic,
    camera: LightFieldCamera,
    *,
    settings: LytroSettings | None = None,
    metadata_suffix: str = ".json",
) -> tuple[Path, Path]:
    """Write an F01 frame: the 12-bit packed ``.raw`` and its metadata JSON beside it, atomically each.

    Parameters
    ----------
    path : path-like
        The raw file (``.raw``); the metadata goes to the same stem with ``metadata_suffix``, where
        imageio's ``lytro-f01-raw`` reader and the F01 tools look for it.
    mosaic : RawMosaic
        12-bit digital numbers of the camera's sensor size (width even).
    camera : LightFieldCamera
        The camera whose geometry the metadata records (:func:`f01_metadata`).
    settings : LytroSettings, optional
        As for :func:`write_lfr` (the serial is ``A``-prefixed if it is not).
    metadata_suffix : {".json", ".txt"}
        The metadata file's suffix.

    Returns
    -------
    (pathlib.Path, pathlib.Path)
        The raw file and the metadata file; the metadata is written first.
    """
    metadata = f01_metadata(mosaic, camera, settings)
    return _write_raw_pair(Path(path), pack_12bit(mosaic.counts), metadata, metadata_suffix)


def write_illum_raw(
    path: str | os.PathLike,
    mosaic: RawMosaic,
    camera: LightFieldCamera,
    *,
    settings: LytroSettings | None = None,
    metadata_suffix: str = ".txt",
) -> tuple[Path, Path]:
    """Write an Illum frame as a bare 10-bit ``.raw`` with its metadata JSON beside it.

    This is how the Illum's factory white images are shipped (``.RAW`` with a ``.TXT`` of JSON);
    imageio's ``lytro-illum-raw`` reader reads it. Parameters as :func:`write_f01_raw`, the
    metadata as :func:`illum_metadata`.
    """
    metadata = illum_metadata(mosaic, camera, settings)
    return _write_raw_pair(Path(path), pack_10bit(mosaic.counts), metadata, metadata_suffix)


def _read_raw_pair(path: str | os.PathLike, metadata_suffix: str | None, what: str) -> tuple[Path, bytes, dict]:
    path = Path(path)
    if metadata_suffix is None:
        candidates = [_metadata_path(path, s) for s in (".json", ".txt")]
        found = [c for c in candidates if c.is_file()]
        if not found:
            raise FileFormatError(
                f"{str(path)!r} has no metadata beside it ({', '.join(repr(str(c)) for c in candidates)})"
            )
        meta_path = found[0]
    else:
        meta_path = _metadata_path(path, metadata_suffix)
    packed = _read_bytes(path, what)
    raw_meta = _read_bytes(meta_path, "a metadata file")
    metadata = _json_section(memoryview(raw_meta), "metadata", repr(str(meta_path)))
    return path, packed, metadata


def read_f01_raw(path: str | os.PathLike, *, metadata_suffix: str | None = None) -> LytroCapture:
    """Read an F01 frame written by :func:`write_f01_raw` (or lfpsplitter's frame and metadata).

    Parameters
    ----------
    path : path-like
        The ``.raw`` file.
    metadata_suffix : {".json", ".txt"} or None
        The metadata file's suffix; ``None``: ``.json`` if present, else ``.txt``.

    Raises
    ------
    FileFormatError
        If either file is missing or malformed, the packing is not 12-bit big-endian, or the raw
        file's size does not match the metadata's width and height; the message names the file.
    """
    path, packed, metadata = _read_raw_pair(path, metadata_suffix, "an F01 raw file")
    where = repr(str(path))
    bits = _integer(metadata, "image.rawDetails.pixelPacking.bitsPerPixel", where)
    endianness = _get(metadata, "image.rawDetails.pixelPacking.endianness", where)
    if bits != _F01_BITS or endianness != "big":
        raise FileFormatError(f"{where}: pixel packing {bits} bits {endianness!r}; the F01's is 12 bits 'big'")
    shape = (_integer(metadata, "image.height", where), _integer(metadata, "image.width", where))
    try:
        counts = unpack_12bit(packed, shape)
    except FileFormatError as exc:
        raise FileFormatError(f"{where}: wrong size: {exc}") from None
    _check_layout(metadata, "image.rawDetails", shape, bits, where)
    mosaic = _mosaic_from_metadata(counts, metadata, "image.rawDetails", bits, where)
    return LytroCapture(mosaic=mosaic, camera=camera_from_metadata(metadata, where=where), metadata=metadata)


def read_illum_raw(path: str | os.PathLike, *, metadata_suffix: str | None = None) -> LytroCapture:
    """Read an Illum frame written by :func:`write_illum_raw`. Errors as :func:`read_f01_raw`."""
    path, packed, metadata = _read_raw_pair(path, metadata_suffix, "an Illum raw file")
    where = repr(str(path))
    bits = _integer(metadata, "image.pixelPacking.bitsPerPixel", where)
    endianness = _get(metadata, "image.pixelPacking.endianness", where)
    if bits != _ILLUM_BITS or endianness != "little":
        raise FileFormatError(f"{where}: pixel packing {bits} bits {endianness!r}; the Illum's is 10 bits 'little'")
    shape = (_integer(metadata, "image.height", where), _integer(metadata, "image.width", where))
    try:
        counts = unpack_10bit(packed, shape)
    except FileFormatError as exc:
        raise FileFormatError(f"{where}: wrong size: {exc}") from None
    _check_layout(metadata, "image", shape, bits, where)
    mosaic = _mosaic_from_metadata(counts, metadata, "image", bits, where)
    return LytroCapture(mosaic=mosaic, camera=camera_from_metadata(metadata, where=where), metadata=metadata)
