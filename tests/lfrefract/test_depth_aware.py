"""Depth-aware synthesis on light fields whose every ray's value is known in closed form.

The raw images here are made without rendering: each usable raw pixel's captured ray is traced
into the water (:func:`trace_scene_rays`) and given the texture value of the first plane it meets,
divided by the port's radiometric factor (what the camera records of that radiance). So the depth
of every output pixel and the value its scene point has are exact, and the method is measured
against them: the depth it finds, the image it renders given that depth and given the true one,
and the same estimator without refraction handling.

The camera is tiny-2x behind a port 40 mm away, tilted 26.8 deg in all: the warp map's exact
coverage is then a small patch (88 of 26 508 pixels), so nearly the whole field is outside it.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
from scipy import ndimage

from lfrefract.errors import ParameterError
from lfrefract.optics.port import FlatPort
from lfrefract.optics.presets import camera_preset
from lfrefract.synthesis._depth_kernels import _landing
from lfrefract.synthesis.depth_aware import (
    FILLED_EXACT_GIVEN_DEPTH,
    DepthAwareOptions,
    DepthAwareSynthesis,
    SceneRays,
    SearchImage,
    depth_planes_m,
    estimate_depth,
    render_given_depth,
    trace_scene_rays,
)
from lfrefract.synthesis.warp_map import FILLED_EMPTY, FILLED_EXACT, build_warp_map
from tests.tolerances import (
    DEPTH_AWARE_DEPTH_RELATIVE,
    DEPTH_AWARE_DEPTH_SHARE,
    DEPTH_AWARE_EDGE_OUTLIER_SHARE,
    DEPTH_AWARE_GIVEN_DEPTH_RMSE,
    DEPTH_AWARE_TRUE_DEPTH_RMSE,
    FLOAT64_GEOMETRY_M,
    FLOAT64_UNIT,
    NO_REFRACTION_DEPTH_ERROR_MIN,
)

CAMERA = "tiny-2x"
PORT = {"tilt_x_deg": 25.0, "tilt_y_deg": 10.0, "distance_m": 0.04, "thickness_m": 0.004}
PLANE_Z_M = 0.5
# Pixels from the field's border and from a depth edge left out of the depth figures: the
# aggregation window (default radius 6) and two pixels more.
MARGIN_PX = DepthAwareOptions().aggregation_radius_px + 2


def texture(x_m: np.ndarray, y_m: np.ndarray, phase: float = 0.0) -> np.ndarray:
    """A smooth texture on a plane (periods of 30 and 41 mm: 14-20 px at 0.5 m), values 0.1-0.9."""
    return 0.5 + 0.4 * np.sin(2 * np.pi * x_m / 0.03 + phase) * np.cos(2 * np.pi * y_m / 0.041)


def crossing(rays: SceneRays, z_m: float) -> np.ndarray:
    """Where each ray crosses the camera-frame plane Z = z_m, (N, 3) metres."""
    o = rays.origins_cam.astype(np.float64)
    d = rays.directions_cam.astype(np.float64)
    return o + ((z_m - o[:, 2]) / d[:, 2])[:, None] * d


def raw_of(rays: SceneRays, ray_values: np.ndarray) -> np.ndarray:
    """A raw image holding each ray's radiance as the camera records it (unused pixels 0)."""
    raw = np.zeros(rays.raw_shape[0] * rays.raw_shape[1], dtype=np.float32)
    raw[rays.raw_index] = ray_values / rays.gain
    return raw.reshape(rays.raw_shape)


@functools.cache
def setup() -> DepthAwareSynthesis:
    camera = camera_preset(CAMERA)
    port = FlatPort.from_degrees(**PORT)
    return DepthAwareSynthesis.build(camera, port, warp=build_warp_map(camera, port))


def plane_raw(synthesis: DepthAwareSynthesis) -> np.ndarray:
    x = crossing(synthesis.rays, PLANE_Z_M)
    return raw_of(synthesis.rays, texture(x[:, 0], x[:, 1]))


def lines_of_sight(synthesis: DepthAwareSynthesis) -> tuple[np.ndarray, np.ndarray]:
    """x / z and y / z of every output pixel's line of sight, (H, W) each."""
    out = synthesis.output
    vv, uu = np.mgrid[0 : out.height_px, 0 : out.width_px]
    return (uu - out.cx_px) / out.focal_px, (vv - out.cy_px) / out.focal_px


@functools.cache
def plane_result():
    synthesis = setup()
    return synthesis.apply(plane_raw(synthesis))


