"""A sensor's raw output: one integer digital number per pixel under a Bayer colour-filter array.

:class:`RawMosaic` is the one mosaic type of the project: the simulator's sensor model
(``simulator.detector``) produces it, the Lytro file writers and readers (:mod:`lfrefract.formats.lytro`)
store and return it, and ``mosaic.npz`` (:func:`write_mosaic_npz`, :func:`read_mosaic_npz`) holds it
beside a render.

Frames and units: ``counts[v, u]``, row ``v`` from the top, column ``u`` from the left, pixel centres
at integers (as in OpenCV); values are digital numbers (DN). A pattern names the colours of the
upper-left 2 x 2 tile read row by row: ``"GRBG"`` (the Illum's) is G R on row 0 and B G on row 1.
"""

from __future__ import annotations

import os
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from lfrefract.errors import FileFormatError, ParameterError
from lfrefract.formats.outputs import atomic_file
from lfrefract.validate import bounded_int, one_of, shown

__all__ = [
    "CFA_PATTERNS",
    "DEMOSAIC_METHODS",
    "MOSAIC_NPZ_KEYS",
    "RawMosaic",
    "cfa_channels",
    "demosaic",
    "demosaic_values",
    "read_mosaic_npz",
    "write_mosaic_npz",
]

#: Bayer tiles, named by their upper-left 2 x 2 block read row by row (Illum ``GRBG``, F01 ``BGGR``).
CFA_PATTERNS = ("GRBG", "RGGB", "GBRG", "BGGR")
#: Index of each colour letter in an RGB triple.
_CHANNEL = {"R": 0, "G": 1, "B": 2}
#: Demosaicing methods (OpenCV's bilinear and edge-aware interpolation).
DEMOSAIC_METHODS = ("bilinear", "edge_aware")
#: OpenCV's conversion code for each pattern (OpenCV's 4-letter names are the top-left 2 x 2 block
#: read row by row, as here; its 2-letter aliases name the second row's second and third pixels).
_CV_CODES = {
    "bilinear": {p: getattr(cv2, f"COLOR_Bayer{p}2RGB") for p in CFA_PATTERNS},
    "edge_aware": {p: getattr(cv2, f"COLOR_Bayer{p}2RGB_EA") for p in CFA_PATTERNS},
}
#: Arrays of a ``mosaic.npz`` file.
MOSAIC_NPZ_KEYS = ("counts", "cfa_pattern", "black_level_dn", "white_level_dn", "bit_depth")


