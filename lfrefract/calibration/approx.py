"""The approximation baseline: a pinhole plus lens distortion fitted at one depth (paper section 3.1).

Ferreira et al. (2005) and the approaches after them treat a camera behind a flat port as an
ordinary pinhole camera whose lens happens to be distorted: chessboard views taken through the
port, at about one distance, are calibrated with the usual model (OpenCV's ``K`` with
``fx, fy, cx, cy`` and radial-tangential distortion ``k1, k2, p1, p2, k3``), and later images are
undistorted with it. Refraction is not a lens distortion: the lines of sight in the water do not
meet in one point, and the virtual focal length depends on the depth, so the model is right only
near the calibration depth, and worse the more the port is tilted (paper section 3.1).

Here the conventional image of a light-field camera is its central sub-aperture view (see
:func:`lfrefract.methods.conventional_image`), but nothing in this module knows about light
fields: :func:`calibrate_approx` calibrates any set of images of a chessboard, and
:class:`ApproxCalibration` undistorts images onto a chosen pinhole ``K``
(``cv2.initUndistortRectifyMap`` and ``cv2.remap``).

The fit determines the model's frame only as well as the views do: boards at one distance and a
narrow field of view let the focal length trade off against the board distances, and the
principal point against a rotation of every board pose; a tilted port deflects the whole field,
which the fit puts into the poses (``docs/calibration.md``: from 6 views at 0.2 m the focal
length came out 318-531 px between render seeds where 315-387 px fit). Undistorted images then
come out in the fit's own frame, which is what the method gives a user (a later stereo
calibration absorbs it). Where the boards' corners are known in the real camera's frame
(``corners_cam``: a simulator's ground truth, or a surveyed rig), the model is instead fitted with
the camera's pose, as the approximation claims it: a pinhole at the camera centre, turned by a
rotation (the port's mean deflection), with its own ``K`` and distortion, fitted to the known 3D
corners by nonlinear least squares (scipy) from the OpenCV result. That removes the calibration's
ambiguities from comparisons, leaving the approximation's own error: small at the calibration
depth, growing away from it.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from scipy import ndimage
from scipy.optimize import least_squares

from lfrefract.calibration.distinct import require_distinct_corners, view_names
from lfrefract.errors import CalibrationError, ParameterError
from lfrefract.formats.jsonio import read_json, write_json
from lfrefract.optics.pinhole import PinholeCamera
from lfrefract.validate import as_points, finite_float, positive_float, positive_int, reject_unknown_keys, require_keys

__all__ = [
    "DISTORTION_MODEL",
    "MIN_PATTERN_SIDE",
    "MIN_PX_PER_SQUARE",
    "PART_MIN_CORNERS",
    "ApproxCalibration",
    "BoardLattice",
    "calibrate_approx",
    "detect_board_lattice",
    "detect_chessboard",
    "lattice_points_m",
]

#: Fewest pixels a chessboard square spans in an image where :func:`detect_chessboard` can find it
#: (OpenCV's detector needs a few pixels of each square around every corner): a board of more
#: squares than the image holds at this size is no board the commands could locate.
MIN_PX_PER_SQUARE = 3

#: Fewest inner corners per side of a pattern OpenCV's sector-based detector looks for.
MIN_PATTERN_SIDE = 3

#: Names of the distortion coefficients, in OpenCV's order.
DISTORTION_MODEL = ("k1", "k2", "p1", "p2", "k3")

#: Names of :attr:`ApproxCalibration.intrinsic_std`, in order.
INTRINSIC_NAMES = ("fx", "fy", "cx", "cy", *DISTORTION_MODEL)

#: The largest relative standard deviation of ``fx`` and ``fy`` accepted: beyond, the views do not
#: determine the focal length (it trades off against the boards' distances) and the calibration is an
#: error. Measured: six rendered views behind a tilted port 10 % (fx 319 +- 31 px), three of them 18 %;
#: one frontal board moved across the image 65 % (fx 228 +- 148 px for 300).
MAX_FOCAL_STD_RELATIVE = 0.25

#: The ``kind`` entry of :meth:`ApproxCalibration.to_dict`.
KIND = "approx_calibration"

_KEYS = frozenset(
    {
        "kind",
        "K",
        "dist_coeffs",
        "distortion_model",
        "image_size",
        "pattern",
        "square_size_m",
        "depth_m",
        "view_depths_m",
        "rms_px",
        "view_rms_px",
        "intrinsic_std",
        "fixed_intrinsics",
        "rotation",
        "known_corners",
    }
)


def _pattern(pattern: Any) -> tuple[int, int]:
    try:
        items = tuple(pattern)
    except TypeError:
        raise ParameterError(f"pattern must be (columns, rows) of inner corners, got {pattern!r}") from None
    if len(items) != 2:
        raise ParameterError(f"pattern must be (columns, rows) of inner corners, got {pattern!r}")
    cols, rows = (positive_int(f"pattern[{i}]", n) for i, n in enumerate(items))
    if cols < MIN_PATTERN_SIDE or rows < MIN_PATTERN_SIDE:
        raise ParameterError(
            f"pattern must have at least {MIN_PATTERN_SIDE} inner corners per side (OpenCV's detector finds no "
            f"fewer), got {pattern!r}"
        )
    return cols, rows


#: The board squares accepted, metres (smallest, largest): a tenth of a millimetre to a metre. Beyond,
#: the value is a unit mistake (millimetres given as metres), not a board.
SQUARE_SIZE_RANGE_M = (1e-4, 1.0)


def square_size(name: str, value: object) -> float:
    """``value`` as a board square's edge in metres, within :data:`SQUARE_SIZE_RANGE_M`.

    Raises
    ------
    ParameterError
        Naming ``name`` and the value, if it is not a number in that range.
    """
    lo, hi = SQUARE_SIZE_RANGE_M
    try:
        size = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ParameterError(f"{name} must be a board square's edge in metres, got {value!r}") from None
    if not lo <= size <= hi:
        raise ParameterError(
            f"{name} must be a board square's edge in metres, between {lo:g} and {hi:g} m, got {value!r} "
            "(a size in millimetres given as metres?)"
        )
    return size


def _as_image(name: str, image: object) -> np.ndarray:
    arr = np.asarray(image)
    if arr.ndim not in (2, 3) or arr.shape[0] < 2 or arr.shape[1] < 2:
        raise ParameterError(f"{name} must be an (H, W) or (H, W, C) image, got shape {arr.shape}")
    if not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
        raise ParameterError(f"{name} must be a real image, got dtype {arr.dtype}")
    return arr


#: Percentiles of an image's values that the detector's 8-bit image is scaled to, tried in turn. The
#: 99th keeps a few bright outliers (a highlight, a hot pixel) from darkening the board; a board
#: whose white covers under about 1 % of the image (a small board far off in an Illum's 1078 x 748 px
#: view: 0.9 %) is clipped there, its blurred black squares shrunk to dots the detector does not
#: find, and is found at the 99.9th. The scale serves only to find the board: the corners are
#: refined on the unclipped image (clipped, a board's white biased them by 2-3 px at Illum size).
WHITE_PERCENTILES = (99.0, 99.9)


def _grey(name: str, image: np.ndarray) -> np.ndarray:
    """Channel mean, NaN as black, divided by its maximum: float64 (H, W), at most 1."""
    grey = image.astype(np.float64)
    if grey.ndim == 3:
        grey = grey.mean(axis=2)
    finite = np.isfinite(grey)
    if not finite.any():
        raise ParameterError(f"{name} has no finite pixel")
    grey = np.where(finite, grey, 0.0)
    top = float(grey.max())
    if not top > 0.0:
        raise ParameterError(f"{name} is blank (its largest value is {top!r})")
    return grey / top


def _gray8(grey: np.ndarray, *, percentile: float) -> np.ndarray | None:
    """8-bit image for the detector: ``grey`` (from :func:`_grey`) scaled to ``percentile`` and clipped.

    None if that percentile is 0: not a blank image (:func:`_grey` refuses those) but a board on an
    exactly black background (NaN, no data) covering less of the image than the percentile leaves,
    which the next, higher percentile scales.
    """
    white = float(np.percentile(grey, percentile))
    if not white > 0.0:
        return None
    return (np.clip(grey / white, 0.0, 1.0) * 255).astype(np.uint8)


def detect_chessboard(
    image: np.ndarray, pattern: tuple[int, int], *, refine_half_window_px: int = 3, name: str = "image"
) -> np.ndarray | None:
    """Find a chessboard's inner corners in an image.

    OpenCV's sector-based detector (``findChessboardCornersSB``, exhaustive, accurate) refined on
    the saddle point by ``cornerSubPix``: the detector's own estimate leans towards the board's
    edge on blurred images (0.2 px RMS on refraction-free images of 9 px squares). The detector
    sees the image scaled to 8 bits at its 99th percentile, and if it finds no board there at its
    99.9th (:data:`WHITE_PERCENTILES`: a board covering under 1 % of the image; a percentile that
    is 0, a small board on an exactly black background, is skipped); the refinement sees the linear
    image, unclipped. OpenCV also reports a pattern smaller than the board, often with its corners
    in a scrambled order: the corners found must be X-junctions where their lattice puts them, and
    the lattice must not go on beyond its edges (:func:`_lattice_check`); a board with more squares
    than the pattern is an error naming them. OpenCV's random generator is seeded for each search,
    so that one image gives one answer.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
        Linear radiance (any scale; colour is averaged). NaN (no data) counts as black.
    pattern : (int, int)
        Inner corners per row and per column (OpenCV's ``patternSize``): a board of
        ``c x r`` squares has pattern ``(c - 1, r - 1)``.
    refine_half_window_px : int
        Half-size of the ``cornerSubPix`` search window, pixels; keep it below a square's size.
    name : str
        How errors name the image.

    Returns
    -------
    ndarray, float64, shape (columns * rows, 2), or None
        Corner pixels ``(u, v)`` (OpenCV convention: pixel centres at integers), row by row with
        u fastest in the detector's order (which may be the reverse of the board's own order on a
        board that looks the same after a half turn); None if no board of the pattern was found.

    Raises
    ------
    ParameterError
        If the image has no finite pixel or is blank (its largest value is 0), an argument is
        invalid, or the image shows a chessboard with more squares than ``pattern`` (named with them).
    """
    cols, rows = _pattern(pattern)
    half = positive_int("refine_half_window_px", refine_half_window_px)
    grey = _grey(name, _as_image(name, image))
    corners = _find_chessboard(grey, (cols, rows))
    if corners is None:
        # The usual mistake: inner corners given as squares, a pattern one short each way. OpenCV
        # finds no pattern on such a board or a scrambled one (below): look for the board's own.
        _refuse_larger_board(grey, (cols, rows), name, candidates=[(cols + 1, rows + 1)])
        return None
    found = _sub_pixel(grey, corners.reshape(-1, 2), half)
    lattice, continues = _lattice_check(grey, found, (cols, rows))
    if lattice and not continues:
        return found
    # A board with more squares than the pattern: OpenCV reports a smaller pattern on it anyway, in
    # a scrambled order (its corners are no lattice) or as a part of the board.
    _refuse_larger_board(grey, (cols, rows), name)
    if continues:
        raise ParameterError(
            f"{name}: the chessboard continues beyond the {cols} x {rows} inner corners of pattern {(cols, rows)!r} "
            f"({cols + 1} x {rows + 1} squares): it has more squares, or lies partly outside the image; give the "
            "board's own squares (--squares) and captures that show all of it"
        )
    return None  # what OpenCV found is not the pattern's lattice of corners


#: The least share of a detected pattern's corners that must be X-junctions where their lattice puts
#: them (:func:`_x_junctions`): every one on the rendered boards (a board's true pattern); 0.67-0.73 on
#: patterns smaller than the board, whose corners OpenCV reports in a scrambled order.
LATTICE_MIN_FRACTION = 0.9
#: The least share of the lattice's next row (or column) beyond an edge that must be X-junctions for
#: the board to continue there: a whole line of corners, not a chance texture.
CONTINUES_MIN_FRACTION = 0.75
#: An X-junction's least score (:func:`_x_junctions`: 1 for an ideal chessboard corner): 0.92-1.0 at
#: the corners of the rendered boards; 0.4-0.7 where OpenCV put a corner half a square off.
X_JUNCTION_MIN_SCORE = 0.75
#: An X-junction's least contrast (the spread of its four squares' values) as a share of the median
#: over the detected corners: flat or noisy surroundings are no junction.
X_JUNCTION_MIN_CONTRAST = 0.3
#: Inner corners tried beyond the pattern's, per side, when the board looks larger than the pattern.
LARGER_PATTERN_SEARCH = 4


def _x_junctions(
    grey: np.ndarray, points: np.ndarray, along_row: np.ndarray, along_col: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Junction scores (...,) of ``points`` (..., 2) with lattice steps ``along_row``, ``along_col``
    (..., 2) in pixels: the four squares' values, sampled at their centres, split into two diagonal
    pairs, and the gap between the pairs over the spread of all four (1 for an ideal chessboard
    corner; below 0 for an L-junction, a board's edge or a square's middle); and the spread."""
    half = 0.5 * (along_row + along_col), 0.5 * (along_row - along_col)
    centres = np.stack([points + half[0], points - half[0], points + half[1], points - half[1]], axis=-2)
    values = ndimage.map_coordinates(grey, [centres[..., 1], centres[..., 0]], order=1, mode="nearest")
    a, b = values[..., :2], values[..., 2:]
    gap = np.maximum(a.min(axis=-1) - b.max(axis=-1), b.min(axis=-1) - a.max(axis=-1))
    spread = values.max(axis=-1) - values.min(axis=-1)
    return gap / np.maximum(spread, np.finfo(float).tiny), spread


