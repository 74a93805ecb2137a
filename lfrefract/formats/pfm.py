"""Portable Float Map (PFM) images: the format of the HCI 4D light field benchmark's disparity maps.

A PFM file is a three-line ASCII header followed by the raw samples:

* ``Pf`` (one channel) or ``PF`` (three channels, R, G, B interleaved per pixel);
* ``W H``, the width and height in pixels;
* the scale: its sign gives the byte order of the samples (negative: little-endian, positive:
  big-endian);

each line followed by one whitespace character (a newline here), then ``W * H * channels`` float32
samples, row by row, **the bottom row first**. The arrays in memory follow the project's convention
(``image[v, u]``, row 0 at the top), so the rows are flipped on writing and reading.

:func:`write_pfm` writes float32, little-endian, with scale ``-1``, as the HCI benchmark's
evaluation toolkit does (``gt_disp_lowres.pfm``, its algorithms' ``disp_maps/*.pfm``). NaN and
+-inf are stored as they are: a disparity map may mark pixels without a value with them.

The magnitude of the scale has no agreed meaning (the toolkit's reader multiplies the samples by
it, OpenCV's divides them by it), so :func:`read_pfm` reads only files whose scale is +1 or -1 and
refuses any other rather than guessing.
"""

from __future__ import annotations

import math
import os
import re
from pathlib import Path

import numpy as np

from lfrefract.errors import FileFormatError, ParameterError
from lfrefract.formats.outputs import atomic_file
from lfrefract.validate import file_problem

__all__ = ["read_pfm", "write_pfm"]

# The header: identifier, width and height, scale, then exactly one whitespace byte before the
# samples (which may themselves begin with bytes that look like whitespace).
_HEADER = re.compile(rb"\A(P[Ff])\s+(\S+)[ \t]+(\S+)\s+(\S+)\s")
# Longest header accepted: identifier, two dimensions and a scale of any sensible spelling.
_MAX_HEADER_BYTES = 256


def write_pfm(path: str | os.PathLike, image: np.ndarray) -> Path:
    """Write a float image as a little-endian float32 PFM file, atomically.

    The file is written to a temporary name beside ``path`` and renamed into place, so ``path``
    never holds a partial file.

    Parameters
    ----------
    path : path-like
        Destination ``.pfm`` file (its directory is created if needed; an existing file is replaced).
    image : ndarray, shape (H, W) or (H, W, 3)
        Real-valued image, row 0 at the top, H, W >= 1. A single channel is written as a greyscale
        ``Pf`` file, three as a colour ``PF`` file (channels in R, G, B order). Values are stored
        as float32 in the image's own units (pixels of disparity for the benchmark's maps); NaN
        and +-inf are kept (a disparity map may mark "no value" with them).

    Returns
    -------
    Path
        The written path.

    Raises
    ------
    ParameterError
        If ``image`` is not a real-valued (floating-point or integer) array of shape (H, W) or
        (H, W, 3) with H, W >= 1, or holds finite values beyond float32's range (they would turn
        into infinities).
    """
    path = Path(path)
    arr = np.asarray(image)
    if arr.dtype == np.bool_ or not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
        raise ParameterError(f"image must hold real numbers (floating point or integer), got dtype {arr.dtype}")
    if arr.ndim == 2:
        identifier = b"Pf"
    elif arr.ndim == 3 and arr.shape[2] == 3:
        identifier = b"PF"
    else:
        raise ParameterError(f"image must have shape (H, W) or (H, W, 3), got {arr.shape}")
    height, width = arr.shape[:2]
    if height < 1 or width < 1:
        raise ParameterError(f"image must have at least one row and one column, got shape {arr.shape}")
    finite = arr[np.isfinite(arr)]
    if finite.size and np.max(np.abs(finite)) > np.finfo(np.float32).max:
        raise ParameterError(
            f"image holds finite values beyond float32's range, e.g. {float(np.max(np.abs(finite)))!r}"
        )
    samples = np.ascontiguousarray(arr[::-1], dtype="<f4")  # bottom row first
    header = identifier + b"\n" + f"{width} {height}\n-1\n".encode("ascii")
    with atomic_file(path) as tmp, tmp.open("wb") as fh:
        fh.write(header)
        fh.write(samples.tobytes())
    return path


