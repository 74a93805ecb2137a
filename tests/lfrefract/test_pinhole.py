"""The virtual pinhole camera of refraction-free images."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from lfrefract import ParameterError, PinholeCamera, camera_preset, virtual_camera_for
from tests.tolerances import FLOAT64_PIXEL_PX, FLOAT64_RELATIVE, FLOAT64_UNIT


@given(
    focal=st.floats(10.0, 5000.0),
    cx=st.floats(-100.0, 1000.0),
    cy=st.floats(-100.0, 1000.0),
    uv=hnp.arrays(np.float64, (16, 2), elements=st.floats(-500.0, 1500.0)),
)
def test_project_inverts_pixel_directions(focal, cx, cy, uv):
    cam = PinholeCamera(focal_px=focal, cx_px=cx, cy_px=cy, width_px=640, height_px=480)
    d = cam.pixel_directions(uv)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, rtol=0, atol=FLOAT64_UNIT)
    assert np.all(d[:, 2] > 0)
    np.testing.assert_allclose(cam.project(d), uv, rtol=0, atol=FLOAT64_PIXEL_PX)
    # Points anywhere along the viewing ray project to the same pixel.
    np.testing.assert_allclose(cam.project(d * 7.5), uv, rtol=0, atol=FLOAT64_PIXEL_PX)


def test_known_projection_and_directions():
    cam = PinholeCamera(focal_px=100.0, cx_px=50.0, cy_px=40.0, width_px=101, height_px=81)
    np.testing.assert_array_equal(cam.K, [[100.0, 0.0, 50.0], [0.0, 100.0, 40.0], [0.0, 0.0, 1.0]])
    # A point 1 m right, 0.5 m down, 2 m ahead: u = 50 + 100 * 1/2, v = 40 + 100 * 0.5/2.
    np.testing.assert_allclose(cam.project([[1.0, 0.5, 2.0]]), [[100.0, 65.0]], rtol=0, atol=FLOAT64_PIXEL_PX)
    # Principal point looks along +z; one focal length to the right is 45 deg right.
    np.testing.assert_allclose(
        cam.pixel_directions([[50.0, 40.0], [150.0, 40.0]]),
        [[0.0, 0.0, 1.0], [math.sqrt(0.5), 0.0, math.sqrt(0.5)]],
        rtol=0,
        atol=FLOAT64_UNIT,
    )
    # Behind or on the camera plane: no projection.
    assert np.all(np.isnan(cam.project([[0.0, 0.0, -1.0], [1.0, 1.0, 0.0]])))
    # Default: every pixel, row-major.
    all_dirs = cam.pixel_directions()
    assert all_dirs.shape == (101 * 81, 3)
    np.testing.assert_allclose(cam.project(all_dirs)[102], [1.0, 1.0], rtol=0, atol=FLOAT64_PIXEL_PX)


def test_from_K_and_dict_round_trip():
    K = np.array([[250.0, 0.0, 91.5], [0.0, 250.0, 68.0], [0.0, 0.0, 1.0]])
    cam = PinholeCamera.from_K(K, 184, 137)
    assert (cam.focal_px, cam.cx_px, cam.cy_px, cam.width_px, cam.height_px) == (250.0, 91.5, 68.0, 184, 137)
    assert PinholeCamera.from_dict(cam.to_dict()) == cam


def test_from_K_rejects_non_square_pixels_and_skew():
    with pytest.raises(ParameterError, match=re.escape("K must have square pixels (fx == fy), got fx=")) as info:
        PinholeCamera.from_K([[250.0, 0.0, 10.0], [0.0, 251.0, 10.0], [0.0, 0.0, 1.0]], 20, 20)
    assert "250.0" in str(info.value)
    assert "251.0" in str(info.value)
    with pytest.raises(ParameterError, match="upper-triangular OpenCV intrinsic matrix"):
        PinholeCamera.from_K([[250.0, 0.5, 10.0], [0.0, 250.0, 10.0], [0.0, 0.0, 1.0]], 20, 20)
    with pytest.raises(ParameterError, match="upper-triangular OpenCV intrinsic matrix"):
        PinholeCamera.from_K([[250.0, 0.0, 10.0], [0.0, 250.0, 10.0], [0.0, 0.0, 2.0]], 20, 20)
    with pytest.raises(ParameterError, match="upper-triangular OpenCV intrinsic matrix"):
        PinholeCamera.from_K(np.eye(4), 20, 20)


@pytest.mark.parametrize(
    ("kwargs", "pattern"),
    [
        ({"focal_px": -1.0}, "focal_px must be positive, got -1.0"),
        ({"cx_px": float("nan")}, "cx_px must be finite, got nan"),
        ({"width_px": 0}, "width_px must be positive, got 0"),
        ({"height_px": 10.5}, "height_px must be an integer, got 10.5"),
    ],
)
def test_bad_pinhole_parameters(kwargs, pattern):
    base = {"focal_px": 100.0, "cx_px": 5.0, "cy_px": 5.0, "width_px": 11, "height_px": 11}
    with pytest.raises(ParameterError, match=re.escape(pattern)):
        PinholeCamera(**{**base, **kwargs})


@pytest.mark.parametrize("pixels_per_lens", [1.0, 2.0, 3.0])
def test_virtual_camera_for_tiny(pixels_per_lens):
    cam = virtual_camera_for(camera_preset("tiny"), pixels_per_lens=pixels_per_lens)
    # Docstring: output pixel = pitch / pixels_per_lens on the MLA plane (100 um / s); focal length
    # f' / pixel = 6 mm / pixel; image = sensor (4.8 x 3.6 mm) scaled by f' / (f' + f_mla) = 6 / 6.2,
    # in whole pixels; principal point at the centre.
    pixel_m = 100e-6 / pixels_per_lens
    width = math.floor(4.8e-3 * 6.0 / 6.2 / pixel_m)
    height = math.floor(3.6e-3 * 6.0 / 6.2 / pixel_m)
    assert (cam.width_px, cam.height_px) == (width, height)
    if pixels_per_lens == 2.0:
        assert (width, height) == (92, 69)
    assert cam.focal_px == pytest.approx(6e-3 / pixel_m, rel=FLOAT64_RELATIVE)
    assert (cam.cx_px, cam.cy_px) == ((width - 1) / 2, (height - 1) / 2)
    # The image's edge column looks at the edge of the field covered by micro-images:
    # half-width on the MLA (width * pixel / 2) at distance f'.
    half_angle = math.atan(width * pixel_m / 2.0 / 6e-3)
    d = cam.pixel_directions([[-0.5, cam.cy_px]])[0]
    assert math.atan2(-d[0], d[2]) == pytest.approx(half_angle, rel=FLOAT64_RELATIVE)


def test_virtual_camera_rejects_bad_density():
    with pytest.raises(ParameterError, match=re.escape("pixels_per_lens must be positive, got 0.0")):
        virtual_camera_for(camera_preset("tiny"), pixels_per_lens=0.0)


# =============================================================================== hostile sidecars (issue 12)
def test_image_sizes_are_bounded_at_once():
    # A meta.json whose ideal was 200000 x 200000 ran for minutes; it is refused by the dataclass.
    from lfrefract.optics.pinhole import MAX_IMAGE_SIDE_PX

    assert MAX_IMAGE_SIDE_PX == 65536
    PinholeCamera(focal_px=1e4, cx_px=0.0, cy_px=0.0, width_px=65536, height_px=65536)
    for name in ("width_px", "height_px"):
        with pytest.raises(ParameterError, match=re.escape(f"{name} must be at most 65536 px, got 200000")):
            PinholeCamera(**{"focal_px": 1e4, "cx_px": 0.0, "cy_px": 0.0, "width_px": 8, "height_px": 8, name: 200_000})
    with pytest.raises(ParameterError, match="must be at most 65536 px"):
        virtual_camera_for(camera_preset("tiny"), pixels_per_lens=2000.0)


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ("92x69", "pinhole must be a table (a JSON object) with K, width_px, height_px, got '92x69'"),
        ([[1, 0, 0], [0, 1, 0], [0, 0, 1]], "pinhole must be a table"),
        ({"K": "eye"}, "K must be a 3 x 3 matrix of numbers, got 'eye'"),
        ({"K": [[1, 0, 0], [0, 1]]}, "K must be a 3 x 3 matrix of numbers"),
        ({"K": {"fx": 1}}, "K must be a 3 x 3 matrix of numbers"),
        ({"width_px": 92.0}, "width_px must be an integer, got 92.0"),
        ({"height_px": None}, "height_px must be an integer, got None"),
        ({"zoom": 2}, "unknown key(s) in pinhole: ['zoom']"),
    ],
)
def test_from_dict_of_the_wrong_types_is_a_parameter_error(data, message):
    good = virtual_camera_for(camera_preset("tiny")).to_dict()
    with pytest.raises(ParameterError, match=re.escape(message)):
        PinholeCamera.from_dict({**good, **data} if isinstance(data, dict) else data)
    with pytest.raises(ParameterError, match=re.escape("missing key(s) in pinhole: ['K']")):
        PinholeCamera.from_dict({"width_px": 8, "height_px": 8})
