"""Forward projection through a flat port (lfrefract.optics.forward) against the port's own backward tracing."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lfrefract.errors import ParameterError
from lfrefract.optics.forward import forward_project, forward_project_quartic, project_through_port
from lfrefract.optics.pinhole import PinholeCamera
from lfrefract.optics.port import FlatPort
from tests.tolerances import (
    FLOAT64_GEOMETRY_M,
    FLOAT64_UNIT,
    FORWARD_DIRECTION_RAD,
    FORWARD_MISS_M,
    FORWARD_QUARTIC_RAD,
    FORWARD_SOLVER_ITERATIONS_MAX,
)

PINHOLE = PinholeCamera(focal_px=500.0, cx_px=319.5, cy_px=239.5, width_px=640, height_px=480)


def _random_port(rng: np.random.Generator, *, glass: bool) -> FlatPort:
    """A port tilted up to 40 deg (any azimuth), 5-60 mm away, single interface or 2-8 mm of glass."""
    tilt = math.radians(rng.uniform(0.0, 40.0))
    azimuth = rng.uniform(0.0, 2.0 * math.pi)
    normal = np.array([math.sin(tilt) * math.cos(azimuth), math.sin(tilt) * math.sin(azimuth), math.cos(tilt)])
    return FlatPort.from_normal(
        normal,
        distance_m=rng.uniform(0.005, 0.06),
        thickness_m=rng.uniform(0.002, 0.008) if glass else 0.0,
        n_glass=rng.uniform(1.45, 1.8),
        n_water=rng.uniform(1.33, 1.35),
    )


def _random_points(rng: np.random.Generator, centre: np.ndarray, count: int) -> np.ndarray:
    """Points 0.05-3 m from ``centre`` in directions within 70 deg of the optical axis."""
    theta = np.arccos(rng.uniform(math.cos(math.radians(70.0)), 1.0, count))
    phi = rng.uniform(0.0, 2.0 * math.pi, count)
    d = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=1)
    return centre + rng.uniform(0.05, 3.0, count)[:, None] * d


def _miss_m(port: FlatPort, centres: np.ndarray, directions: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Distance (N,) of each point from the water-side ray that ``trace_from_air`` makes of the air ray."""
    trace = port.trace_from_air(np.broadcast_to(centres, directions.shape), directions)
    assert trace.valid.all()
    rel = points - trace.exit_points_cam
    along = np.sum(rel * trace.directions_cam, axis=1)
    assert np.all(along > 0.0)  # the point is ahead on the ray, not behind it
    return np.linalg.norm(rel - along[:, None] * trace.directions_cam, axis=1)


@pytest.mark.parametrize("glass", [False, True], ids=["single-interface", "glass"])
@pytest.mark.parametrize("seed", range(6))
def test_the_backward_trace_of_the_ray_passes_through_the_point(seed, glass):
    rng = np.random.default_rng(seed)
    port = _random_port(rng, glass=glass)
    centre = np.array([*rng.uniform(-0.003, 0.003, 2), 0.0])
    points = _random_points(rng, centre, 4000)
    result = forward_project(port, centre, points)
    visible = result.visible
    beyond = points @ port.normal > port.distance_m + port.thickness_m
    np.testing.assert_array_equal(visible, beyond)  # every point in the water is seen (no grazing ones here)
    assert visible.mean() > 0.5
    assert result.iterations <= FORWARD_SOLVER_ITERATIONS_MAX
    directions = result.directions_cam[visible]
    np.testing.assert_allclose(np.linalg.norm(directions, axis=1), 1.0, atol=FLOAT64_UNIT)
    assert _miss_m(port, centre, directions, points[visible]).max() < FORWARD_MISS_M
    # The face points are the backward trace's.
    trace = port.trace_from_air(np.broadcast_to(centre, directions.shape), directions)
    np.testing.assert_allclose(result.entry_points_cam[visible], trace.entry_points_cam, atol=FORWARD_MISS_M)
    np.testing.assert_allclose(result.exit_points_cam[visible], trace.exit_points_cam, atol=FORWARD_MISS_M)


