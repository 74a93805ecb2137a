"""Camera presets from published optics (Lytro metadata and the paper's reference implementation).

Every preset focuses at infinity (f' = f) and has a main-lens image-side f-number at or above the
microlens f-number, so micro-images tile the sensor without overlapping.
"""

from __future__ import annotations

from collections.abc import Callable

from lfrefract.optics.camera import LightFieldCamera, MicrolensArray, SensorGeometry
from lfrefract.validate import one_of

__all__ = ["PRESETS", "camera_preset"]


def _illum() -> LightFieldCamera:
    # Lytro Illum: 7728 x 5368 px at 1.4 um, hexagonal MLA of 20 um pitch (about 14.3 px per lens),
    # MLA-sensor gap 36 um (MLA f/1.8), main lens as in the reference implementation of the paper
    # (f = f' = 9.993 mm) at f/2.0.
    return LightFieldCamera(
        name="illum",
        focal_length_m=9.993e-3,
        lens_to_mla_m=9.993e-3,
        f_number=2.0,
        mla=MicrolensArray(grid="hex", pitch_m=20e-6, focal_length_m=36e-6),
        sensor=SensorGeometry(width_px=7728, height_px=5368, pixel_pitch_m=1.4e-6),
    )


def _f01() -> LightFieldCamera:
    # Lytro first generation: 3280 x 3280 px at 1.4 um, hexagonal MLA of 14 um pitch (10 px per lens),
    # gap 25 um (MLA f/1.79), f = 6.84 mm at f/1.92.
    return LightFieldCamera(
        name="f01",
        focal_length_m=6.84e-3,
        lens_to_mla_m=6.84e-3,
        f_number=1.92,
        mla=MicrolensArray(grid="hex", pitch_m=14e-6, focal_length_m=25e-6),
        sensor=SensorGeometry(width_px=3280, height_px=3280, pixel_pitch_m=1.4e-6),
    )


def _tiny() -> LightFieldCamera:
    # A small camera with the Illum's character for tests: hexagonal MLA, 10 px per lens, MLA f/2,
    # main lens f/2.2 (image side above the MLA's), a 44 deg horizontal field, and micro-image
    # centres up to 8 px away from their lens centres at the edge. 1907 lenses (about 46 x 41) on 480 x 360 px.
    return LightFieldCamera(
        name="tiny",
        focal_length_m=6e-3,
        lens_to_mla_m=6e-3,
        f_number=2.2,
        mla=MicrolensArray(grid="hex", pitch_m=100e-6, focal_length_m=200e-6),
        sensor=SensorGeometry(width_px=480, height_px=360, pixel_pitch_m=10e-6),
    )


def _tiny_2x() -> LightFieldCamera:
    # The tiny camera at twice its focal length and sensor: the same 44 deg field, MLA and
    # f-numbers, four times the microlenses (7655). Its refraction-free image (188 x 141 px,
    # f = 240 px) is large enough for a chessboard detector; the corner and stereo tests use it.
    tiny = _tiny()
    return LightFieldCamera(
        name="tiny-2x",
        focal_length_m=2 * tiny.focal_length_m,
        lens_to_mla_m=2 * tiny.lens_to_mla_m,
        f_number=tiny.f_number,
        mla=tiny.mla,
        sensor=SensorGeometry(width_px=960, height_px=720, pixel_pitch_m=tiny.sensor.pixel_pitch_m),
    )


PRESETS: dict[str, Callable[[], LightFieldCamera]] = {"illum": _illum, "f01": _f01, "tiny": _tiny, "tiny-2x": _tiny_2x}


def camera_preset(name: str) -> LightFieldCamera:
    """Return the named preset camera: ``"illum"``, ``"f01"``, ``"tiny"`` or ``"tiny-2x"``."""
    return PRESETS[one_of("camera preset", name, tuple(PRESETS))]()
