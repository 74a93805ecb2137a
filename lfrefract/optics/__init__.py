"""Optics: the light-field camera, the flat port, poses, pinhole cameras, water and multi-element main lenses.

Everything here is a frozen dataclass validated when it is made (lengths in metres, angles in
degrees, camera frames OpenCV's: +x right, +y down, +z forward).
"""

from lfrefract.optics.camera import CapturedRays, LightFieldCamera, MicrolensArray, SensorGeometry
from lfrefract.optics.lens import (
    GLASSES,
    LENS_PRESETS,
    FirstOrder,
    LensPrescription,
    LensTrace,
    Medium,
    Surface,
    exit_pupil_bounds,
    lens_preset,
    trace_lens,
)
from lfrefract.optics.pinhole import PinholeCamera, virtual_camera_for
from lfrefract.optics.port import FlatPort, PortTrace, fresnel_transmittance, refract
from lfrefract.optics.pose import Pose
from lfrefract.optics.presets import PRESETS, camera_preset
from lfrefract.optics.ray_correction import RayCorrection
from lfrefract.optics.real_lens import RealLensCamera
from lfrefract.optics.water import seawater_index

__all__ = [
    "GLASSES",
    "LENS_PRESETS",
    "PRESETS",
    "CapturedRays",
    "FirstOrder",
    "FlatPort",
    "LensPrescription",
    "LensTrace",
    "LightFieldCamera",
    "Medium",
    "MicrolensArray",
    "PinholeCamera",
    "PortTrace",
    "Pose",
    "RayCorrection",
    "RealLensCamera",
    "SensorGeometry",
    "Surface",
    "camera_preset",
    "exit_pupil_bounds",
    "fresnel_transmittance",
    "lens_preset",
    "refract",
    "seawater_index",
    "trace_lens",
    "virtual_camera_for",
]