def _junctions(score: np.ndarray, spread: np.ndarray, contrast: float) -> np.ndarray:
    """Which points are X-junctions: score (:func:`_x_junctions`) above :data:`X_JUNCTION_MIN_SCORE`
    and their squares' spread above ``contrast``."""
    return (score > X_JUNCTION_MIN_SCORE) & (spread > contrast)


def _lattice_check(grey: np.ndarray, corners: np.ndarray, pattern: tuple[int, int]) -> tuple[bool, bool]:
    """Whether detected ``corners`` (row by row) are chessboard corners at their lattice places, and
    whether the lattice continues beyond one of its edges (a whole row or column of corners more)."""
    cols, rows = pattern
    grid = corners.reshape(rows, cols, 2)
    along_row, along_col = np.gradient(grid, axis=1), np.gradient(grid, axis=0)
    score, spread = _x_junctions(grey, grid, along_row, along_col)
    contrast = X_JUNCTION_MIN_CONTRAST * float(np.median(spread))
    junction = _junctions(score, spread, contrast)
    lattice = float(np.mean(junction)) >= LATTICE_MIN_FRACTION
    continues = False
    # The next line beyond each edge, extrapolated, with the edge's steps.
    for line, step_out, row_step, col_step in (
        (grid[:, 0], grid[:, 0] - grid[:, 1], along_row[:, 0], along_col[:, 0]),
        (grid[:, -1], grid[:, -1] - grid[:, -2], along_row[:, -1], along_col[:, -1]),
        (grid[0], grid[0] - grid[1], along_row[0], along_col[0]),
        (grid[-1], grid[-1] - grid[-2], along_row[-1], along_col[-1]),
    ):
        score, spread = _x_junctions(grey, line + step_out, row_step, col_step)
        continues |= float(np.mean(_junctions(score, spread, contrast))) >= CONTINUES_MIN_FRACTION
    return lattice, continues


