"""Distinct board views: a calibration counts its views by what they show, not by how many were given.

The same capture given twice (the same file, a copy of it, a link to it) or two captures of one board
pose add no geometry: a fit that counts them as two views meets its minimum-view check and reports
parameters, and uncertainties, that its views do not determine. Two views are the same when their
corners lie within :data:`SAME_VIEW_RMS_PX` of each other; every calibration
(:func:`~lfrefract.calibration.calibrate_camera`, :func:`~lfrefract.calibration.calibrate_approx`,
:func:`~lfrefract.calibration.calibrate_port`) refuses such views with a
:class:`~lfrefract.errors.CalibrationError` naming both, before it fits anything.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from lfrefract.errors import CalibrationError, ParameterError

__all__ = ["SAME_VIEW_RMS_PX", "require_distinct_corners", "same_corners", "view_names"]

#: Two views whose corners lie within this RMS distance of each other (pixels) show one board pose:
#: two renders or exposures of one pose differ by their corners' noise (0.01-0.03 px located in the
#: light field, 0.2-0.4 px by OpenCV in a central view), two poses by whole squares (a board moved by
#: 0.5 px is moved by under 0.3 % of a view 200 px across, which tells a calibration nothing new).
SAME_VIEW_RMS_PX = 0.5
#: Fewest corners two views must share (by board point) to be compared.
_MIN_SHARED = 4


def same_corners(a_px: np.ndarray, b_px: np.ndarray) -> bool:
    """Whether two views' corners (N, 2), pixels, in the detector's order, show one board pose:
    within :data:`SAME_VIEW_RMS_PX` RMS of each other in that order or half-turned (reversed)."""
    a, b = np.asarray(a_px, dtype=np.float64), np.asarray(b_px, dtype=np.float64)
    if a.shape != b.shape or len(a) == 0:
        return False
    rms = min(float(np.sqrt(np.mean(np.sum((a - c) ** 2, axis=1)))) for c in (b, b[::-1]))
    return rms <= SAME_VIEW_RMS_PX


def _shared(points_a: np.ndarray, points_b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Indices of the board points (N, 2), metres, that two views share (to the nanometre)."""
    keys = [np.round(np.asarray(p, dtype=np.float64) * 1e9).astype(np.int64) for p in (points_a, points_b)]
    packed = [k[:, 0] * (1 << 32) + k[:, 1] for k in keys]
    _, ia, ib = np.intersect1d(packed[0], packed[1], assume_unique=False, return_indices=True)
    return ia, ib


def _same_board_view(a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray]) -> bool:
    """Whether two (board points (N, 2) m, corners (N, 2) px) views show one pose: their shared board
    points, or the half-turned ones (board coordinates centred: a point p is -p half-turned), within
    :data:`SAME_VIEW_RMS_PX`."""
    for sign in (1.0, -1.0):
        ia, ib = _shared(a[0], sign * b[0])
        if len(ia) >= _MIN_SHARED:
            offset = a[1][ia] - b[1][ib]
            if float(np.sqrt(np.mean(np.sum(offset**2, axis=1)))) <= SAME_VIEW_RMS_PX:
                return True
    return False


def require_distinct_corners(
    views: Sequence[tuple[np.ndarray, np.ndarray] | np.ndarray], names: Sequence[str], *, what: str
) -> None:
    """Refuse views that show one board pose twice.

    Parameters
    ----------
    views : sequence
        Each view's corners: an array (N, 2) of pixels in the detector's order (all of one board), or
        a pair (board points (N, 2), metres, centred on the board; corners (N, 2), pixels) matched by
        board point.
    names : sequence of str
        How the error names each view (a file, or ``views[3]``).
    what : str
        The calibration, for the message (``"a camera calibration"``).

    Raises
    ------
    CalibrationError
        Naming the first two views found within :data:`SAME_VIEW_RMS_PX` of each other.
    """
    for j in range(1, len(views)):
        for i in range(j):
            a, b = views[i], views[j]
            if isinstance(a, tuple) and isinstance(b, tuple):
                same = _same_board_view(a, b)
            else:
                same = same_corners(np.asarray(a), np.asarray(b))
            if same:
                raise CalibrationError(
                    f"{names[i]} and {names[j]} show the board in the same pose (their corners within "
                    f"{SAME_VIEW_RMS_PX:g} px of each other): the same capture twice adds nothing to {what}; "
                    "give each capture once, and captures of the board in other poses"
                )


def view_names(names: Sequence[str] | None, count: int, default: str) -> list[str]:
    """How errors name ``count`` views: ``names`` (one per view) or ``default[i]``.

    Raises
    ------
    ParameterError
        If ``names`` is not one string per view.
    """
    if names is None:
        return [f"{default}[{i}]" for i in range(count)]
    if isinstance(names, str):
        raise ParameterError(f"names must be a sequence of strings, one per view, got the string {names!r}")
    listed = list(names)
    if len(listed) != count or not all(isinstance(n, str) for n in listed):
        raise ParameterError(f"names must be {count} strings, one per view, got {listed!r}")
    return listed
