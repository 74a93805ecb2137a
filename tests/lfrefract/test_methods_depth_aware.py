"""The ``depth-aware`` method of the registry (lfrefract.methods), without rendering.

The raw image is made from the camera's own rays: each ray traced into the water
(:func:`~lfrefract.synthesis.depth_aware.trace_scene_rays`) records a smooth texture where it
crosses a plane at :data:`PLANE_Z_M`, divided by the port's radiometric factor along it.
"""

from __future__ import annotations

import numpy as np
import pytest

from lfrefract import FlatPort, LightFieldCamera, ParameterError, PinholeCamera, camera_preset
from lfrefract.methods import METHODS, CentralProjector, DepthAwareProjector, build_projector
from lfrefract.synthesis.depth_aware import DepthAwareOptions, DepthAwareSynthesis, trace_scene_rays
from lfrefract.synthesis.warp_map import FILLED_EXACT, build_warp_map

#: Camera-frame depth of the textured plane the synthetic raw image sees, metres.
PLANE_Z_M = 0.5

#: Period of the plane's sinusoidal texture, metres.
PERIOD_M = 0.05


def plane_raw(camera: LightFieldCamera, port: FlatPort) -> np.ndarray:
    """A colour raw image of a textured plane at PLANE_Z_M seen through ``port`` (zero where no ray)."""
    rays = trace_scene_rays(camera, port)
    origins, directions = rays.origins_cam.astype(np.float64), rays.directions_cam.astype(np.float64)
    points = origins + ((PLANE_Z_M - origins[:, 2]) / directions[:, 2])[:, None] * directions
    phase = 2.0 * np.pi * points[:, :2] / PERIOD_M
    texture = 0.5 + 0.2 * np.sin(phase[:, 0]) * np.cos(phase[:, 1]) + 0.1 * np.sin(phase[:, 0] + phase[:, 1])
    colour = texture[:, None] * np.array([1.0, 0.8, 0.6])
    image = np.zeros((camera.sensor.height_px, camera.sensor.width_px, 3), dtype=np.float32)
    image.reshape(-1, 3)[rays.raw_index] = colour / rays.gain[:, None]
    return image


@pytest.fixture(scope="module")
def camera():
    return camera_preset("tiny")


@pytest.fixture(scope="module")
def port():
    return FlatPort.from_degrees(tilt_x_deg=15.0, tilt_y_deg=5.0, distance_m=0.012, thickness_m=0.004)


@pytest.fixture(scope="module")
def warp(camera, port):
    return build_warp_map(camera, port)


@pytest.fixture(scope="module")
def raw(camera, port):
    return plane_raw(camera, port)


@pytest.fixture(scope="module")
def projector(camera, port):
    return build_projector("depth-aware", camera, port)


def test_registered_after_the_proposed_methods():
    assert list(METHODS)[-2:] == ["proposed+distortion", "depth-aware"]


def test_depth_aware_projector(camera, port, warp, raw, projector):
    assert isinstance(projector, DepthAwareProjector)
    assert isinstance(projector, CentralProjector)
    assert projector.name == "depth-aware"
    assert projector.output == warp.output
    assert projector.synthesis.options == DepthAwareOptions()
    height, width = warp.output.height_px, warp.output.width_px
    image = projector.apply(raw)
    assert image.dtype == np.float32
    assert image.shape == (height, width, 3)
    grey = projector.apply(raw[..., 1])
    assert grey.dtype == np.float32
    assert grey.shape == (height, width)
    # Inside the warp map's exact coverage the image is the proposed method's on the same map, bit for bit.
    exact = projector.synthesis.warp.filled_classes == FILLED_EXACT
    assert exact.any()
    proposed = build_projector("proposed", camera, port, warp=projector.synthesis.warp)
    reference = proposed.apply(raw)
    assert np.array_equal(image[exact], reference[exact])
    assert np.array_equal(grey[exact], proposed.apply(raw[..., 1])[exact])
    # Every pixel the proposed method fills has a value here too; none holds a partial colour.
    assert np.all(np.isfinite(image[np.isfinite(reference).all(axis=-1)]))
    assert np.array_equal(np.isnan(image).any(axis=-1), np.isnan(image).all(axis=-1))
    assert np.array_equal(np.isnan(grey), np.isnan(image).all(axis=-1))
    assert np.isnan(image).any()  # the tilted port leaves part of the image without rays
    assert np.array_equal(image, projector.synthesis.apply(raw).image, equal_nan=True)


def test_a_prebuilt_warp_map_and_options_are_honoured(camera, port, warp, raw):
    options = DepthAwareOptions(depth_min_m=0.2, depth_max_m=2.0, depth_steps=16, aggregation_radius_px=2)
    projector = build_projector("depth-aware", camera, port, warp=warp, output=warp.output, depth_options=options)
    assert isinstance(projector, DepthAwareProjector)
    assert projector.synthesis.warp is warp
    assert projector.synthesis.options is options
    data = projector.to_dict()
    assert data == {
        **build_projector("proposed", camera, port, warp=warp).to_dict(),
        "method": "depth-aware",
        "depth_options": options.to_dict(),
    }
    assert data["warp_map_key"] == warp.key
    expected = DepthAwareSynthesis.build(camera, port, warp=warp, options=options).apply(raw).image
    assert np.array_equal(projector.apply(raw), expected, equal_nan=True)


def test_bad_depth_aware_input(camera, port, warp):
    options = DepthAwareOptions()
    for name in ("naive", "proposed"):
        with pytest.raises(ParameterError, match=f"depth_options are for method 'depth-aware' only, not '{name}'"):
            build_projector(name, camera, port, warp=warp, depth_options=options)
    with pytest.raises(ParameterError, match="depth_options must be DepthAwareOptions"):
        build_projector("depth-aware", camera, port, warp=warp, depth_options={"depth_steps": 8})
    other = PinholeCamera(focal_px=100.0, cx_px=10.0, cy_px=10.0, width_px=21, height_px=21)
    with pytest.raises(ParameterError, match="differs from the warp map's"):
        build_projector("depth-aware", camera, port, warp=warp, output=other)
    with pytest.raises(ParameterError, match="method 'depth-aware' needs the port"):
        build_projector("depth-aware", camera, warp=warp)
    with pytest.raises(ParameterError, match="warp must be a WarpMap"):
        build_projector("depth-aware", camera, port, warp="map")
    with pytest.raises(ParameterError, match="synthesis must be a DepthAwareSynthesis"):
        DepthAwareProjector(warp)