def _detector_images(grey: np.ndarray) -> Iterator[np.ndarray]:
    """``grey`` (:func:`_grey`) as the 8-bit images OpenCV's detector is given: scaled to each of
    :data:`WHITE_PERCENTILES` in turn (one black at a percentile, a small board on a black
    background, skipped), OpenCV's random generator seeded before each."""
    for percentile in WHITE_PERCENTILES:
        gray8 = _gray8(grey, percentile=percentile)
        if gray8 is None:
            continue  # black at this percentile: the board is small on a black background
        # The exhaustive search draws from OpenCV's random generator: unseeded, a pattern smaller
        # than the board was found in 3 of 8 calls on one image. Seeded, one image gives one answer.
        cv2.setRNGSeed(0)
        yield gray8


_DETECTOR_FLAGS = cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY


def _find_chessboard(grey: np.ndarray, pattern: tuple[int, int]) -> np.ndarray | None:
    """OpenCV's corners (N, 1, 2) of ``pattern`` in ``grey`` (:func:`_grey`), unrefined; None if not
    found in any of :func:`_detector_images`."""
    for gray8 in _detector_images(grey):
        found, corners = cv2.findChessboardCornersSB(gray8, pattern, flags=_DETECTOR_FLAGS)
        if found:
            return corners
    return None


def _find_lattice(grey: np.ndarray) -> tuple[np.ndarray, tuple[int, int]] | None:
    """OpenCV's largest lattice of chessboard corners in ``grey`` (at least 3 x 3, as far as squares
    are seen): its corners (N, 2), unrefined, and its shape (rows, columns); None if none is found."""
    for gray8 in _detector_images(grey):
        found, corners, meta = cv2.findChessboardCornersSBWithMeta(
            gray8, (3, 3), flags=_DETECTOR_FLAGS | cv2.CALIB_CB_LARGER
        )
        if found:
            return corners.reshape(-1, 2).astype(np.float64), (int(meta.shape[0]), int(meta.shape[1]))
    return None


def _refuse_larger_board(
    grey: np.ndarray, pattern: tuple[int, int], name: str, *, candidates: list[tuple[int, int]] | None = None
) -> None:
    """Raise :class:`ParameterError` naming the board's squares if the image shows a board larger than
    ``pattern``: the first of ``candidates`` (inner corners; default every pattern up to
    :data:`LARGER_PATTERN_SEARCH` more each way, smallest first, in the pattern's orientation first)
    that OpenCV finds as a whole board's lattice (:func:`_lattice_check`)."""
    cols, rows = pattern
    if candidates is None:
        larger = [
            (c, r)
            for c in range(cols, cols + LARGER_PATTERN_SEARCH + 1)
            for r in range(rows, rows + LARGER_PATTERN_SEARCH + 1)
            if (c, r) != (cols, rows)
        ]
        candidates = sorted(larger, key=lambda cr: (cr[0] * cr[1], (cr[0] - cr[1]) * (cols - rows) < 0, cr))
    for c, r in candidates:
        corners = _find_chessboard(grey, (c, r))
        if corners is None:
            continue
        lattice, continues = _lattice_check(grey, corners.reshape(-1, 2).astype(np.float64), (c, r))
        if lattice and not continues:
            raise ParameterError(
                f"{name}: the chessboard has {c + 1} x {r + 1} squares ({c} x {r} inner corners), more than "
                f"pattern {pattern!r} gives ({cols + 1} x {rows + 1} squares); give the board's own squares "
                f"(--squares {c + 1} {r + 1})"
            )


#: Fewest inner corners a board seen in part (:func:`detect_board_lattice`) must show as X-junctions.
PART_MIN_CORNERS = 9


@dataclass(frozen=True, eq=False)
class BoardLattice:
    """The inner corners of a chessboard seen whole or in part: a ``rows x columns`` lattice of them.

    Attributes
    ----------
    corners_px : ndarray, float64, shape (rows * columns, 2)
        Corner pixels ``(u, v)``, row by row with the column index fastest (OpenCV's convention:
        pixel centres at integers). Where ``valid`` is False, the lattice's place for a corner the
        image does not show (a projective fit to the valid corners): a start, not a measurement.
    shape : (int, int)
        ``(rows, columns)`` of the lattice: the pattern's (either way round) for a whole board, fewer
        where the view cuts the board.
    valid : ndarray of bool, shape (rows * columns,)
        Which corners the image shows as chessboard corners (X-junctions at their lattice places).
    whole : bool
        Whether the lattice is the whole pattern and every corner of it is valid.
    """

    corners_px: np.ndarray
    shape: tuple[int, int]
    valid: np.ndarray
    whole: bool

    @property
    def pattern(self) -> tuple[int, int]:
        """``(columns, rows)``: the lattice as an OpenCV ``patternSize``."""
        return self.shape[1], self.shape[0]

    def board_points_m(self, square_size_m: float) -> np.ndarray:
        """The corners' places on the board, shape (rows * columns, 2), metres, centred on the lattice.

        A chessboard's inner corners are a square lattice, so which part of the board a lattice is,
        and which way round, is a rigid motion of the board that its pose absorbs."""
        return lattice_points_m(self.shape, square_size_m)


