"""Results with no value anywhere are refused, never returned as a success.

An image of NaN everywhere (or a warp map with no entry, whose image is zero everywhere) is what the
synthesis gives when the output geometry sees nothing the camera recorded, when every ray it needs
lands on raw pixels masked as unrecorded, or when no line of sight passes the port. Every image the
core produces (:meth:`~lfrefract.synthesis.warp_map.WarpMap.apply` and
:func:`~lfrefract.synthesis.warp_map.build_warp_map`, the depth-aware synthesis, the naive and
sub-aperture views) goes through :func:`require_a_value`, which refuses such a result naming what
left it empty, so that no command writes one with exit status 0.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from lfrefract.errors import ParameterError
from lfrefract.optics.pinhole import PinholeCamera

__all__ = ["masked_reason", "output_geometry", "require_a_value"]


def require_a_value(has_value: np.ndarray | bool, *, what: str, because: Callable[[], str]) -> None:
    """Refuse a result with no value anywhere.

    Parameters
    ----------
    has_value : ndarray of bool, or bool
        Where the result holds a value (any element True: it passes).
    what : str
        The result, as the message names it (``"the 92 x 69 px central view"``).
    because : callable returning str
        What left it empty and what to do; called only when it is.

    Raises
    ------
    ParameterError
        ``"{what} has no value anywhere: {because()}"`` when ``has_value`` holds nowhere.
    """
    if not np.any(has_value):
        raise ParameterError(f"{what} has no value anywhere: {because()}")


def masked_reason(unrecorded: int | None = None, total: int | None = None) -> str:
    """Why a result is empty when every raw pixel it needs is masked as unrecorded (with their count
    when known)."""
    counted = f"the {unrecorded} of {total} raw pixels" if unrecorded is not None else "raw pixels"
    return (
        f"every ray it needs lies on {counted} masked as unrecorded (NaN, inf or negative values under "
        "--nonfinite mask, or a Lytro capture's saturated or bad pixels); give a raw image that records them"
    )


def output_geometry(output: PinholeCamera) -> str:
    """An output geometry as a message names it: size and intrinsics."""
    return (
        f"the {output.width_px} x {output.height_px} px output (focal {output.focal_px:.4g} px, principal point "
        f"cx {output.cx_px:.4g}, cy {output.cy_px:.4g} px)"
    )
