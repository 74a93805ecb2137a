"""lfrefract: refraction-free imaging through flat ports with light-field cameras.

The core is numpy/scipy/OpenCV only; it never imports the renderer.
"""

from lfrefract.errors import ParameterError
from lfrefract.optics.camera import CapturedRays, LightFieldCamera, MicrolensArray, SensorGeometry
from lfrefract.optics.pinhole import PinholeCamera, virtual_camera_for
from lfrefract.optics.port import FlatPort, PortTrace, fresnel_transmittance, refract
from lfrefract.optics.pose import Pose
from lfrefract.optics.presets import PRESETS, camera_preset
from lfrefract.optics.water import seawater_index

__version__ = "0.1.0"

__all__ = [
    "PRESETS",
    "CapturedRays",
    "FlatPort",
    "LightFieldCamera",
    "MicrolensArray",
    "ParameterError",
    "PinholeCamera",
    "PortTrace",
    "Pose",
    "SensorGeometry",
    "__version__",
    "camera_preset",
    "fresnel_transmittance",
    "refract",
    "seawater_index",
    "virtual_camera_for",
]