def lattice_points_m(shape: tuple[int, int], square_size_m: float) -> np.ndarray:
    """A ``(rows, columns)`` lattice of chessboard corners on the board, row by row with the column
    index fastest, centred on the lattice: shape (rows * columns, 2), metres."""
    rows, cols = shape
    jj, ii = np.mgrid[0:rows, 0:cols]
    points = np.stack([ii.ravel() - (cols - 1) / 2, jj.ravel() - (rows - 1) / 2], axis=1)
    return points * square_size_m


def detect_board_lattice(
    image: np.ndarray, pattern: tuple[int, int], *, refine_half_window_px: int = 3, name: str = "image"
) -> BoardLattice | None:
    """Find a chessboard's inner corners in an image: the whole board, or the part of it seen.

    The whole board first (:func:`detect_chessboard`). Where the view cuts the board (it reaches
    past the image's edge, or past a lens's image circle), OpenCV's detector looks for any lattice
    of at least 3 x 3 corners and grows it as far as the image shows squares
    (``findChessboardCornersSBWithMeta`` with ``CALIB_CB_LARGER``), else (its search can take a wrong
    turn at the cut) for every smaller pattern, largest first. The corners are refined as
    :func:`detect_chessboard`'s and each is valid if it is an X-junction at its lattice place; rows
    and columns without one are trimmed away. A calibration needs only the corners' places on the
    board (:meth:`BoardLattice.board_points_m`), not which of the board's corners they are.

    Parameters
    ----------
    image, pattern, refine_half_window_px, name
        As for :func:`detect_chessboard`.

    Returns
    -------
    BoardLattice or None
        None if no lattice with at least :data:`PART_MIN_CORNERS` valid corners is found.

    Raises
    ------
    ParameterError
        As :func:`detect_chessboard`; also if the lattice seen is larger than ``pattern`` either way
        round (the board has more squares than the pattern says).
    """
    cols, rows = _pattern(pattern)
    whole = detect_chessboard(image, (cols, rows), refine_half_window_px=refine_half_window_px, name=name)
    if whole is not None:
        return BoardLattice(whole, (rows, cols), np.ones(len(whole), dtype=bool), True)
    half = positive_int("refine_half_window_px", refine_half_window_px)
    grey = _grey(name, _as_image(name, image))
    found = _find_lattice(grey)
    lattice = None if found is None else _seen_lattice(grey, *found, half=half, pattern=(cols, rows), name=name)
    if lattice is not None:
        return lattice
    # OpenCV's growing search can take a wrong turn where the image cuts the board (its corners then
    # are no lattice): every smaller pattern, largest first, as OpenCV finds it (not grown).
    smaller = {
        (c, r)
        for c in range(3, max(cols, rows) + 1)
        for r in range(3, max(cols, rows) + 1)
        if _fits((c, r), (cols, rows)) and {c, r} != {cols, rows}
    }
    for c, r in sorted(smaller, key=lambda cr: (-cr[0] * cr[1], cr)):
        corners = _find_chessboard(grey, (c, r))
        lattice = (
            None
            if corners is None
            else _seen_lattice(grey, corners, (r, c), half=half, pattern=(cols, rows), name=name)
        )
        if lattice is not None:
            return lattice
    return None


def _fits(lattice: tuple[int, int], pattern: tuple[int, int]) -> bool:
    """Whether a lattice of ``(columns, rows)`` corners fits in ``pattern``, either way round."""
    (c, r), (cols, rows) = lattice, pattern
    return (c <= cols and r <= rows) or (c <= rows and r <= cols)


def _seen_lattice(
    grey: np.ndarray, corners: np.ndarray, shape: tuple[int, int], *, half: int, pattern: tuple[int, int], name: str
) -> BoardLattice | None:
    """A lattice OpenCV found (``corners`` row by row, ``shape`` (rows, columns)) as the part of the
    board it shows (:func:`detect_board_lattice`); None if it shows under :data:`PART_MIN_CORNERS`."""
    cols, rows = pattern
    grid = _sub_pixel(grey, corners, half).reshape((*shape, 2))
    score, spread = _x_junctions(grey, grid, np.gradient(grid, axis=1), np.gradient(grid, axis=0))
    contrast = X_JUNCTION_MIN_CONTRAST * float(np.median(spread))
    valid = _junctions(score, spread, contrast)
    if _skips_corners(grey, grid, contrast) or _irregular(grid, valid):
        return None
    kept_rows, kept_cols = np.flatnonzero(valid.any(axis=1)), np.flatnonzero(valid.any(axis=0))
    if np.count_nonzero(valid) < PART_MIN_CORNERS or len(kept_rows) < 2 or len(kept_cols) < 2:
        return None
    box = np.s_[kept_rows[0] : kept_rows[-1] + 1, kept_cols[0] : kept_cols[-1] + 1]
    grid, valid = grid[box], valid[box]
    seen_rows, seen_cols = valid.shape
    if not _fits((seen_cols, seen_rows), pattern):
        raise ParameterError(
            f"{name}: a lattice of {seen_cols} x {seen_rows} inner corners is seen, more than pattern "
            f"{pattern!r} holds ({cols + 1} x {rows + 1} squares): the board has more squares; give "
            "the board's own squares (--squares)"
        )
    # The corners not shown: where the lattice puts them (a homography from the valid ones).
    jj, ii = np.mgrid[0:seen_rows, 0:seen_cols]
    index = np.stack([ii, jj], axis=-1).astype(np.float64)
    homography, _ = cv2.findHomography(index[valid], grid[valid])
    if homography is None:
        return None
    placed = cv2.perspectiveTransform(index.reshape(-1, 1, 2), homography).reshape(seen_rows, seen_cols, 2)
    grid = np.where(valid[..., None], grid, placed)
    whole = {seen_cols, seen_rows} == {cols, rows} and bool(valid.all())
    return BoardLattice(grid.reshape(-1, 2), (seen_rows, seen_cols), valid.ravel(), whole)


#: Largest difference between neighbouring steps of a chessboard's lattice (consecutive along a
#: line, or side by side on neighbouring lines), as a share of the longer: a board's perspective and
#: a lens's distortion change a step by a few per cent over one square.
LATTICE_STEP_TOLERANCE = 0.3


