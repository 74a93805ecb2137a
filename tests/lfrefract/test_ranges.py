"""Every numeric field of the core's camera, image and pose types has a physical range (issue 12):
values such as 1e300 are refused with the field named, and every preset lies inside."""

from __future__ import annotations

import dataclasses

import pytest

from lfrefract import PRESETS, ParameterError, PinholeCamera, Pose, camera_preset
from lfrefract.optics.camera import CAMERA_RANGES
from lfrefract.optics.pinhole import MAX_FOCAL_PX, MAX_PRINCIPAL_POINT_PX
from lfrefract.optics.pose import MAX_POSITION_M

TINY = camera_preset("tiny")


def replaced(field: str, value: float):
    """The tiny camera with one field (``"mla.pitch_m"`` for a nested one) set to ``value``."""
    if field.startswith("mla."):
        name = field.removeprefix("mla.")
        value = (value, 0.0) if name == "offset_m" else value
        return dataclasses.replace(TINY, mla=dataclasses.replace(TINY.mla, **{name: value}))
    if field.startswith("sensor."):
        return dataclasses.replace(
            TINY, sensor=dataclasses.replace(TINY.sensor, **{field.removeprefix("sensor."): value})
        )
    return dataclasses.replace(TINY, **{field: value})


@pytest.mark.parametrize("field", sorted(CAMERA_RANGES))
@pytest.mark.parametrize("value", [1e300, -1e300, 1e-300])
def test_camera_fields_out_of_range_are_refused_by_name(field, value):
    low, high, _ = CAMERA_RANGES[field]
    if low <= value <= high:
        pytest.skip("inside the range of this field")
    with pytest.raises(ParameterError, match=field.replace(".", r"\.")):
        replaced(field, value)


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_every_preset_lies_inside_the_ranges(name):
    camera = camera_preset(name)
    values = {
        "focal_length_m": camera.focal_length_m,
        "lens_to_mla_m": camera.lens_to_mla_m,
        "f_number": camera.f_number,
        "mla.pitch_m": camera.mla.pitch_m,
        "mla.focal_length_m": camera.mla.focal_length_m,
        "mla.rotation_rad": camera.mla.rotation_rad,
        "sensor.pixel_pitch_m": camera.sensor.pixel_pitch_m,
    }
    for field, value in values.items():
        low, high, _ = CAMERA_RANGES[field]
        assert low <= value <= high, (field, value)


def test_pinhole_and_pose_bounds():
    with pytest.raises(ParameterError, match="focal_px must be at most"):
        PinholeCamera(focal_px=MAX_FOCAL_PX * 2, cx_px=0.0, cy_px=0.0, width_px=8, height_px=8)
    with pytest.raises(ParameterError, match="cx_px must lie within"):
        PinholeCamera(focal_px=100.0, cx_px=MAX_PRINCIPAL_POINT_PX * 2, cy_px=0.0, width_px=8, height_px=8)
    with pytest.raises(ParameterError, match=r"pose\.position_m must lie within"):
        Pose(position_m=(0.0, 1e300, 0.0))
    assert Pose(position_m=(0.0, MAX_POSITION_M, 0.0)).position_m[1] == MAX_POSITION_M
