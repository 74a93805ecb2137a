"""Calibration: what the pipeline estimates instead of knowing (port, MLA, the approximation baseline)."""

from lfrefract.calibration.approx import ApproxCalibration, calibrate_approx, detect_chessboard
from lfrefract.calibration.mla import LATTICE_MODELS, LENS_STATUS, MlaCalibration, calibrate_mla
from lfrefract.calibration.port import (
    BoardView,
    CalibrationError,
    PortCalibration,
    calibrate_port,
    project_through_port,
)

__all__ = [
    "LATTICE_MODELS",
    "LENS_STATUS",
    "ApproxCalibration",
    "BoardView",
    "CalibrationError",
    "MlaCalibration",
    "PortCalibration",
    "calibrate_approx",
    "calibrate_mla",
    "calibrate_port",
    "detect_chessboard",
    "project_through_port",
]