def _irregular(grid: np.ndarray, valid: np.ndarray) -> bool:
    """Whether the lattice ``grid`` (rows, columns, 2) is no chessboard's: two neighbouring steps
    between its ``valid`` (rows, columns) corners differ by more than :data:`LATTICE_STEP_TOLERANCE`.
    OpenCV's growing search returned, on a board cut by a lens's image circle, a lattice of true
    corners whose first row lay a square further out than its place (steps of 26 and 13 px)."""
    for axis in (0, 1):
        lines, kept = np.moveaxis(grid, axis, 0), np.moveaxis(valid, axis, 0)
        step, both = lines[1:] - lines[:-1], kept[1:] & kept[:-1]
        for first, second, seen in (
            (step[1:], step[:-1], both[1:] & both[:-1]),
            (step[:, 1:], step[:, :-1], both[:, 1:] & both[:, :-1]),
        ):
            gap = np.linalg.norm(first - second, axis=-1)
            longer = np.maximum(np.linalg.norm(first, axis=-1), np.linalg.norm(second, axis=-1))
            if np.any(seen & (gap > LATTICE_STEP_TOLERANCE * longer)):
                return True
    return False


def _skips_corners(grey: np.ndarray, grid: np.ndarray, contrast: float) -> bool:
    """Whether the lattice ``grid`` (rows, columns, 2) steps over corners: points halfway between
    neighbouring corners that are X-junctions (two or more: a skipped row or column has one at each
    of its corners), where a lattice of one square's steps has them on a square's edge. OpenCV's
    search returned a lattice that skipped a column on a board cut by a lens's image circle, every
    corner a true one."""
    down, across = np.gradient(grid, axis=0), np.gradient(grid, axis=1)
    for axis, other in ((1, down), (0, across)):
        ahead = [slice(None)] * 2
        behind = [slice(None)] * 2
        ahead[axis], behind[axis] = slice(1, None), slice(None, -1)
        a, b = tuple(ahead), tuple(behind)
        mid = 0.5 * (grid[a] + grid[b])
        # sampled as a corner of half the step's squares: the skipped corner, if there is one
        score, spread = _x_junctions(grey, mid, 0.5 * (grid[a] - grid[b]), 0.5 * (other[a] + other[b]))
        if np.count_nonzero(_junctions(score, spread, contrast)) >= 2:
            return True
    return False


def _sub_pixel(grey: np.ndarray, points: np.ndarray, half: int) -> np.ndarray:
    """``points`` (N, 2) refined on the saddle points of the linear image (``cornerSubPix``; unclipped:
    the saddle of the board's own edges)."""
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)
    refined = cv2.cornerSubPix(
        grey.astype(np.float32), points.reshape(-1, 1, 2).astype(np.float32), (half, half), (-1, -1), criteria
    )
    return refined.reshape(-1, 2).astype(np.float64)