def interior(mask: np.ndarray) -> np.ndarray:
    """``mask`` less MARGIN_PX pixels along its border."""
    return ndimage.binary_erosion(mask, iterations=MARGIN_PX)


def test_coverage_outside_the_exact_patch_is_given_depth():
    synthesis = setup()
    result = plane_result()
    exact = synthesis.warp.exact
    assert np.array_equal(result.classes == FILLED_EXACT, exact)
    assert not np.any((result.classes == FILLED_EXACT_GIVEN_DEPTH) & exact)
    coverage = result.coverage
    assert coverage["exact_given_depth_fraction"] > 10 * coverage["exact_fraction"]
    assert coverage["filled_fraction"] == pytest.approx(
        coverage["exact_fraction"] + coverage["exact_given_depth_fraction"] + coverage["approximated_fraction"]
    )
    # The composition keeps the warp map's values where it is exact, and says "no value" with NaN.
    raw = plane_raw(synthesis)
    classic = synthesis.warp.apply(raw)
    assert np.array_equal(result.image[exact], classic[exact])
    assert np.all(np.isnan(result.image[result.classes == FILLED_EMPTY]))
    assert np.all(np.isfinite(result.image[result.classes != FILLED_EMPTY]))


def test_depth_of_a_textured_plane_behind_a_tilted_port():
    result = plane_result()
    region = interior(result.classes == FILLED_EXACT_GIVEN_DEPTH)
    assert region.sum() > 5000
    error = result.depth.depth_m[region] - PLANE_Z_M
    assert np.mean(np.abs(error) < DEPTH_AWARE_DEPTH_RELATIVE * PLANE_Z_M) > DEPTH_AWARE_DEPTH_SHARE
    assert np.all((result.depth.confidence[region] >= 0) & (result.depth.confidence[region] <= 1))


def test_the_same_estimator_without_refraction_handling_misses_the_depth():
    synthesis = setup()
    raw = plane_raw(synthesis)
    camera = camera_preset(CAMERA)
    rays_in_air = trace_scene_rays(camera, None)
    values, keep = rays_in_air.values(raw)
    estimate = estimate_depth(rays_in_air, values, synthesis.output, DepthAwareOptions(), keep=keep)
    region = interior(plane_result().classes == FILLED_EXACT_GIVEN_DEPTH) & np.isfinite(estimate.depth_m)
    relative = np.median(np.abs(estimate.depth_m[region] - PLANE_Z_M)) / PLANE_Z_M
    assert relative > NO_REFRACTION_DEPTH_ERROR_MIN


def test_render_given_the_true_depth_reproduces_the_texture():
    synthesis = setup()
    raw = plane_raw(synthesis)
    values, keep = synthesis.rays.values(raw)
    out = synthesis.output
    truth_depth = np.full((out.height_px, out.width_px), PLANE_Z_M)
    image, used = render_given_depth(synthesis.rays, values, out, truth_depth, synthesis.options, keep=keep)
    xz, yz = lines_of_sight(synthesis)
    truth = texture(xz * PLANE_Z_M, yz * PLANE_Z_M)
    rendered = used >= synthesis.options.min_rays
    region = interior(rendered)
    rmse = np.sqrt(np.mean((image[..., 0][region] - truth[region]) ** 2))
    assert rmse < DEPTH_AWARE_TRUE_DEPTH_RMSE


def test_render_given_the_estimated_depth_beats_the_stand_in_rays():
    synthesis = setup()
    result = plane_result()
    classic = synthesis.warp.apply(plane_raw(synthesis))
    xz, yz = lines_of_sight(synthesis)
    truth = texture(xz * PLANE_Z_M, yz * PLANE_Z_M)
    region = interior(result.classes == FILLED_EXACT_GIVEN_DEPTH)
    ours = np.sqrt(np.mean((result.image[region] - truth[region]) ** 2))
    stand_in = np.sqrt(np.mean((classic[region] - truth[region]) ** 2))
    assert ours < DEPTH_AWARE_GIVEN_DEPTH_RMSE
    assert ours < stand_in / 5