def read_pfm(path: str | os.PathLike) -> np.ndarray:
    """Read a PFM image (greyscale ``Pf`` or colour ``PF``, either byte order).

    Parameters
    ----------
    path : path-like
        A PFM file whose scale is -1 (little-endian samples) or +1 (big-endian samples).

    Returns
    -------
    ndarray, float32, shape (H, W) or (H, W, 3)
        The samples as stored, in native byte order, row 0 at the top (the file's last row);
        colour channels in R, G, B order. NaN and +-inf are returned as they are.

    Raises
    ------
    FileFormatError
        If the file is missing or not a regular file, does not start with a PFM header (identifier
        ``PF`` or ``Pf``, positive integer width and height, a finite non-zero scale), has a scale
        of magnitude other than 1, or holds more or fewer bytes of samples than its header says;
        the message names the file.
    """
    path = Path(path)
    name = str(path)
    if (problem := file_problem(path)) is not None:
        raise FileFormatError(problem)
    try:
        with path.open("rb") as fh:
            head = fh.read(_MAX_HEADER_BYTES)
            match = _HEADER.match(head)
            if match is None:
                raise FileFormatError(_header_problem(name, head))
            identifier, width_text, height_text, scale_text = match.groups()
            width = _dimension(name, "width", width_text)
            height = _dimension(name, "height", height_text)
            scale = _scale(name, scale_text)
            channels = 3 if identifier == b"PF" else 1
            expected = width * height * channels * 4
            stored = os.fstat(fh.fileno()).st_size - match.end()
            if stored != expected:
                kind = "colour" if channels == 3 else "greyscale"
                raise FileFormatError(
                    f"{name!r} holds {stored} bytes of samples, but its header describes a {width} x {height} "
                    f"{kind} PFM of {expected} bytes ({'truncated' if stored < expected else 'trailing data'})"
                )
            fh.seek(match.end())
            body = fh.read(expected)
    except OSError as exc:
        raise FileFormatError(f"{name!r} cannot be read: {exc.strerror or exc}") from None
    if len(body) != expected:  # the file changed while it was read
        raise FileFormatError(f"{name!r} holds {len(body)} bytes of samples, expected {expected}")
    order = "<" if scale < 0 else ">"
    shape = (height, width, 3) if channels == 3 else (height, width)
    samples = np.frombuffer(body, dtype=f"{order}f4").reshape(shape)
    return np.array(samples[::-1], dtype=np.float32, order="C")  # a writable copy, native order


def _header_problem(name: str, head: bytes) -> str:
    """Why ``head`` is not the start of a PFM header, for the error message."""
    if not head:
        return f"{name!r} is empty, not a PFM file"
    if not head.startswith((b"PF", b"Pf")) or (len(head) > 2 and not head[2:3].isspace()):
        return f"{name!r} is not a PFM file (it starts with {head[:8]!r}, not 'PF' or 'Pf')"
    return (
        f"{name!r} has an incomplete or malformed PFM header {head[:40]!r}: expected the identifier, "
        "'WIDTH HEIGHT' and the scale, each followed by a newline"
    )


def _dimension(name: str, what: str, text: bytes) -> int:
    if not text.isdigit() or len(text) > 9 or int(text) < 1:
        raise FileFormatError(f"{name!r}: the PFM {what} must be a positive integer, got {text[:20]!r}")
    return int(text)


def _scale(name: str, text: bytes) -> float:
    try:
        scale = float(text.decode("ascii"))
    except (UnicodeDecodeError, ValueError):
        raise FileFormatError(f"{name!r}: the PFM scale must be a number, got {text[:20]!r}") from None
    if not math.isfinite(scale) or scale == 0.0:
        raise FileFormatError(f"{name!r}: the PFM scale must be a finite non-zero number, got {text[:20]!r}")
    if abs(scale) != 1.0:
        raise FileFormatError(
            f"{name!r} has PFM scale {scale!r}; only +1 and -1 are read (readers disagree on what "
            "another magnitude means: some multiply the samples by it, others divide)"
        )
    return scale