def cfa_channels(pattern: str, shape: tuple[int, int]) -> np.ndarray:
    """Colour channel (0 R, 1 G, 2 B) of every pixel of a ``pattern`` mosaic.

    Parameters
    ----------
    pattern : str
        One of :data:`CFA_PATTERNS`.
    shape : (int, int)
        ``(H, W)``, pixels.

    Returns
    -------
    ndarray of int8, shape (H, W)
    """
    one_of("cfa_pattern", pattern, CFA_PATTERNS)
    tile = np.array([[_CHANNEL[pattern[0]], _CHANNEL[pattern[1]]], [_CHANNEL[pattern[2]], _CHANNEL[pattern[3]]]])
    h, w = shape
    return np.tile(tile, ((h + 1) // 2, (w + 1) // 2))[:h, :w].astype(np.int8)


@dataclass(frozen=True, eq=False, kw_only=True)
class RawMosaic:
    """A sensor's output: one digital number per pixel, under a colour-filter array.

    Parameters
    ----------
    counts : numpy.ndarray
        Digital numbers, shape (H, W) with H, W >= 2, any integer dtype with values in
        ``[0, 2**bit_depth - 1]``; stored as a read-only uint16 copy.
    cfa_pattern : str
        The colour-filter pattern, one of :data:`CFA_PATTERNS`.
    black_level_dn, white_level_dn : int
        The digital number of no light and of saturation,
        ``0 <= black_level_dn < white_level_dn <= 2**bit_depth - 1``.
    bit_depth : int
        Bits per pixel of the analogue-to-digital converter, 1 to 16 (Illum 10, F01 12).

    Raises
    ------
    ParameterError
        If ``counts`` is not a 2-D integer array of at least 2 x 2, a value is out of range, or a
        level or the pattern is impossible; the message names the parameter and its value.
    """

    counts: np.ndarray = field(repr=False)
    cfa_pattern: str
    black_level_dn: int
    white_level_dn: int
    bit_depth: int

    def __post_init__(self) -> None:
        bits = bounded_int("bit_depth", self.bit_depth, 1, 16)
        top = 2**bits - 1
        white = bounded_int("white_level_dn", self.white_level_dn, 1, top)
        black = bounded_int("black_level_dn", self.black_level_dn, 0, top)
        if black >= white:
            raise ParameterError(f"black_level_dn={black} must be below white_level_dn={white}")
        one_of("cfa_pattern", self.cfa_pattern, CFA_PATTERNS)
        counts = self.counts
        if not isinstance(counts, np.ndarray) or counts.ndim != 2 or not np.issubdtype(counts.dtype, np.integer):
            raise ParameterError(
                f"counts must be a 2-D integer array (H, W), got "
                f"{getattr(counts, 'dtype', type(counts).__name__)} of shape {getattr(counts, 'shape', None)}"
            )
        if min(counts.shape) < 2:
            raise ParameterError(f"counts must be at least 2 x 2 (one Bayer tile), got shape {counts.shape}")
        low, high = int(counts.min()), int(counts.max())
        if low < 0 or high > top:
            raise ParameterError(f"counts must lie in [0, {top}] for bit_depth={bits}, got values in [{low}, {high}]")
        stored = np.array(counts, dtype=np.uint16, order="C", copy=True)
        stored.setflags(write=False)
        object.__setattr__(self, "counts", stored)
        object.__setattr__(self, "bit_depth", bits)
        object.__setattr__(self, "black_level_dn", black)
        object.__setattr__(self, "white_level_dn", white)

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W), pixels."""
        return (int(self.counts.shape[0]), int(self.counts.shape[1]))

    @property
    def saturated(self) -> np.ndarray:
        """Pixels at or above the white level, bool (H, W)."""
        return self.counts >= self.white_level_dn

    def channel_index(self) -> np.ndarray:
        """Colour channel (0 R, 1 G, 2 B) of every pixel, int8 of shape (H, W)."""
        return cfa_channels(self.cfa_pattern, self.shape)

    def normalised(self) -> np.ndarray:
        """``(counts - black) / (white - black)``, float64 (H, W): 0 no light, 1 the white level."""
        return (self.counts.astype(np.float64) - self.black_level_dn) / (self.white_level_dn - self.black_level_dn)

    def full_scale(self) -> np.ndarray:
        """The counts over the converter's full scale ``2**bit_depth - 1``, float64 (H, W).

        This is what imageio's Lytro readers return (counts / 1023 for the Illum, / 4095 for the
        F01): the black level is not subtracted.
        """
        return np.divide(self.counts, float(2**self.bit_depth - 1)).astype(np.float64)


def demosaic(mosaic: RawMosaic, *, method: str = "bilinear") -> np.ndarray:
    """Linear camera RGB of every pixel from a Bayer mosaic (OpenCV's demosaicing).

    Parameters
    ----------
    mosaic : RawMosaic
    method : {"bilinear", "edge_aware"}
        OpenCV's bilinear interpolation or its edge-aware variant.

    Returns
    -------
    ndarray of float64, shape (H, W, 3)
        Camera R, G, B (the filters' channels, not colour-corrected), black subtracted and divided
        by ``white - black``: 0 no light, 1 the white level. The counts are shifted to 16 bits
        before OpenCV interpolates them, so its integer rounding costs at most
        ``2**(bit_depth - 17)`` DN.
    """
    if not isinstance(mosaic, RawMosaic):
        raise ParameterError(f"mosaic must be a RawMosaic, got {shown(mosaic)}")
    code = _CV_CODES[one_of("method", method, DEMOSAIC_METHODS)][mosaic.cfa_pattern]
    shift = 16 - mosaic.bit_depth
    rgb = cv2.cvtColor(np.ascontiguousarray(mosaic.counts << shift, dtype=np.uint16), code).astype(np.float64)
    return (rgb / 2**shift - mosaic.black_level_dn) / (mosaic.white_level_dn - mosaic.black_level_dn)


#: Levels of the 16-bit quantisation :func:`demosaic_values` hands OpenCV (whose Bayer conversions
#: take 8- or 16-bit integers only): values are rounded to 1 / 65535 of their largest.
_DEMOSAIC_LEVELS = 65535


def demosaic_values(values: np.ndarray, cfa_pattern: str, *, method: str = "bilinear") -> np.ndarray:
    """Camera RGB of every pixel from one linear value per pixel under ``cfa_pattern`` (e.g. a devignetted mosaic).

    Parameters
    ----------
    values : array_like, shape (H, W)
        Finite values >= 0, any linear scale.
    cfa_pattern : str
        One of :data:`CFA_PATTERNS`.
    method : {"bilinear", "edge_aware"}

    Returns
    -------
    ndarray of float64, shape (H, W, 3)
        On the scale of ``values``. OpenCV interpolates 16-bit integers: the values are quantised to
        1 / 65535 of their largest first (a relative error of at most 7.6e-6 of the largest).
    """
    image = np.asarray(values, dtype=np.float64)
    if image.ndim != 2 or min(image.shape) < 2:
        raise ParameterError(f"values must have shape (H, W) with H, W >= 2, got {image.shape}")
    if not np.all(np.isfinite(image)) or image.min() < 0.0:
        raise ParameterError("values must be finite and >= 0")
    code = _CV_CODES[one_of("method", method, DEMOSAIC_METHODS)][one_of("cfa_pattern", cfa_pattern, CFA_PATTERNS)]
    top = float(image.max())
    if top == 0.0:
        return np.zeros((*image.shape, 3))
    quantised = np.rint(image * (_DEMOSAIC_LEVELS / top)).astype(np.uint16)
    return cv2.cvtColor(quantised, code).astype(np.float64) * (top / _DEMOSAIC_LEVELS)


def write_mosaic_npz(path: str | os.PathLike, mosaic: RawMosaic) -> Path:
    """Write a mosaic as ``.npz`` (compressed), atomically.

    The file holds the arrays :data:`MOSAIC_NPZ_KEYS`: ``counts`` (H, W) uint16 and the scalars
    ``cfa_pattern`` (a string), ``black_level_dn``, ``white_level_dn`` and ``bit_depth``. numpy
    alone reads it (``numpy.load``); :func:`read_mosaic_npz` validates it back into a
    :class:`RawMosaic`.

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    if not isinstance(mosaic, RawMosaic):
        raise ParameterError(f"mosaic must be a RawMosaic, got {type(mosaic).__name__}")
    with atomic_file(path) as tmp, open(tmp, "wb") as handle:
        np.savez_compressed(
            handle,
            counts=mosaic.counts,
            cfa_pattern=np.array(mosaic.cfa_pattern),
            black_level_dn=np.array(mosaic.black_level_dn, dtype=np.int32),
            white_level_dn=np.array(mosaic.white_level_dn, dtype=np.int32),
            bit_depth=np.array(mosaic.bit_depth, dtype=np.int32),
        )
    return Path(path)


def read_mosaic_npz(path: str | os.PathLike) -> RawMosaic:
    """Read a mosaic written by :func:`write_mosaic_npz`.

    Raises
    ------
    FileFormatError
        If the file is missing, not an ``.npz``, lacks one of :data:`MOSAIC_NPZ_KEYS`, or holds values
        that are no mosaic; the message names the file.
    """
    where = repr(str(path))
    try:
        with np.load(path, allow_pickle=False) as data:
            missing = [key for key in MOSAIC_NPZ_KEYS if key not in data.files]
            if missing:
                raise FileFormatError(f"{where} is no mosaic file: it lacks {missing}")
            arrays = {key: data[key] for key in MOSAIC_NPZ_KEYS}
    except FileNotFoundError:
        raise FileFormatError(f"no such file: {where}") from None
    except (OSError, ValueError, zipfile.BadZipFile) as exc:
        raise FileFormatError(f"{where} is not a readable .npz file: {exc}") from None
    scalars = {}
    for key in ("black_level_dn", "white_level_dn", "bit_depth"):
        value = arrays[key]
        if value.shape != () or not np.issubdtype(value.dtype, np.integer):
            raise FileFormatError(f"{where}: {key} must be an integer scalar, got {value.dtype} of shape {value.shape}")
        scalars[key] = int(value)
    pattern = arrays["cfa_pattern"]
    if pattern.shape != () or pattern.dtype.kind != "U":
        raise FileFormatError(f"{where}: cfa_pattern must be a string, got {pattern.dtype} of shape {pattern.shape}")
    try:
        return RawMosaic(counts=arrays["counts"], cfa_pattern=str(pattern), **scalars)
    except ParameterError as exc:
        raise FileFormatError(f"{where}: {exc}") from None