def test_occluding_edge_depth_away_from_the_edge():
    """A textured half-plane at 0.3 m (x < 0) in front of another texture at 0.6 m."""
    synthesis = setup()
    front = crossing(synthesis.rays, 0.3)
    back = crossing(synthesis.rays, 0.6)
    in_front = front[:, 0] < 0.0
    ray_values = np.where(in_front, texture(front[:, 0], front[:, 1]), texture(back[:, 0], back[:, 1], phase=1.7))
    result = synthesis.apply(raw_of(synthesis.rays, ray_values))
    xz, _ = lines_of_sight(synthesis)
    truth = np.where(xz < 0, 0.3, 0.6)
    edge_px = np.abs(xz * synthesis.output.focal_px)
    given = interior(result.classes != FILLED_EMPTY) & (result.classes == FILLED_EXACT_GIVEN_DEPTH)
    away = given & (edge_px > MARGIN_PX)
    near = given & (edge_px <= MARGIN_PX)
    good = np.abs(result.depth.depth_m - truth) < DEPTH_AWARE_DEPTH_RELATIVE * truth
    assert np.mean(good[away]) > DEPTH_AWARE_DEPTH_SHARE
    # Near the edge the window mixes both surfaces: the depth ramps from one to the other over
    # about the window's width (docs/synthesis.md), and seldom leaves the range between them.
    depth_near = result.depth.depth_m[near]
    assert near.sum() > 500
    beyond = (depth_near < 0.3 * (1 - DEPTH_AWARE_DEPTH_RELATIVE)) | (
        depth_near > 0.6 * (1 + DEPTH_AWARE_DEPTH_RELATIVE)
    )
    assert np.mean(beyond) < DEPTH_AWARE_EDGE_OUTLIER_SHARE