@dataclass(frozen=True, eq=False, kw_only=True)
class ApproxCalibration:
    """A pinhole with radial-tangential distortion fitted to chessboard views at one depth.

    Attributes
    ----------
    K : ndarray, shape (3, 3)
        Intrinsic matrix of the calibrated images (OpenCV form; ``fx`` and ``fy`` may differ:
        a tilted port magnifies more across its tilt axis), pixels.
    dist_coeffs : ndarray, shape (5,)
        ``k1, k2, p1, p2, k3`` (:data:`DISTORTION_MODEL`), OpenCV's model on normalised coordinates.
    image_size : (int, int)
        ``(width, height)`` of the calibrated images, pixels; images to undistort must have it.
    pattern : (int, int)
        Inner corners per row and column of the board.
    square_size_m : float
        Edge length of a square, metres.
    depth_m : float
        Calibration depth: the median over views of the board centre's z, metres, in the camera
        frame (from ``corners_cam`` where given, else from the fitted poses).
    view_depths_m : ndarray, shape (V,)
        The same per view.
    rms_px : float
        RMS reprojection error of the fit over all corners, pixels.
    view_rms_px : ndarray, shape (V,)
        RMS reprojection error per view, pixels.
    intrinsic_std : ndarray, shape (9,)
        Standard deviations of ``fx, fy, cx, cy, k1, k2, p1, p2, k3`` (:data:`INTRINSIC_NAMES`)
        from OpenCV's Jacobian (0 for fixed ones): a large ``cx``/``cy`` spread means the views
        hardly fix the principal point (and with it the frame's orientation).
    fixed_intrinsics : bool
        ``K`` was given and only the distortion was fitted.
    rotation : ndarray, shape (3, 3)
        Rotation from the camera frame to the model's frame (``d_model = rotation @ d_cam``);
        identity unless fitted with ``corners_cam``.
    known_corners : bool
        Fitted to corners known in the camera frame (``corners_cam``): the model's pinhole is at
        the camera centre, turned by :attr:`rotation`, and :attr:`rms_px` is its error at the
        calibration depth in the camera's frame. Otherwise the model's frame is the fit's own.
    """

    K: np.ndarray
    dist_coeffs: np.ndarray
    image_size: tuple[int, int]
    pattern: tuple[int, int]
    square_size_m: float
    depth_m: float
    view_depths_m: np.ndarray
    rms_px: float
    view_rms_px: np.ndarray
    intrinsic_std: np.ndarray
    fixed_intrinsics: bool = False
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    known_corners: bool = False

    def __post_init__(self) -> None:
        k = np.asarray(self.K, dtype=np.float64)
        upper = k.shape == (3, 3) and np.allclose(k[[1, 2, 2, 2], [0, 0, 1, 2]], [0, 0, 0, 1])
        if not upper or not np.all(np.isfinite(k)):
            raise ParameterError(f"K must be a finite upper-triangular OpenCV intrinsic matrix, got {k.tolist()}")
        if k[0, 0] <= 0 or k[1, 1] <= 0:
            raise ParameterError(f"K must have positive focal lengths, got fx={k[0, 0]!r}, fy={k[1, 1]!r}")
        dist = np.asarray(self.dist_coeffs, dtype=np.float64).ravel()
        if dist.shape != (len(DISTORTION_MODEL),) or not np.all(np.isfinite(dist)):
            raise ParameterError(
                f"dist_coeffs must be {len(DISTORTION_MODEL)} finite numbers {DISTORTION_MODEL}, got {dist.tolist()}"
            )
        size = tuple(self.image_size)
        if len(size) != 2:
            raise ParameterError(f"image_size must be (width, height), got {self.image_size!r}")
        size = tuple(positive_int(f"image_size[{i}]", s) for i, s in enumerate(size))
        rotation = np.asarray(self.rotation, dtype=np.float64)
        if rotation.shape != (3, 3) or not np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-9):
            raise ParameterError(f"rotation must be a 3 x 3 rotation matrix, got {rotation.tolist()}")
        if np.linalg.det(rotation) < 0:
            raise ParameterError(f"rotation must be proper (det +1), got {rotation.tolist()}")
        views = np.asarray(self.view_rms_px, dtype=np.float64).ravel()
        depths = np.asarray(self.view_depths_m, dtype=np.float64).ravel()
        if len(depths) != len(views):
            raise ParameterError(
                f"view_depths_m and view_rms_px must have one entry per view, got {len(depths)} and {len(views)}"
            )
        std = np.asarray(self.intrinsic_std, dtype=np.float64).ravel()
        if std.shape != (len(INTRINSIC_NAMES),):
            raise ParameterError(f"intrinsic_std must have {len(INTRINSIC_NAMES)} entries, got {std.tolist()}")
        if not isinstance(self.fixed_intrinsics, bool):
            raise ParameterError(f"fixed_intrinsics must be True or False, got {self.fixed_intrinsics!r}")
        object.__setattr__(self, "K", k)
        object.__setattr__(self, "dist_coeffs", dist)
        object.__setattr__(self, "image_size", size)
        object.__setattr__(self, "pattern", _pattern(self.pattern))
        object.__setattr__(self, "square_size_m", positive_float("square_size_m", self.square_size_m))
        object.__setattr__(self, "depth_m", positive_float("depth_m", self.depth_m))
        object.__setattr__(self, "view_depths_m", depths)
        object.__setattr__(self, "rms_px", finite_float("rms_px", self.rms_px))
        object.__setattr__(self, "view_rms_px", views)
        object.__setattr__(self, "intrinsic_std", std)
        object.__setattr__(self, "rotation", rotation)
        if not isinstance(self.known_corners, bool):
            raise ParameterError(f"known_corners must be True or False, got {self.known_corners!r}")

    # ------------------------------------------------------------------ undistortion
    def _check_output(self, output: PinholeCamera) -> PinholeCamera:
        if not isinstance(output, PinholeCamera):
            raise ParameterError(f"output must be a PinholeCamera, got {output!r}")
        return output

    def undistort_maps(self, output: PinholeCamera) -> tuple[np.ndarray, np.ndarray]:
        """Where each output pixel samples the calibrated image.

        Parameters
        ----------
        output : PinholeCamera
            The undistorted image's geometry: a pinhole at the camera centre, camera orientation
            (with :attr:`known_corners`; else the fit's own), ``output.K``.

        Returns
        -------
        map_u, map_v : ndarray, float32, shape (output.height_px, output.width_px)
            Source pixel coordinates in the calibrated image (``cv2.remap`` maps).
        """
        output = self._check_output(output)
        # OpenCV's R takes output rays to the source camera's frame as R^-1: ours is `rotation`.
        return cv2.initUndistortRectifyMap(
            self.K,
            self.dist_coeffs,
            self.rotation.T,
            output.K,
            (output.width_px, output.height_px),
            cv2.CV_32FC1,
        )

    def undistort(
        self, image: np.ndarray, output: PinholeCamera, *, maps: tuple[np.ndarray, np.ndarray] | None = None
    ) -> np.ndarray:
        """Resample a calibrated-geometry image onto the undistorted pinhole ``output``.

        Parameters
        ----------
        image : ndarray, shape (height, width) or (height, width, C)
            An image of :attr:`image_size`; NaN marks pixels with no value.
        output : PinholeCamera
        maps : (ndarray, ndarray), optional
            :meth:`undistort_maps` ``(output)``, if already computed.

        Returns
        -------
        ndarray, float32, shape (output.height_px, output.width_px) (+ channels)
            Bilinear interpolation; NaN where the source is NaN or outside the image.
        """
        arr = _as_image("image", image)
        width, height = self.image_size
        if arr.shape[:2] != (height, width):
            raise ParameterError(f"image must have shape ({height}, {width}) (+ channels), got {arr.shape}")
        map_u, map_v = self.undistort_maps(output) if maps is None else maps
        src = arr.astype(np.float32)
        planes = [src] if src.ndim == 2 else [src[..., c] for c in range(src.shape[2])]
        out = [
            cv2.remap(p, map_u, map_v, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=math.nan)
            for p in planes
        ]
        return out[0] if src.ndim == 2 else np.stack(out, axis=-1)

    def undistort_points(self, uv: np.ndarray, output: PinholeCamera) -> np.ndarray:
        """Map pixels (N, 2) of the calibrated image to the undistorted image ``output`` (N, 2)."""
        output = self._check_output(output)
        pts = as_points("uv", uv, 2)
        out = cv2.undistortPoints(pts.reshape(-1, 1, 2), self.K, self.dist_coeffs, R=self.rotation.T, P=output.K)
        return out.reshape(-1, 2).astype(np.float64)

    def project(self, points_cam: np.ndarray) -> np.ndarray:
        """Project camera-frame points (N, 3), metres, into the calibrated image (N, 2) with the model.

        The model's pinhole sits at the camera centre, turned by :attr:`rotation`.
        """
        p = as_points("points_cam", points_cam, 3)
        rvec, _ = cv2.Rodrigues(self.rotation)
        uv, _ = cv2.projectPoints(p, rvec, np.zeros(3), self.K, self.dist_coeffs)
        return uv.reshape(-1, 2).astype(np.float64)

    # ------------------------------------------------------------------ files
    def to_dict(self) -> dict:
        """Plain data for a JSON file (:meth:`save`)."""
        return {
            "kind": KIND,
            "K": self.K.tolist(),
            "dist_coeffs": self.dist_coeffs.tolist(),
            "distortion_model": list(DISTORTION_MODEL),
            "image_size": list(self.image_size),
            "pattern": list(self.pattern),
            "square_size_m": self.square_size_m,
            "depth_m": self.depth_m,
            "view_depths_m": self.view_depths_m.tolist(),
            "rms_px": self.rms_px,
            "view_rms_px": self.view_rms_px.tolist(),
            "intrinsic_std": dict(zip(INTRINSIC_NAMES, self.intrinsic_std.tolist(), strict=True)),
            "fixed_intrinsics": self.fixed_intrinsics,
            "rotation": self.rotation.tolist(),
            "known_corners": self.known_corners,
        }

    @classmethod
    def from_dict(cls, data: dict) -> ApproxCalibration:
        """Inverse of :meth:`to_dict` (a ``schema_version`` entry, as files carry, is ignored)."""
        if not isinstance(data, dict):
            raise ParameterError(f"an approximation calibration must be a dict, got {type(data).__name__}")
        data = {k: v for k, v in data.items() if k != "schema_version"}
        reject_unknown_keys("approximation calibration", data, _KEYS)
        require_keys("approximation calibration", data, _KEYS)
        if data["kind"] != KIND:
            raise ParameterError(f"kind must be {KIND!r}, got {data['kind']!r}")
        if list(data["distortion_model"]) != list(DISTORTION_MODEL):
            raise ParameterError(f"distortion_model must be {list(DISTORTION_MODEL)}, got {data['distortion_model']!r}")
        std = data["intrinsic_std"]
        if not isinstance(std, dict) or set(std) != set(INTRINSIC_NAMES):
            raise ParameterError(f"intrinsic_std must name {list(INTRINSIC_NAMES)}, got {std!r}")
        return cls(
            K=np.asarray(data["K"], dtype=np.float64),
            dist_coeffs=np.asarray(data["dist_coeffs"], dtype=np.float64),
            image_size=tuple(data["image_size"]),
            pattern=tuple(data["pattern"]),
            square_size_m=data["square_size_m"],
            depth_m=data["depth_m"],
            view_depths_m=np.asarray(data["view_depths_m"], dtype=np.float64),
            rms_px=data["rms_px"],
            view_rms_px=np.asarray(data["view_rms_px"], dtype=np.float64),
            intrinsic_std=np.array([std[n] for n in INTRINSIC_NAMES], dtype=np.float64),
            fixed_intrinsics=data["fixed_intrinsics"],
            rotation=np.asarray(data["rotation"], dtype=np.float64),
            known_corners=data["known_corners"],
        )

    def save(self, path: str | os.PathLike) -> Path:
        """Write :meth:`to_dict` as a JSON sidecar (with the schema version), atomically."""
        return write_json(path, self.to_dict())

    @classmethod
    def load(cls, path: str | os.PathLike) -> ApproxCalibration:
        """Read a file written by :meth:`save`."""
        return cls.from_dict(read_json(path))


