"""lfrefract: refraction-free imaging through flat ports with light-field cameras.

The core is numpy/scipy/OpenCV only; it never imports the renderer.
"""

from lfrefract._validate import ParameterError
from lfrefract.camera import CapturedRays, LightFieldCamera, MicrolensArray, SensorGeometry
from lfrefract.pinhole import PinholeCamera, virtual_camera_for
from lfrefract.port import FlatPort, PortTrace, fresnel_transmittance, refract
from lfrefract.pose import Pose
from lfrefract.presets import PRESETS, camera_preset
from lfrefract.water import seawater_index

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
