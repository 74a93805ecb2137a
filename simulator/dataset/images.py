"""A dataset sample's images in the dataset's file format: OpenEXR, numpy ``.npz`` or 16-bit PNG.

Every image a sample holds is written by :func:`write_image`, which returns its entry for
``sample.json`` (file, format, dtype, shape and, for PNG, how to decode it), and read back by
:func:`read_image` from that entry, so a loader needs no knowledge of the format.

- ``exr``: float32 OpenEXR (:func:`lfrefract.formats.exr.write_exr`, ZIP-compressed, with its role
  in the header). Integer images are stored as float32, exact up to 2**24; they read back as the
  recorded integer dtype.
- ``npz``: the array as it is (dtype and values exact), compressed (``numpy.savez_compressed``,
  one array named ``image``).
- ``png16``: 16-bit PNG (OpenCV; three channels in RGB order on disk as PNG has it), which image
  viewers and the OpenCV build without OpenEXR read. A float image is stored as
  ``code = round((value - offset) / scale)`` with ``offset`` its least finite value and ``scale``
  its finite range over :data:`PNG_DATA_CODES`, both recorded in the entry; reading gives
  ``offset + code * scale`` (float32), within half a ``scale`` of the value written. The codes
  above hold the non-finite values (:data:`PNG_SPECIAL_CODES`: NaN "no value", +inf "no surface").
  An integer image is stored as ``value - offset`` when its values span at most 65 536 codes; a
  wider one (the lenslet index of an Illum's 234 000 lenses) cannot be, and is written as ``.npz``,
  which its entry records.

No value: float images mark it with NaN in every format (see docs/conventions.md, "No value"),
integer label images with a value their entry's ``no_value`` names (-1 for a lenslet index, 0 for
an instance id, which is also "background").
"""

from __future__ import annotations

import io
import math
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import OpenEXR

from lfrefract.errors import FileFormatError, ParameterError
from lfrefract.formats.exr import read_exr, write_exr
from lfrefract.formats.outputs import atomic_file
from lfrefract.validate import one_of

__all__ = ["IMAGE_FORMATS", "PNG_DATA_CODES", "PNG_SPECIAL_CODES", "exr_entry", "read_image", "write_image"]

#: The formats of :func:`write_image`.
IMAGE_FORMATS = ("exr", "npz", "png16")
#: File suffix of each format.
SUFFIXES = {"exr": ".exr", "npz": ".npz", "png16": ".png"}
#: Codes 0 .. PNG_DATA_CODES - 1 of a 16-bit PNG float image hold values; the ones above, these.
PNG_SPECIAL_CODES = {"nan": 65535, "+inf": 65534, "-inf": 65533}
PNG_DATA_CODES = 65533
_SPECIAL_VALUES = {"nan": math.nan, "+inf": math.inf, "-inf": -math.inf}
#: Integers spanned by a 16-bit PNG integer image at most.
_PNG_INTEGER_SPAN = 65536


def _checked(image: Any, stem: str) -> np.ndarray:
    arr = np.asarray(image)
    is_real = np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)
    if not is_real or np.issubdtype(arr.dtype, np.bool_):
        raise ParameterError(f"image {stem!r} must hold real numbers (float or integer), got dtype {arr.dtype}")
    if not (arr.ndim == 2 or (arr.ndim == 3 and arr.shape[2] == 3)):
        raise ParameterError(f"image {stem!r} must have shape (H, W) or (H, W, 3), got {arr.shape}")
    if np.issubdtype(arr.dtype, np.integer) and arr.size and np.max(np.abs(arr.astype(np.int64))) >= 2**24:
        raise ParameterError(f"integer image {stem!r} holds values beyond +-2**24, which float32 cannot hold exactly")
    return arr


def write_image(
    folder: str | Path, stem: str, image: Any, *, image_format: str, role: str, no_value: Any = None
) -> dict:
    """Write ``image`` as ``folder / (stem + suffix)`` in ``image_format``; return its entry.

    Parameters
    ----------
    folder : path-like
        The sample's (staging) folder.
    stem : str
        File name without suffix (``"depth"``, ``"normal_cam"``).
    image : ndarray, shape (H, W) or (H, W, 3)
        Float or integer values (bool: convert to an integer first).
    image_format : {"exr", "npz", "png16"}
    role : str
        What the image is (stored in an EXR's header and in the entry).
    no_value : int, optional
        For an integer image: the value that means "no value" (recorded in the entry).

    Returns
    -------
    dict
        ``{"file", "format", "role", "dtype", "shape"}``, with ``offset`` and ``scale`` (PNG),
        ``codes`` (PNG float images) and ``no_value`` (when given).
    """
    one_of("image_format", image_format, IMAGE_FORMATS)
    arr = _checked(image, stem)
    integer = bool(np.issubdtype(arr.dtype, np.integer))
    entry: dict[str, Any] = {"role": role, "dtype": arr.dtype.name, "shape": list(arr.shape)}
    if no_value is not None:
        entry["no_value"] = int(no_value)
    fmt = image_format
    if fmt == "png16" and integer and arr.size and int(arr.max()) - int(arr.min()) >= _PNG_INTEGER_SPAN:
        fmt = "npz"  # documented: a 16-bit PNG cannot hold it
        entry["png16_too_wide"] = [int(arr.min()), int(arr.max())]
    path = Path(folder) / (stem + SUFFIXES[fmt])
    entry |= {"file": path.name, "format": fmt}
    if fmt == "exr":
        write_exr(path, arr.astype(np.float32), role=role)
    elif fmt == "npz":
        buffer = io.BytesIO()
        np.savez_compressed(buffer, image=arr)
        with atomic_file(path) as tmp:
            tmp.write_bytes(buffer.getvalue())
    else:
        codes = _png_codes(arr, entry)
        bgr = codes[..., ::-1] if codes.ndim == 3 else codes
        ok, encoded = cv2.imencode(".png", np.ascontiguousarray(bgr))
        if not ok:
            raise FileFormatError(f"OpenCV could not encode {stem!r} as a 16-bit PNG")
        with atomic_file(path) as tmp:
            tmp.write_bytes(encoded.tobytes())
    return entry