def _board_points(pattern: tuple[int, int], square_size_m: float) -> np.ndarray:
    """Inner corners in the board frame (N, 3), metres, row by row with x fastest."""
    cols, rows = pattern
    jj, ii = np.mgrid[0:rows, 0:cols]
    return np.stack([ii.ravel() * square_size_m, jj.ravel() * square_size_m, np.zeros(cols * rows)], axis=1)


def _wahba(model_dirs: np.ndarray, cam_dirs: np.ndarray) -> np.ndarray:
    """Rotation R minimising sum |model - R cam|^2 over direction vectors (Kabsch / Wahba, SVD)."""
    u, _, vt = np.linalg.svd(model_dirs.T @ cam_dirs)
    d = np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))])
    return u @ d @ vt


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _k_matrix(fx: float, fy: float, cx: float, cy: float) -> np.ndarray:
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def _fit_known(
    points_cam: np.ndarray, corners_px: np.ndarray, k: np.ndarray, dist: np.ndarray, rotation: np.ndarray, fix_k: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Least-squares fit of (K,) distortion and rotation to known camera-frame corners.

    The pinhole sits at the camera centre. Returns K, distortion, rotation, the per-corner pixel
    residuals (N, 2) and the standard deviations of fx, fy, cx, cy, k1..k3 (0 where fixed).
    """
    rvec0, _ = cv2.Rodrigues(rotation)
    k0 = np.array([k[0, 0], k[1, 1], k[0, 2], k[1, 2]])
    x0 = np.concatenate([dist, rvec0.ravel()]) if fix_k else np.concatenate([k0, dist, rvec0.ravel()])

    def unpack(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if fix_k:
            return k, x[:5], x[5:8]
        return _k_matrix(*x[:4]), x[4:9], x[9:12]

    def residuals(x: np.ndarray) -> np.ndarray:
        kx, dx, rx = unpack(x)
        projected, _ = cv2.projectPoints(points_cam, rx, np.zeros(3), kx, dx)
        return (projected.reshape(-1, 2) - corners_px).ravel()

    solution = least_squares(residuals, x0, method="lm", x_scale="jac")
    if not np.all(np.isfinite(solution.x)):
        raise ParameterError("the calibration with known corners did not converge (non-finite result)")
    kx, dx, rx = unpack(solution.x)
    jac = solution.jac
    dof = max(len(solution.fun) - len(solution.x), 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        cov = np.linalg.pinv(jac.T @ jac) * float(solution.fun @ solution.fun) / dof
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    std_all = np.concatenate([np.zeros(4), std[:5]]) if fix_k else std[:9]
    return kx, np.asarray(dx, dtype=np.float64), cv2.Rodrigues(rx)[0], solution.fun.reshape(-1, 2), std_all


def _require_determined(k: np.ndarray, std: np.ndarray, *, free_k: bool) -> None:
    """Refuse a fit whose views do not determine it: a fitted parameter's standard deviation that is not
    finite (OpenCV reports a singular direction as NaN), or ``fx`` or ``fy`` spread over
    :data:`MAX_FOCAL_STD_RELATIVE` of its value."""
    free = np.ones(len(INTRINSIC_NAMES), dtype=bool)
    free[:4] = free_k
    hint = "add views of the board tilted 20-45 deg towards and away from the camera, about several axes"
    undetermined = [name for name, s, f in zip(INTRINSIC_NAMES, std, free, strict=True) if f and not math.isfinite(s)]
    if undetermined:
        raise CalibrationError(
            f"the views do not determine {', '.join(undetermined)} (no finite standard deviation): {hint}"
        )
    for name, value, spread in (("fx", k[0, 0], std[0]), ("fy", k[1, 1], std[1])):
        if free_k and spread > MAX_FOCAL_STD_RELATIVE * abs(value):
            raise CalibrationError(
                f"the views do not determine the focal length: {name} {value:.4g} +- {spread:.3g} px "
                f"({100 * spread / abs(value):.0f} %, limit {100 * MAX_FOCAL_STD_RELATIVE:.0f} %): {hint}"
            )


def _rms(residuals: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(residuals**2, axis=1))))


def calibrate_approx(
    images: Sequence[np.ndarray],
    *,
    pattern: tuple[int, int],
    square_size_m: float,
    corners_cam: Sequence[np.ndarray] | None = None,
    intrinsics: PinholeCamera | None = None,
    min_views: int = 3,
    refine_half_window_px: int = 3,
    names: Sequence[str] | None = None,
) -> ApproxCalibration:
    """Calibrate a pinhole with radial-tangential distortion from chessboard views (Ferreira et al. 2005).

    Every view must show the whole board (detected by :func:`detect_chessboard`); the boards
    should sit at about one distance (the calibration depth) and cover the image in varied
    orientations. ``cv2.calibrateCameraExtended`` fits ``K`` (``fx, fy, cx, cy``), the distortion
    ``k1, k2, p1, p2, k3`` and one pose per view. With ``corners_cam`` the model is then refitted
    with the camera's pose (see the module docstring).

    Parameters
    ----------
    images : sequence of ndarray, each shape (H, W) or (H, W, C)
        The views, all of one size: linear radiance, NaN where there is no value (e.g. outside the
        lenses' hull of a central view).
    pattern : (int, int)
        Inner corners per row and column (OpenCV's ``patternSize``; a board of ``c x r`` squares
        has ``(c - 1, r - 1)``).
    square_size_m : float
        Edge length of a square, metres.
    corners_cam : sequence of ndarray, each shape (columns * rows, 3), optional
        The boards' inner corners in the camera frame, metres, one array per view, in the board's
        order (row by row, x fastest, as :func:`simulator.assets.chessboard_inner_corners`; the
        detector's half-turned order is recognised). With them ``K``, the distortion and a
        rotation are fitted with the pinhole at the camera centre and the corners where they are
        (:attr:`ApproxCalibration.known_corners`), and the calibration depth comes from them.
    intrinsics : PinholeCamera, optional
        A known ``K`` (of the images' size): only the distortion (and, with ``corners_cam``, the
        rotation) is fitted. For images that are already nearly central projections with a known
        ``K``, such as refraction-free ones (paper condition (d)), where a free ``K`` would only
        add the principal point's ambiguity.
    min_views : int
        Fewest views accepted (default 3).
    refine_half_window_px : int
        ``cornerSubPix`` half window, pixels (see :func:`detect_chessboard`).
    names : sequence of str, optional
        How errors name the views (their files); default ``images[i]``.

    Returns
    -------
    ApproxCalibration

    Raises
    ------
    ParameterError
        Too few views, views of different sizes or shapes, a view without a finite pixel, a view
        where the board is not found (the error names its index), ``corners_cam`` of the wrong
        count or shape, or a fit that does not converge to finite values.
    CalibrationError
        Two views of one board pose (the same image twice is one view:
        :func:`lfrefract.calibration.distinct.require_distinct_corners`), or views that do not determine
        the fit: a fitted parameter without a finite standard deviation, or ``fx`` or ``fy`` spread
        over :data:`MAX_FOCAL_STD_RELATIVE` of its value.
    """
    cols, rows = _pattern(pattern)
    square = square_size("square_size_m", square_size_m)
    minimum = positive_int("min_views", min_views)
    if isinstance(images, np.ndarray) and images.dtype != object:
        raise ParameterError(f"images must be a sequence of images, got one array of shape {images.shape}")
    try:
        views = [_as_image(f"images[{i}]", im) for i, im in enumerate(images)]
    except TypeError:
        raise ParameterError(f"images must be a sequence of images, got {type(images).__name__}") from None
    if len(views) < minimum:
        raise ParameterError(f"calibration needs at least {minimum} views (min_views), got {len(views)}")
    labels = view_names(names, len(views), "images")
    height, width = views[0].shape[:2]
    for i, v in enumerate(views):
        if v.shape != views[0].shape:
            raise ParameterError(f"images[{i}] has shape {v.shape}, images[0] has {views[0].shape}: all must match")
    if intrinsics is not None:
        if not isinstance(intrinsics, PinholeCamera):
            raise ParameterError(f"intrinsics must be a PinholeCamera, got {intrinsics!r}")
        if (intrinsics.width_px, intrinsics.height_px) != (width, height):
            raise ParameterError(
                f"intrinsics is {intrinsics.width_px} x {intrinsics.height_px} px, the images are {width} x {height}"
            )
    known = None
    if corners_cam is not None:
        if len(corners_cam) != len(views):
            raise ParameterError(f"corners_cam must have one array per view ({len(views)}), got {len(corners_cam)}")
        known = [as_points(f"corners_cam[{i}]", c, 3) for i, c in enumerate(corners_cam)]
        for i, c in enumerate(known):
            if len(c) != cols * rows:
                raise ParameterError(
                    f"corners_cam[{i}] must have {cols * rows} corners (pattern {cols} x {rows}), got {len(c)}"
                )
            if np.any(c[:, 2] <= 0):
                raise ParameterError(f"corners_cam[{i}] has corners behind the camera (z <= 0)")

    detected = []
    for i, v in enumerate(views):
        corners = detect_chessboard(v, (cols, rows), refine_half_window_px=refine_half_window_px, name=labels[i])
        if corners is None:
            raise ParameterError(f"{labels[i]}: no chessboard with {cols} x {rows} inner corners found")
        detected.append(corners)
    require_distinct_corners(detected, labels, what="a calibration")

    board = _board_points((cols, rows), square)
    flags, k_init = 0, None
    if intrinsics is not None:
        flags = cv2.CALIB_USE_INTRINSIC_GUESS | cv2.CALIB_FIX_PRINCIPAL_POINT | cv2.CALIB_FIX_FOCAL_LENGTH
        k_init = intrinsics.K.copy()
    # OpenCV accepts None for the initial K and distortion (its type stubs say arrays only).
    rms, k, dist, rvecs, tvecs, std_intr, _, per_view = cv2.calibrateCameraExtended(  # type: ignore[call-overload]
        [board.astype(np.float32)] * len(views),
        [c.reshape(-1, 1, 2).astype(np.float32) for c in detected],
        (width, height),
        k_init,
        None,
        flags=flags,
    )
    dist = np.asarray(dist, dtype=np.float64).ravel()[: len(DISTORTION_MODEL)]
    if not (np.all(np.isfinite(k)) and np.all(np.isfinite(dist)) and math.isfinite(rms)):
        raise ParameterError("the calibration did not converge (non-finite result): check the views")
    fitted_cam = [
        board @ cv2.Rodrigues(r)[0].T + np.asarray(t).reshape(1, 3) for r, t in zip(rvecs, tvecs, strict=True)
    ]
    rotation = np.eye(3)
    std = np.asarray(std_intr, dtype=np.float64).ravel()[: len(INTRINSIC_NAMES)]
    _require_determined(k, std, free_k=intrinsics is None)
    view_rms = np.asarray(per_view, dtype=np.float64).ravel()
    if known is None:
        depths = np.array([float(np.mean(f[:, 2])) for f in fitted_cam])
    else:
        # Match the board's order to the detector's: a half turn reverses the list, and flips the
        # vector from the first corner to the last (the two frames differ by a few degrees only).
        truth = [
            t[::-1] if np.dot(f[-1] - f[0], t[-1] - t[0]) < 0 else t for f, t in zip(fitted_cam, known, strict=True)
        ]
        points = np.concatenate(truth)
        corners_px = np.concatenate(detected)
        # Start from the rotation that best turns the known directions into the fitted model's.
        model = cv2.undistortPoints(corners_px.reshape(-1, 1, 2), k, dist).reshape(-1, 2)
        model_dirs = np.concatenate([model, np.ones((len(model), 1))], axis=1)
        rotation = _wahba(_unit(model_dirs), _unit(points))
        k, dist, rotation, residuals, std = _fit_known(points, corners_px, k, dist, rotation, intrinsics is not None)
        _require_determined(k, std, free_k=intrinsics is None)
        rms = _rms(residuals)
        view_rms = np.array([_rms(r) for r in np.split(residuals, np.cumsum([len(c) for c in detected])[:-1])])
        depths = np.array([float(np.mean(t[:, 2])) for t in known])
    return ApproxCalibration(
        K=k,
        dist_coeffs=dist,
        image_size=(width, height),
        pattern=(cols, rows),
        square_size_m=square,
        depth_m=float(np.median(depths)),
        view_depths_m=depths,
        rms_px=float(rms),
        view_rms_px=view_rms,
        intrinsic_std=std,
        fixed_intrinsics=intrinsics is not None,
        rotation=rotation,
        known_corners=known is not None,
    )
