"""A small target at a known 3D point behind a tilted port: where it lands in the ideal and raw images."""

from __future__ import annotations

import numpy as np
import pytest

from lfrefract import PinholeCamera, virtual_camera_for
from simulator import groundtruth
from simulator.config import PORT_MODELS, RenderSettings
from simulator.job import render_raw
from simulator.scene import build_scene
from tests.simulator.scenes import port, scene
from tests.tolerances import (
    DEPTH_FLOAT32_RELATIVE,
    IDEAL_DISC_FLUX_RELATIVE,
    IDEAL_TARGET_CENTROID_PX,
    PORT_RADIANCE_RELATIVE,
    RAW_LIT_THRESHOLD,
    RAW_STRAIGHT_PREDICTION_MAX_LIT,
    RAW_TARGET_BRIGHT_MIN,
    RAW_TARGET_DARK_MAX,
)

pytestmark = pytest.mark.render

TARGET_CAM = np.array([0.035, -0.02, 0.40])  # metres, camera frame (identity pose)
TARGET_RADIUS_M = 0.015
RADIANCE = 1.0
# A raw pixel integrates a beam as wide as its microlens: at 0.4 m about 100 um * 0.4 m / 6 mm,
# narrowed by the water: ~5 mm. Pixels whose chief ray passes within this of the disc's rim are
# not classified.
BEAM_MARGIN_M = 0.008


def _target_scene(tilt_x_deg: float, tilt_y_deg: float):
    disc = {
        "type": "disc",
        "position_m": TARGET_CAM.tolist(),
        "radius_m": TARGET_RADIUS_M,
        "reflectance": 0.0,
        "radiance": RADIANCE,
    }
    return scene(port=port(tilt_x_deg, tilt_y_deg), objects=[disc], spp=32)


def _render_raw(mi, config, port_model):
    config = config.with_overrides(render=RenderSettings(spp=config.render.spp, seed=1, port_model=port_model))
    return render_raw(mi, config, progress=False).mean(axis=2)


def _distance_on_target_plane(origins, directions) -> np.ndarray:
    """Distance from the disc centre where each ray meets the (fronto-parallel) disc plane."""
    t = (TARGET_CAM[2] - origins[:, 2]) / directions[:, 2]
    hit = origins + t[:, None] * directions
    return np.linalg.norm(hit - TARGET_CAM, axis=1)


OFF_CENTRE = PinholeCamera(focal_px=150.0, cx_px=30.25, cy_px=41.5, width_px=120, height_px=90)


@pytest.mark.parametrize("which", ["default", "off-centre"])
def test_target_in_ideal_image_at_pinhole_projection(mi, which):
    """The ideal image (no port, whatever the scene's port) projects with its K, pixel centres at integers."""
    config = _target_scene(25.0, 10.0)
    pinhole = virtual_camera_for(config.camera) if which == "default" else OFF_CENTRE
    truth = groundtruth.compute(
        mi, build_scene(mi, config, port_geometry=False), config, pinhole, spp=64, seed=0, progress=False
    )
    image = truth.ideal.mean(axis=2)
    # A fronto-parallel disc projects to a disc centred on the projection of its centre.
    expected = pinhole.project(TARGET_CAM)[0]
    vv, uu = np.mgrid[0 : image.shape[0], 0 : image.shape[1]]
    centroid = np.array([(image * uu).sum(), (image * vv).sum()]) / image.sum()
    assert np.linalg.norm(centroid - expected) < IDEAL_TARGET_CENTROID_PX
    # Its area is the projected disc area (in pixels) times the radiance.
    expected_area = np.pi * (TARGET_RADIUS_M * pinhole.focal_px / TARGET_CAM[2]) ** 2
    assert image.sum() == pytest.approx(expected_area * RADIANCE, rel=IDEAL_DISC_FLUX_RELATIVE)
    # Depth ground truth at the target centre.
    u, v = np.round(expected).astype(int)
    assert truth.depth_m[v, u] == pytest.approx(TARGET_CAM[2], rel=DEPTH_FLOAT32_RELATIVE)


@pytest.mark.parametrize("port_model", PORT_MODELS)
def test_target_in_raw_image_under_predicted_pixels(mi, port_model):
    config = _target_scene(25.0, 10.0)
    raw = _render_raw(mi, config, port_model)
    cam, prt = config.camera, config.port
    rays = cam.captured_rays()
    trace = prt.trace_from_air(rays.origins_cam, rays.directions_cam)
    lit = rays.in_aperture & trace.valid
    dist = np.full(len(lit), np.inf)
    dist[lit] = _distance_on_target_plane(trace.exit_points_cam[lit], trace.directions_cam[lit])
    values = raw.ravel()
    expected_radiance = RADIANCE * prt.radiance_scale * trace.transmittance
    bright = dist < TARGET_RADIUS_M - BEAM_MARGIN_M
    # Pixels whose centre is vignetted may still be lit over part of their area: not classified.
    dark = lit & (dist > TARGET_RADIUS_M + BEAM_MARGIN_M)
    assert bright.sum() > 200
    assert np.mean(values[bright] / expected_radiance[bright]) > RAW_TARGET_BRIGHT_MIN
    assert np.max(values[dark]) < RAW_TARGET_DARK_MAX
    # Ignoring the port (straight rays) predicts other pixels: most of them are dark.
    straight = _distance_on_target_plane(rays.origins_cam, rays.directions_cam) < TARGET_RADIUS_M - BEAM_MARGIN_M
    straight &= rays.in_aperture
    assert straight.sum() > 200
    lit = values[straight] > RAW_LIT_THRESHOLD * RADIANCE * prt.radiance_scale
    assert np.mean(lit) < RAW_STRAIGHT_PREDICTION_MAX_LIT


@pytest.mark.parametrize("port_model", PORT_MODELS)
def test_port_radiometry_matches_fresnel_and_index_scaling(mi, port_model):
    """Behind the port a uniform emitter appears at radiance * T_fresnel * (n_air / n_water)^2."""
    wall = {"type": "disc", "position_m": [0.0, 0.0, 0.5], "radius_m": 2.0, "reflectance": 0.0, "radiance": RADIANCE}
    config = scene(port=port(30.0, 0.0), objects=[wall], spp=16)
    raw = _render_raw(mi, config, port_model)
    cam, prt = config.camera, config.port
    rays = cam.captured_rays()
    trace = prt.trace_from_air(rays.origins_cam, rays.directions_cam)
    uv = np.stack(np.meshgrid(np.arange(raw.shape[1]), np.arange(raw.shape[0])), axis=-1).reshape(-1, 2)
    centre_dist = np.linalg.norm(uv - cam.micro_image_centres_px(rays.lens_indices), axis=1)
    inner = centre_dist < cam.micro_image_radius_px - 1.0  # pixel wholly inside its micro-image
    expected = RADIANCE * prt.radiance_scale * trace.transmittance[inner]
    ratio = raw.ravel()[inner] / expected
    assert np.median(np.abs(ratio - 1.0)) < PORT_RADIANCE_RELATIVE
    # Without the (n_air / n_water)^2 factor the ratio would be off by 44 %.
    assert abs(1.0 / prt.radiance_scale - 1.0) > 10 * PORT_RADIANCE_RELATIVE
