"""Optics: the light-field camera, the flat port, poses, pinhole cameras and the water's index.

Everything here is a frozen dataclass validated when it is made (lengths in metres, angles in
degrees, camera frames OpenCV's: +x right, +y down, +z forward).
"""

from lfrefract.optics.camera import CapturedRays, LightFieldCamera, MicrolensArray, SensorGeometry
from lfrefract.optics.pinhole import PinholeCamera, virtual_camera_for
from lfrefract.optics.port import FlatPort, PortTrace, fresnel_transmittance, refract
from lfrefract.optics.pose import Pose
from lfrefract.optics.presets import PRESETS, camera_preset
from lfrefract.optics.water import seawater_index

__all__ = [
    "PRESETS",
    "CapturedRays",
    "FlatPort",
    "LightFieldCamera",
    "MicrolensArray",
    "PinholeCamera",
    "PortTrace",
    "Pose",
    "SensorGeometry",
    "camera_preset",
    "fresnel_transmittance",
    "refract",
    "seawater_index",
    "virtual_camera_for",
]
