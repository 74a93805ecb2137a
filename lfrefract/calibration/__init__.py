"""Calibration: what the pipeline estimates instead of knowing (MLA, the camera's ray model, port, the
approximation baseline)."""

from lfrefract.calibration.approx import ApproxCalibration, calibrate_approx, detect_chessboard
from lfrefract.calibration.camera import CameraCalibration, RayCorrection, calibrate_camera
from lfrefract.calibration.corners import CornerTracks, light_field_corners
from lfrefract.calibration.joint import JointCalibration, calibrate_port_and_camera
from lfrefract.calibration.mla import LATTICE_MODELS, LENS_STATUS, MlaCalibration, calibrate_mla
from lfrefract.calibration.port import (
    BoardView,
    PortCalibration,
    board_view_from_light_field,
    calibrate_port,
    project_through_port,
)
from lfrefract.errors import CalibrationError

__all__ = [
    "LATTICE_MODELS",
    "LENS_STATUS",
    "ApproxCalibration",
    "BoardView",
    "CalibrationError",
    "CameraCalibration",
    "CornerTracks",
    "JointCalibration",
    "MlaCalibration",
    "PortCalibration",
    "RayCorrection",
    "board_view_from_light_field",
    "calibrate_approx",
    "calibrate_camera",
    "calibrate_mla",
    "calibrate_port",
    "calibrate_port_and_camera",
    "detect_chessboard",
    "light_field_corners",
    "project_through_port",
]
