"""Calibration: what the pipeline estimates instead of knowing (port, MLA, the approximation baseline)."""

from lfrefract.calibration.port import (
    BoardView,
    CalibrationError,
    PortCalibration,
    calibrate_port,
    project_through_port,
)

__all__ = [
    "BoardView",
    "CalibrationError",
    "PortCalibration",
    "calibrate_port",
    "project_through_port",
]