def test_landing_matches_the_pinhole_projection():
    out = setup().output
    rng = np.random.default_rng(3)
    origins = rng.uniform([-0.01, -0.01, 0.04], [0.01, 0.01, 0.05], size=(500, 3))
    directions = rng.normal([0, 0, 1], [0.25, 0.2, 0.01], size=(500, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    for o, d, z in zip(origins, directions, rng.uniform(0.1, 2.0, 500), strict=True):
        p, du, dv = _landing(*o, *d, z, out.focal_px, out.cx_px, out.cy_px, out.width_px, out.height_px)
        point = o + (z - o[2]) / d[2] * d
        uv = out.project(point[None])[0]
        iu, iv = np.floor(uv + 0.5).astype(int)
        if 0 <= iu < out.width_px and 0 <= iv < out.height_px:
            assert p == iv * out.width_px + iu
            assert (du, dv) == pytest.approx(tuple(uv - [iu, iv]), abs=1e-9)
        else:
            assert p == -1


def test_rays_leave_the_water_face_as_the_port_traces_them():
    synthesis = setup()
    rays = synthesis.rays
    port = FlatPort.from_degrees(**PORT)
    normal = port.normal
    water_face = port.distance_m + port.thickness_m
    # float32 storage: about 1e-8 m at 0.05 m.
    assert np.allclose(rays.origins_cam @ normal, water_face, atol=1e-7)
    assert np.allclose(np.linalg.norm(rays.directions_cam, axis=1), 1.0, atol=1e-6)
    camera = camera_preset(CAMERA)
    uv = np.stack([rays.raw_index % camera.sensor.width_px, rays.raw_index // camera.sensor.width_px], axis=1)
    sample = slice(0, None, 997)
    air = camera.captured_rays(uv[sample].astype(np.float64))
    trace = port.trace_from_air(air.origins_cam, air.directions_cam)
    assert np.allclose(rays.origins_cam[sample], trace.exit_points_cam, atol=1e-7)
    assert np.allclose(rays.directions_cam[sample], trace.directions_cam, atol=1e-6)
    quadrant = (air.origins_cam[:, 0] > 0).astype(int) + 2 * (air.origins_cam[:, 1] > 0)
    assert np.array_equal(rays.quadrant[sample], quadrant)
    expected_gain = 1.0 / (trace.transmittance * port.radiance_scale)
    assert np.allclose(rays.gain[sample], expected_gain, rtol=1e-6)
    # Without a port the rays are the captured rays themselves, from the lens plane.
    in_air = trace_scene_rays(camera, None)
    assert np.all(np.abs(in_air.origins_cam[:, 2]) <= FLOAT64_GEOMETRY_M)
    assert np.all(in_air.gain == 1.0)
    assert not in_air.refracted
    assert rays.refracted
    assert np.max(np.abs(np.linalg.norm(in_air.directions_cam, axis=1) - 1)) < 1e-6 + FLOAT64_UNIT


def test_values_leave_out_unrecorded_pixels_and_refuse_bad_input():
    synthesis = setup()
    raw = plane_raw(synthesis)
    recorded = np.ones(raw.shape, dtype=bool)
    recorded[: raw.shape[0] // 2] = False
    values, keep = synthesis.rays.values(raw, recorded=recorded)
    assert len(values) == keep.sum() < len(keep)
    assert np.all(synthesis.rays.raw_index[keep] >= (raw.shape[0] // 2) * raw.shape[1])
    with pytest.raises(ParameterError, match="raw must have shape"):
        synthesis.rays.values(raw[:-1])
    with pytest.raises(ParameterError, match="recorded must be a bool array"):
        synthesis.rays.values(raw, recorded=recorded[:-1])
    bad = raw.copy()
    bad.reshape(-1)[synthesis.rays.raw_index[0]] = np.nan
    with pytest.raises(ParameterError, match="non-finite"):
        synthesis.rays.values(bad)
    # A non-finite value at a pixel no ray uses is no error.
    unused = np.setdiff1d(np.arange(raw.size), synthesis.rays.raw_index)[0]
    fine = raw.copy()
    fine.reshape(-1)[unused] = np.nan
    synthesis.rays.values(fine)


@pytest.mark.parametrize(
    ("options", "name"),
    [
        ({"depth_min_m": 0.0}, "depth_min_m"),
        ({"depth_min_m": 1.0, "depth_max_m": 0.5}, "depth_max_m"),
        ({"depth_steps": 2}, "depth_steps"),
        ({"depth_steps": 4.5}, "depth_steps"),
        ({"aggregation_radius_px": -1}, "aggregation_radius_px"),
        ({"aggregation_radius_px": True}, "aggregation_radius_px"),
        ({"min_rays": 0}, "min_rays"),
        ({"occlusion_aware": 1}, "occlusion_aware"),
        ({"compensate_port": "yes"}, "compensate_port"),
        ({"rim_margin_px": -0.5}, "rim_margin_px"),
        ({"min_confidence": 1.5}, "min_confidence"),
    ],
)
def test_options_refuse_bad_values(options, name):
    with pytest.raises(ParameterError, match=name):
        DepthAwareOptions(**options)


def test_depth_planes_are_uniform_in_inverse_depth():
    planes = depth_planes_m(DepthAwareOptions(depth_min_m=0.2, depth_max_m=2.0, depth_steps=5))
    assert planes[0] == pytest.approx(0.2)
    assert planes[-1] == pytest.approx(2.0)
    assert np.allclose(np.diff(1.0 / planes), (1 / 2.0 - 1 / 0.2) / 4)


def test_build_refuses_a_warp_map_of_another_camera():
    synthesis = setup()
    camera = camera_preset(CAMERA)
    other_port = FlatPort.from_degrees(**{**PORT, "tilt_x_deg": 5.0})
    with pytest.raises(ParameterError, match="another port"):
        DepthAwareSynthesis.build(camera, other_port, warp=synthesis.warp)
    with pytest.raises(ParameterError, match="another camera"):
        DepthAwareSynthesis.build(camera_preset("tiny"), FlatPort.from_degrees(**PORT), warp=synthesis.warp)
    other = camera_preset("tiny")
    with pytest.raises(ParameterError, match="raw images"):
        DepthAwareSynthesis(warp=synthesis.warp, rays=trace_scene_rays(other, FlatPort.from_degrees(**PORT)))
    with pytest.raises(ParameterError, match="traced through the port"):
        DepthAwareSynthesis(warp=synthesis.warp, rays=trace_scene_rays(camera_preset(CAMERA), None))


@pytest.mark.parametrize(("near", "far"), [(1e-9, 1e-8), (1e-3, 0.035)], ids=["nanometres", "before-the-water"])
def test_a_depth_range_in_front_of_the_water_is_refused_naming_it(near, far):
    """Every ray enters the water beyond the port's water face (z >= 0.0399 m here): planes all in front
    of it hold no ray, and the sweep gave an all-NaN depth without a word."""
    synthesis = setup()
    options = DepthAwareOptions(depth_min_m=near, depth_max_m=far)
    with pytest.raises(ParameterError, match=rf"depth_min_m={near!r}, depth_max_m={far!r} \(--depth-range\).*water"):
        DepthAwareSynthesis(warp=synthesis.warp, rays=synthesis.rays, options=options)


def test_a_frame_where_no_pixel_finds_a_depth_is_refused():
    """A depth range the rays reach but where no pixel gathers min_rays rays on any plane: the depth
    would be NaN everywhere, which is refused rather than returned as a result."""
    synthesis = setup()
    options = DepthAwareOptions(min_rays=10**6)
    many = DepthAwareSynthesis(warp=synthesis.warp, rays=synthesis.rays, options=options)
    with pytest.raises(ParameterError, match=r"no output pixel has a depth: .*min_rays=1000000"):
        many.apply(plane_raw(synthesis))


def test_a_frame_whose_masks_leave_too_few_rays_for_a_depth_names_the_masks():
    """Masks that leave most rays out (a Lytro capture through a lens whose micro-images are much smaller
    than the camera model's: the retrofocus design at tiny-2x lights 13 % of the rays fully) and no pixel
    with a depth: the refusal blamed the depth range; it names the share of rays the masks left."""
    synthesis = setup()
    options = DepthAwareOptions(min_rays=10**6)
    many = DepthAwareSynthesis(warp=synthesis.warp, rays=synthesis.rays, options=options)
    recorded = np.zeros(synthesis.rays.raw_shape, dtype=bool)
    recorded[::3] = True
    with pytest.raises(ParameterError, match=r"no output pixel has a depth: only 3\d % of the camera's rays .*part"):
        many.apply(plane_raw(synthesis), recorded=recorded)


def test_a_frame_whose_every_ray_is_masked_is_refused_naming_the_mask():
    """Every raw pixel masked as unrecorded (``--nonfinite mask`` on an all-NaN raw): the refusal blamed the
    depth range (no pixel finds a depth); it names the masked pixels instead, before the sweep."""
    from lfrefract.formats.capture import mask_warp_map

    synthesis = setup()
    raw = plane_raw(synthesis)
    nothing = np.zeros(raw.shape[:2], dtype=bool)
    masked = DepthAwareSynthesis(
        warp=mask_warp_map(synthesis.warp, nothing), rays=synthesis.rays, options=synthesis.options
    )
    with pytest.raises(
        ParameterError, match=r"no value anywhere: every ray it needs lies on the .* raw pixels masked"
    ) as err:
        masked.apply(raw, recorded=nothing)
    assert "--depth-range" not in str(err.value)


def test_a_masked_warp_map_leaves_the_depth_aware_pixels_their_values():
    """The warp map emptied by the mask (its rows gather none of the recorded rays) while the rays that see
    the scene keep theirs: the depth-aware pixels are a result, not refused with the warp map."""
    from lfrefract.formats.capture import mask_warp_map

    synthesis = setup()
    raw = plane_raw(synthesis)
    recorded = np.ones(raw.shape[:2], dtype=bool)
    recorded.ravel()[synthesis.warp.indices] = False  # every raw pixel the warp map gathers
    emptied = mask_warp_map(synthesis.warp, recorded)
    assert not emptied.filled.any()
    result = DepthAwareSynthesis(warp=emptied, rays=synthesis.rays, options=synthesis.options).apply(
        raw, recorded=recorded
    )
    given = result.classes == FILLED_EXACT_GIVEN_DEPTH
    assert given.any()
    assert np.isfinite(result.image[given]).all()
    assert np.isnan(result.image[result.classes == FILLED_EMPTY]).all()


@pytest.mark.parametrize("per_call", [1, 2, 5])
def test_the_sweep_in_groups_of_planes_gives_the_single_calls_depth_bit_for_bit(monkeypatch, per_call):
    """The sweep runs in groups of planes (so that SIGTERM is handled between them); each plane is swept
    alone, so the depth, its confidence and its plane are those of one call over every plane, bit for bit."""
    import lfrefract.synthesis.depth_aware as depth_aware

    synthesis = setup()
    values, keep = synthesis.rays.values(plane_raw(synthesis))
    rays = synthesis.rays.kept(keep)
    options = DepthAwareOptions(depth_steps=11)
    monkeypatch.setattr(depth_aware, "sweep_planes_per_call", lambda: options.depth_steps)
    whole = estimate_depth(rays, values, synthesis.output, options)
    monkeypatch.setattr(depth_aware, "sweep_planes_per_call", lambda: per_call)
    grouped = estimate_depth(rays, values, synthesis.output, options)
    assert np.isfinite(whole.depth_m).any()
    for name in ("depth_m", "confidence", "plane_index", "depths_m"):
        np.testing.assert_array_equal(getattr(grouped, name), getattr(whole, name))


def test_a_search_image_is_checked_once_where_it_is_made():
    mosaic = np.zeros((4, 6))
    with pytest.raises(ParameterError, match=r"groups must have the image's shape \(4, 6\), got \(4, 5\)"):
        SearchImage(raw=mosaic, groups=np.zeros((4, 5), dtype=int))
    with pytest.raises(ParameterError, match=r"recorded must have the image's shape"):
        SearchImage(raw=mosaic, recorded=np.ones((3, 6), dtype=bool))
    with pytest.raises(ParameterError, match="raw must be an"):
        SearchImage(raw=np.zeros(5))
    search = SearchImage(raw=mosaic, recorded=np.ones((4, 6)), groups=np.ones((4, 6)))
    assert search.recorded.dtype == bool
    assert search.groups.dtype == np.int64