def _png_codes(arr: np.ndarray, entry: dict) -> np.ndarray:
    """The uint16 codes of ``arr``; records ``offset``, ``scale`` and ``codes`` in ``entry``."""
    if np.issubdtype(arr.dtype, np.integer):
        offset = int(arr.min()) if arr.size else 0
        entry |= {"offset": offset, "scale": 1}
        return (arr.astype(np.int64) - offset).astype(np.uint16)
    values = arr.astype(np.float64)
    finite = np.isfinite(values)
    lo = float(values[finite].min()) if finite.any() else 0.0
    hi = float(values[finite].max()) if finite.any() else 0.0
    scale = (hi - lo) / (PNG_DATA_CODES - 1) if hi > lo else 1.0
    codes = np.zeros(arr.shape, dtype=np.uint16)
    codes[finite] = np.round((values[finite] - lo) / scale).astype(np.uint16)
    for name, code in PNG_SPECIAL_CODES.items():
        special = np.isnan(values) if name == "nan" else values == _SPECIAL_VALUES[name]
        codes[special] = code
    entry |= {"offset": lo, "scale": scale, "codes": dict(PNG_SPECIAL_CODES)}
    return codes


def exr_entry(path: str | Path, *, role: str) -> dict:
    """The entry of an OpenEXR image already written (by ``lfsim render``), from its header alone.

    Raises
    ------
    FileFormatError
        If it is not a readable single-channel or RGB OpenEXR file.
    """
    path = Path(path)
    try:
        with OpenEXR.File(str(path), header_only=True) as exr:
            header = exr.header()
            (x0, y0), (x1, y1) = (tuple(int(v) for v in corner) for corner in header["dataWindow"])
            names = sorted(channel.name for channel in header["channels"])
    except (RuntimeError, ValueError, OSError, KeyError) as exc:
        raise FileFormatError(f"{str(path)!r} is not a readable OpenEXR file: {exc}") from None
    if names not in (["B", "G", "R"], ["Y"]):
        raise FileFormatError(f"{str(path)!r} has channels {names}; expected RGB or a single Y channel")
    shape = [y1 - y0 + 1, x1 - x0 + 1] + ([3] if len(names) == 3 else [])
    return {"role": role, "dtype": "float32", "shape": shape, "file": path.name, "format": "exr"}


def read_image(folder: str | Path, entry: dict) -> np.ndarray:
    """Read an image written by :func:`write_image` from its ``entry``.

    Returns
    -------
    ndarray, shape and dtype of the entry
        (float images: float32; a PNG float image decoded within half its ``scale``).

    Raises
    ------
    FileFormatError
        If the file is missing or does not hold what the entry says.
    """
    try:
        path = Path(folder) / entry["file"]
        fmt, dtype, shape = entry["format"], np.dtype(entry["dtype"]), tuple(entry["shape"])
    except (KeyError, TypeError) as exc:
        raise FileFormatError(f"image entry {entry!r} in {str(folder)!r} lacks {exc}") from None
    if not path.is_file():
        raise FileFormatError(f"no such file: {str(path)!r}")
    if fmt == "exr":
        image = read_exr(path, role=entry.get("role"))
        image = image.astype(dtype) if np.issubdtype(dtype, np.integer) else image
    elif fmt == "npz":
        try:
            with np.load(path, allow_pickle=False) as npz:
                image = npz["image"]
        except (OSError, ValueError, KeyError) as exc:
            raise FileFormatError(f"{str(path)!r} is not an image .npz of this format: {exc}") from None
    elif fmt == "png16":
        codes = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if codes is None or codes.dtype != np.uint16:
            raise FileFormatError(f"{str(path)!r} is not a 16-bit PNG")
        codes = codes[..., ::-1] if codes.ndim == 3 else codes
        if np.issubdtype(dtype, np.integer):
            image = (codes.astype(np.int64) + int(entry["offset"])).astype(dtype)
        else:
            image = (float(entry["offset"]) + codes.astype(np.float64) * float(entry["scale"])).astype(np.float32)
            for name, code in entry["codes"].items():
                image[codes == code] = _SPECIAL_VALUES[name]
    else:
        raise FileFormatError(f"{str(path)!r}: unknown image format {fmt!r}; one of {list(IMAGE_FORMATS)}")
    if image.shape != shape:
        raise FileFormatError(f"{str(path)!r} holds an image of shape {image.shape}, its entry says {list(shape)}")
    return image
