"""Two-view stereo on refraction-free images.

- :mod:`~lfrefract.stereo.geometry`: relative pose from chessboard corners, rectification and
  triangulation.
- :mod:`~lfrefract.stereo.matching`: disparity maps (ZNCC block matching, OpenCV's SGBM).
"""

from lfrefract.stereo.geometry import (
    Rectification,
    StereoCalibration,
    calibrate_stereo,
    disparity_to_depth,
    disparity_to_points,
    rectify,
)
from lfrefract.stereo.matching import SGBM_MODES, sgbm_disparity, zncc_disparity

__all__ = [
    "SGBM_MODES",
    "Rectification",
    "StereoCalibration",
    "calibrate_stereo",
    "disparity_to_depth",
    "disparity_to_points",
    "rectify",
    "sgbm_disparity",
    "zncc_disparity",
]