@pytest.mark.parametrize("glass", [False, True], ids=["single-interface", "glass"])
def test_a_point_on_a_traced_ray_gives_that_ray_back(glass):
    rng = np.random.default_rng(7)
    port = _random_port(rng, glass=glass)
    centres = np.stack([*rng.uniform(-0.003, 0.003, (2, 3000)), np.zeros(3000)], axis=1)
    rays = _random_points(rng, np.zeros(3), 3000)
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    trace = port.trace_from_air(centres, rays)
    ok = trace.valid
    points = trace.exit_points_cam[ok] + rng.uniform(0.05, 3.0, ok.sum())[:, None] * trace.directions_cam[ok]
    result = forward_project(port, centres[ok], points)
    assert result.visible.all()
    # The chord between unit vectors is the angle between them, radians, to third order (arccos of the
    # dot product would lose half the digits).
    chord = np.linalg.norm(result.directions_cam - rays[ok], axis=1)
    assert chord.max() < FORWARD_DIRECTION_RAD


def test_a_point_on_the_axis_behind_a_straight_port_is_seen_along_the_axis():
    port = FlatPort(distance_m=0.03, thickness_m=0.005)
    result = forward_project(port, np.zeros(3), np.array([[0.0, 0.0, 0.5], [0.0, 0.0, 2.0]]))
    np.testing.assert_array_equal(result.directions_cam, [[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    np.testing.assert_array_equal(result.entry_points_cam, [[0.0, 0.0, 0.03], [0.0, 0.0, 0.03]])
    np.testing.assert_allclose(result.exit_points_cam, [[0.0, 0.0, 0.035], [0.0, 0.0, 0.035]], atol=FLOAT64_GEOMETRY_M)
    # Tilted: a point on the normal through the centre is seen along the normal.
    tilted = FlatPort.from_degrees(distance_m=0.03, thickness_m=0.005, tilt_x_deg=30.0, tilt_y_deg=-10.0)
    centre = np.array([0.001, -0.002, 0.0])
    result = forward_project(tilted, centre, centre + 0.7 * tilted.normal)
    np.testing.assert_allclose(result.directions_cam[0], tilted.normal, atol=FLOAT64_UNIT)


def test_the_quartic_agrees_with_the_iteration_for_a_single_interface():
    rng = np.random.default_rng(11)
    for _ in range(10):
        port = _random_port(rng, glass=False)
        centre = np.array([*rng.uniform(-0.003, 0.003, 2), 0.0])
        points = _random_points(rng, centre, 2000)
        iterated = forward_project(port, centre, points)
        closed = forward_project_quartic(port, centre, points)
        np.testing.assert_array_equal(np.isnan(closed).any(axis=1), ~iterated.visible)
        v = iterated.visible
        assert np.linalg.norm(closed[v] - iterated.directions_cam[v], axis=1).max() < FORWARD_QUARTIC_RAD
    with pytest.raises(ParameterError, match="thickness"):
        forward_project_quartic(FlatPort(distance_m=0.02, thickness_m=0.004), np.zeros(3), [[0.0, 0.0, 1.0]])


def test_points_that_cannot_be_seen_are_nan():
    port = FlatPort.from_degrees(distance_m=0.02, thickness_m=0.006, tilt_x_deg=20.0)
    n = port.normal
    points = np.array(
        [
            0.01 * n,  # in the air, before the port
            0.023 * n + [0.01, 0.0, 0.0],  # inside the glass
            0.026 * n,  # on the water-side face: not beyond it
            0.5 * n + [0.0, 0.1, 0.0],  # in the water: seen
            # In the water but 1e5 m to the side of a 1 mm deep point: the ray would leave the camera at
            # cos < 1e-6 to the normal, which the backward trace calls a miss.
            0.027 * n + 1e5 * np.cross(n, [1.0, 0.0, 0.0]),
        ]
    )
    result = forward_project(port, np.zeros(3), points)
    np.testing.assert_array_equal(result.visible, [False, False, False, True, False])
    assert np.isnan(result.directions_cam[~result.visible]).all()
    assert np.isnan(result.entry_points_cam[~result.visible]).all()
    assert np.isnan(result.exit_points_cam[~result.visible]).all()
    assert np.isnan(result.residual_m[~result.visible]).all()
    assert np.isfinite(result.directions_cam[3]).all()
    assert np.isnan(project_through_port(port, PINHOLE, np.zeros(3), points)[~result.visible]).all()


def test_an_optically_dense_camera_side_still_reaches_every_point():
    """Air denser than water and glass (indices are free within 1-5): total internal reflection then
    removes air rays, never points; the slowest medium is the glass."""
    rng = np.random.default_rng(3)
    port = FlatPort.from_degrees(
        distance_m=0.02, thickness_m=0.004, tilt_x_deg=25.0, tilt_y_deg=15.0, n_air=1.7, n_glass=1.2, n_water=1.4
    )
    points = _random_points(rng, np.zeros(3), 3000)
    result = forward_project(port, np.zeros(3), points)
    beyond = points @ port.normal > port.distance_m + port.thickness_m
    np.testing.assert_array_equal(result.visible, beyond)
    v = result.visible
    assert _miss_m(port, np.zeros(3), result.directions_cam[v], points[v]).max() < FORWARD_MISS_M


def test_the_iteration_count_is_bounded():
    port = FlatPort.from_degrees(distance_m=0.02, thickness_m=0.006, tilt_x_deg=35.0)
    points = _random_points(np.random.default_rng(5), np.zeros(3), 500)
    capped = forward_project(port, np.zeros(3), points, max_iterations=2)
    assert capped.iterations == 2
    assert np.nanmax(capped.residual_m) > 1e-6  # two steps do not converge: the cap is what stopped it
    full = forward_project(port, np.zeros(3), points)
    assert np.nanmax(full.residual_m) <= 1e-12


def test_project_through_port_is_the_pinhole_projection_without_a_port_and_the_traced_ray_with_one():
    rng = np.random.default_rng(9)
    points = _random_points(rng, np.zeros(3), 500)
    centre = np.array([0.002, -0.001, 0.0])
    np.testing.assert_allclose(
        project_through_port(None, PINHOLE, centre, points), PINHOLE.project(points - centre), rtol=0, atol=1e-9
    )
    port = FlatPort.from_degrees(distance_m=0.03, thickness_m=0.004, tilt_x_deg=-15.0, tilt_y_deg=25.0)
    uv = project_through_port(port, PINHOLE, centre, points)
    ok = np.isfinite(uv).all(axis=1)
    assert ok.mean() > 0.5
    # The pixel's ray from the centre, traced through the port, passes through the point.
    assert _miss_m(port, centre, PINHOLE.pixel_directions(uv[ok]), points[ok]).max() < FORWARD_MISS_M


def test_bad_input_is_refused_with_the_parameter_named():
    port = FlatPort.from_degrees(distance_m=0.02, tilt_x_deg=20.0)
    point = [[0.0, 0.0, 1.0]]
    with pytest.raises(ParameterError, match="centres_cam must lie on the camera side"):
        forward_project(port, 0.03 * port.normal, point)
    with pytest.raises(ParameterError, match="points_cam must be finite"):
        forward_project(port, np.zeros(3), [[0.0, np.nan, 1.0]])
    with pytest.raises(ParameterError, match=r"points_cam must have shape \(N, 3\)"):
        forward_project(port, np.zeros(3), [[0.0, 1.0]])
    with pytest.raises(ParameterError, match="centres_cam must have shape"):
        forward_project(port, np.zeros((2, 3)), np.ones((3, 3)))
    with pytest.raises(ParameterError, match="port must be a FlatPort"):
        forward_project("port", np.zeros(3), point)
    with pytest.raises(ParameterError, match="tolerance_m"):
        forward_project(port, np.zeros(3), point, tolerance_m=0.0)
    with pytest.raises(ParameterError, match="max_iterations"):
        forward_project(port, np.zeros(3), point, max_iterations=0)
    with pytest.raises(ParameterError, match="pinhole must be a PinholeCamera"):
        project_through_port(port, "K", np.zeros(3), point)
