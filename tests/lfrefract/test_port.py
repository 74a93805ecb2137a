"""Vector refraction, Fresnel transmittance and the flat port.

Expected values come from Snell's law in angle form, textbook Fresnel equations, slab optics and
hand-computed normals, never from re-running the code under test.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from scipy.optimize import minimize_scalar

from lfrefract import FlatPort, ParameterError, fresnel_transmittance, refract
from lfrefract.optics.port import GRAZING_COS_MIN, MAX_DISTANCE_M, MAX_THICKNESS_M, N_MAX, N_MIN
from tests.tolerances import (
    FLOAT64_ANGLE_DEG,
    FLOAT64_ANGLE_RAD,
    FLOAT64_GEOMETRY_M,
    FLOAT64_UNIT,
    FRESNEL_NEAR_GRAZING,
    PORT_REVERSAL_RELATIVE,
    QUOTED_TILT_DEG,
)

indices = st.floats(min_value=1.0, max_value=2.5, allow_nan=False)
raw_vectors = hnp.arrays(np.float64, (3,), elements=st.floats(-1.0, 1.0, allow_nan=False))
raw_batches = hnp.arrays(np.float64, (24, 3), elements=st.floats(-1.0, 1.0, allow_nan=False))


def unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def perpendicular_unit(n: np.ndarray, azimuth: float) -> np.ndarray:
    """A unit vector perpendicular to the unit vector ``n``, at ``azimuth`` about it."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = unit(np.cross(n, helper))
    e2 = np.cross(n, e1)
    return math.cos(azimuth) * e1 + math.sin(azimuth) * e2


def direction_at(n: np.ndarray, theta: float, azimuth: float) -> np.ndarray:
    """Unit direction at angle ``theta`` from the unit normal ``n``."""
    return math.cos(theta) * n + math.sin(theta) * perpendicular_unit(n, azimuth)


def distance_point_to_line(point, line_point, line_dir) -> np.ndarray:
    """Distance of points (N, 3) from lines through ``line_point`` along unit ``line_dir``."""
    return np.linalg.norm(np.cross(np.asarray(point) - np.asarray(line_point), line_dir), axis=-1)


# =============================================================================== refract
@settings(max_examples=200)
@given(normal=raw_vectors, dirs=raw_batches, n1=indices, n2=indices)
def test_refract_snell_invariants_and_tir(normal, dirs, n1, n2):
    assume(np.linalg.norm(normal) > 0.1)
    nrm = unit(normal)
    keep = np.linalg.norm(dirs, axis=1) > 0.1
    assume(keep.sum() >= 4)
    d = unit(dirs[keep])
    d[d @ nrm < 0] *= -1.0  # orient along the travel, as refract requires
    cos1 = d @ nrm
    sin1 = np.linalg.norm(np.cross(d, nrm), axis=1)
    would_be_sin_t = n1 / n2 * sin1
    # Stay away from the critical angle itself, where round-off decides the flag.
    assume(np.all(np.abs(would_be_sin_t - 1.0) > 1e-9))
    assume(np.all(cos1 > 1e-6))

    out, tir = refract(d, nrm, n1, n2)

    assert out.shape == d.shape
    assert tir.shape == (d.shape[0],)
    np.testing.assert_array_equal(tir, would_be_sin_t > 1.0)
    assert np.all(np.isnan(out[tir]))

    t = out[~tir]
    di = d[~tir]
    # Unit length.
    np.testing.assert_allclose(np.linalg.norm(t, axis=1), 1.0, rtol=0, atol=FLOAT64_UNIT)
    # Snell: n1 sin(theta1) = n2 sin(theta2).
    sin2 = np.linalg.norm(np.cross(t, nrm), axis=1)
    np.testing.assert_allclose(n1 * sin1[~tir], n2 * sin2, rtol=0, atol=FLOAT64_UNIT * max(n1, n2))
    # Coplanar: incident, normal and refracted directions span a plane.
    np.testing.assert_allclose(
        np.einsum("ij,ij->i", di, np.cross(np.broadcast_to(nrm, t.shape), t)), 0.0, atol=FLOAT64_UNIT
    )
    # Transmitted, not reflected: continues across the interface on the same side of the normal.
    assert np.all(t @ nrm > 0.0)
    tangential_in = di - (di @ nrm)[:, None] * nrm
    tangential_out = t - (t @ nrm)[:, None] * nrm
    assert np.all(np.einsum("ij,ij->i", tangential_in, tangential_out) >= -FLOAT64_UNIT)


def test_refract_known_angle_air_to_glass():
    # 30 deg in air into glass of 1.5: sin(theta_t) = 0.5 / 1.5 = 1/3.
    n = np.array([0.0, 0.0, 1.0])
    d = np.array([[math.sin(math.radians(30)), 0.0, math.cos(math.radians(30))]])
    out, tir = refract(d, n, 1.0, 1.5)
    expected = np.array([1.0 / 3.0, 0.0, math.sqrt(1.0 - 1.0 / 9.0)])
    assert not tir[0]
    np.testing.assert_allclose(out[0], expected, rtol=0, atol=FLOAT64_UNIT)


def test_refract_per_ray_normals_and_normal_incidence():
    normals = unit(np.array([[0.0, 0.0, 1.0], [1.0, 1.0, 1.0], [0.0, -1.0, 2.0]]))
    out, tir = refract(normals, normals, 1.0, 1.7)
    assert not tir.any()
    np.testing.assert_allclose(out, normals, rtol=0, atol=FLOAT64_UNIT)


def test_refract_tir_exactly_past_the_critical_angle():
    # Glass 1.5 to air: critical angle asin(1/1.5) = 41.81 deg.
    critical = math.degrees(math.asin(1.0 / 1.5))
    n = np.array([0.0, 0.0, 1.0])
    angles = np.radians([0.0, 20.0, critical - 0.01, critical + 0.01, 60.0, 89.0])
    d = np.stack([np.sin(angles), np.zeros_like(angles), np.cos(angles)], axis=1)
    out, tir = refract(d, n, 1.5, 1.0)
    np.testing.assert_array_equal(tir, [False, False, False, True, True, True])
    assert np.all(np.isnan(out[tir]))
    assert np.all(np.isfinite(out[~tir]))


# =============================================================================== Fresnel
@given(n1=indices, n2=indices)
def test_fresnel_normal_incidence(n1, n2):
    t = fresnel_transmittance(np.array([1.0, -1.0]), n1, n2)
    expected = 1.0 - ((n1 - n2) / (n1 + n2)) ** 2
    np.testing.assert_allclose(t, expected, rtol=0, atol=FLOAT64_UNIT)


@given(n=indices, cos_i=st.floats(min_value=1e-3, max_value=1.0))
def test_fresnel_equal_indices_transmit_everything(n, cos_i):
    np.testing.assert_allclose(fresnel_transmittance(np.array([cos_i]), n, n), 1.0, rtol=0, atol=FLOAT64_UNIT)


@given(n1=indices, n2=indices, theta_deg=st.floats(min_value=1.0, max_value=89.0))
def test_fresnel_matches_angle_form_and_reciprocity(n1, n2, theta_deg):
    theta_i = math.radians(theta_deg)
    sin_t = n1 / n2 * math.sin(theta_i)
    assume(sin_t < 1.0 - 1e-6)
    assume(abs(n1 - n2) > 1e-6)  # the angle form is 0/0 for equal indices
    theta_t = math.asin(sin_t)
    # Textbook angle form of the Fresnel reflectances (a different formula from the code's).
    rs = math.sin(theta_i - theta_t) ** 2 / math.sin(theta_i + theta_t) ** 2
    rp = math.tan(theta_i - theta_t) ** 2 / math.tan(theta_i + theta_t) ** 2
    expected = 1.0 - 0.5 * (rs + rp)
    forward = fresnel_transmittance(np.array([math.cos(theta_i)]), n1, n2)[0]
    backward = fresnel_transmittance(np.array([math.cos(theta_t)]), n2, n1)[0]
    assert forward == pytest.approx(expected, abs=FRESNEL_NEAR_GRAZING)
    assert backward == pytest.approx(forward, abs=FRESNEL_NEAR_GRAZING)  # Stokes reciprocity


def test_fresnel_zero_under_tir_and_positive_below():
    critical = math.asin(1.0 / 1.5)
    cos_i = np.cos([critical - 1e-3, critical + 1e-3, math.radians(70.0)])
    t = fresnel_transmittance(cos_i, 1.5, 1.0)
    assert t[0] > 0.0
    np.testing.assert_array_equal(t[1:], 0.0)


# =============================================================================== FlatPort geometry
@pytest.mark.parametrize(
    ("tilt_x_deg", "tilt_y_deg", "expected"),
    [
        (0.0, 0.0, (0.0, 0.0, 1.0)),
        (30.0, 0.0, (0.0, -0.5, math.sqrt(3.0) / 2.0)),
        (-30.0, 0.0, (0.0, 0.5, math.sqrt(3.0) / 2.0)),
        (0.0, 30.0, (0.5, 0.0, math.sqrt(3.0) / 2.0)),
        (30.0, 30.0, (math.sqrt(3.0) / 4.0, -0.5, 0.75)),
        (45.0, -60.0, (-math.sqrt(3.0) / 2.0 * math.sqrt(0.5), -math.sqrt(0.5), 0.5 * math.sqrt(0.5))),
    ],
)
def test_normal_from_tilt_angles(tilt_x_deg, tilt_y_deg, expected):
    port = FlatPort.from_degrees(distance_m=0.05, tilt_x_deg=tilt_x_deg, tilt_y_deg=tilt_y_deg)
    np.testing.assert_allclose(port.normal, expected, rtol=0, atol=FLOAT64_UNIT)
    assert port.total_tilt_rad == pytest.approx(math.acos(expected[2]), abs=FLOAT64_ANGLE_RAD)
    normal, d = port.plane
    np.testing.assert_array_equal(normal, port.normal)
    assert d == 0.05


def test_from_normal_reference_port():
    # The reference implementation's port normal, 59.2 mm away (docs/design.md, "Facts the presets rest on").
    raw = np.array([0.0085, 0.5004, 1.0])
    port = FlatPort.from_normal(raw, distance_m=59.2e-3, thickness_m=3e-3, n_water=1.33)
    norm = math.sqrt(0.0085**2 + 0.5004**2 + 1.0)
    np.testing.assert_allclose(port.normal, raw / norm, rtol=0, atol=FLOAT64_UNIT)
    tilt_x_deg = math.degrees(port.tilt_x_rad)
    assert tilt_x_deg == pytest.approx(-math.degrees(math.asin(0.5004 / norm)), abs=FLOAT64_ANGLE_DEG)
    assert tilt_x_deg == pytest.approx(-26.6, abs=QUOTED_TILT_DEG)
    assert math.degrees(port.tilt_y_rad) == pytest.approx(math.degrees(math.atan2(0.0085, 1.0)), abs=FLOAT64_ANGLE_DEG)
    assert math.degrees(port.total_tilt_rad) == pytest.approx(26.6, abs=QUOTED_TILT_DEG)
    assert port.thickness_m == 3e-3
    assert port.n_water == 1.33
    # Round trip through the degree form of a config file.
    again = FlatPort.from_degrees(distance_m=59.2e-3, tilt_x_deg=tilt_x_deg, tilt_y_deg=math.degrees(port.tilt_y_rad))
    np.testing.assert_allclose(again.normal, raw / norm, rtol=0, atol=FLOAT64_UNIT)


@given(
    normal=raw_vectors.filter(lambda v: np.linalg.norm(v) > 0.1 and v[2] > 0.05 * np.linalg.norm(v)),
    scale=st.floats(min_value=1e-3, max_value=1e3),
)
def test_from_normal_round_trip(normal, scale):
    port = FlatPort.from_normal(normal * scale, distance_m=0.1)
    np.testing.assert_allclose(port.normal, unit(normal), rtol=0, atol=FLOAT64_UNIT)


def test_faces_and_radiance_scale():
    port = FlatPort(distance_m=0.05, thickness_m=0.01, n_air=1.0, n_glass=1.5, n_water=1.333)
    assert port.faces == [(0.05, 1.0, 1.5), (pytest.approx(0.06, abs=FLOAT64_GEOMETRY_M), 1.5, 1.333)]
    single = FlatPort(distance_m=0.05, n_air=1.0, n_water=1.333)
    assert single.faces == [(0.05, 1.0, 1.333)]
    assert port.radiance_scale == pytest.approx((1.0 / 1.333) ** 2, rel=1e-15)


def test_clearance_matches_sampled_aperture_rim():
    port = FlatPort.from_degrees(distance_m=0.03, tilt_x_deg=25.0, tilt_y_deg=-10.0)
    radius = 0.004
    n = port.normal

    def z_face(phi):
        # z of the air face above the rim point of the lens plane z = 0 at angle phi.
        return (0.03 - radius * (n[0] * np.cos(phi) + n[1] * np.sin(phi))) / n[2]

    # Numerical minimum over the rim: coarse search, then a bounded scalar minimisation.
    phi = np.linspace(0.0, 2.0 * np.pi, 3601)
    best = phi[np.argmin(z_face(phi))]
    step = phi[1] - phi[0]
    res = minimize_scalar(z_face, bounds=(best - step, best + step), method="bounded", options={"xatol": 1e-10})
    assert port.clearance_m(radius) == pytest.approx(res.fun, abs=FLOAT64_GEOMETRY_M)
    # Sanity: the minimum is below the face's height on the axis.
    assert res.fun < 0.03 / n[2]


# =============================================================================== tracing
def test_equal_indices_leave_rays_unchanged():
    port = FlatPort.from_degrees(
        distance_m=0.05,
        thickness_m=0.01,
        tilt_x_deg=20.0,
        tilt_y_deg=-15.0,
        n_air=1.33,
        n_glass=1.33,
        n_water=1.33,
    )
    rng = np.random.default_rng(1)
    origins = np.concatenate([rng.uniform(-0.003, 0.003, (50, 2)), np.zeros((50, 1))], axis=1)
    dirs = unit(np.concatenate([rng.uniform(-0.4, 0.4, (50, 2)), np.ones((50, 1))], axis=1))
    tr = port.trace_from_air(origins, dirs)
    assert tr.valid.all()
    np.testing.assert_allclose(tr.directions_cam, dirs, rtol=0, atol=FLOAT64_UNIT)
    n = port.normal
    np.testing.assert_allclose(tr.entry_points_cam @ n, 0.05, rtol=0, atol=FLOAT64_GEOMETRY_M)
    np.testing.assert_allclose(tr.exit_points_cam @ n, 0.06, rtol=0, atol=FLOAT64_GEOMETRY_M)
    np.testing.assert_allclose(distance_point_to_line(tr.exit_points_cam, origins, dirs), 0.0, atol=FLOAT64_GEOMETRY_M)
    np.testing.assert_allclose(distance_point_to_line(tr.entry_points_cam, origins, dirs), 0.0, atol=FLOAT64_GEOMETRY_M)
    np.testing.assert_allclose(tr.transmittance, 1.0, rtol=0, atol=FLOAT64_UNIT)


@settings(max_examples=150)
@given(
    thickness=st.sampled_from([0.0, 0.004, 0.02]),
    tilt_x=st.floats(-35.0, 35.0),
    tilt_y=st.floats(-35.0, 35.0),
    origin_xy=hnp.arrays(np.float64, (2,), elements=st.floats(-0.003, 0.003)),
    theta=st.floats(0.0, 50.0),
    azimuth=st.floats(0.0, 2.0 * math.pi),
)
def test_air_water_round_trip_is_reversible(thickness, tilt_x, tilt_y, origin_xy, theta, azimuth):
    port = FlatPort.from_degrees(
        distance_m=0.05,
        thickness_m=thickness,
        tilt_x_deg=tilt_x,
        tilt_y_deg=tilt_y,
        n_air=1.0,
        n_glass=1.5,
        n_water=1.333,
    )
    n = port.normal
    origin = np.array([origin_xy[0], origin_xy[1], 0.0])
    d = direction_at(np.array([0.0, 0.0, 1.0]), math.radians(theta), azimuth)
    assume(d @ n > 0.05)

    fwd = port.trace_from_air(origin, d)
    assert fwd.valid[0]
    w = fwd.directions_cam[0]
    # Parallel faces: n_air sin(theta_air) = n_water sin(theta_water), the glass drops out.
    sin_air = np.linalg.norm(np.cross(d, n))
    sin_water = np.linalg.norm(np.cross(w, n))
    assert 1.0 * sin_air == pytest.approx(1.333 * sin_water, abs=FLOAT64_UNIT)
    assert fwd.entry_points_cam[0] @ n == pytest.approx(0.05, abs=FLOAT64_GEOMETRY_M)
    assert fwd.exit_points_cam[0] @ n == pytest.approx(0.05 + thickness, abs=FLOAT64_GEOMETRY_M)
    assert distance_point_to_line(fwd.entry_points_cam[0], origin, d) == pytest.approx(0.0, abs=FLOAT64_GEOMETRY_M)

    # Light from a point in the water along the reversed ray comes back along the air ray.
    water_point = fwd.exit_points_cam[0] + 0.3 * w
    back = port.trace_from_water(water_point, -w)
    assert back.valid[0]
    np.testing.assert_allclose(back.directions_cam[0], -d, rtol=0, atol=FLOAT64_UNIT)
    np.testing.assert_allclose(back.entry_points_cam[0], fwd.exit_points_cam[0], rtol=0, atol=FLOAT64_GEOMETRY_M)
    np.testing.assert_allclose(back.exit_points_cam[0], fwd.entry_points_cam[0], rtol=0, atol=FLOAT64_GEOMETRY_M)
    assert distance_point_to_line(origin, back.exit_points_cam[0], back.directions_cam[0]) == pytest.approx(
        0.0, abs=FLOAT64_GEOMETRY_M
    )
    # Fresnel transmittance is reciprocal.
    assert back.transmittance[0] == pytest.approx(fwd.transmittance[0], abs=FLOAT64_UNIT)


@pytest.mark.parametrize("thickness", [0.0, 0.01])
@pytest.mark.parametrize(("tilt_x", "tilt_y"), [(0.0, 0.0), (26.6, 0.5), (-10.0, 40.0)])
def test_normal_incidence_is_undeviated(thickness, tilt_x, tilt_y):
    port = FlatPort.from_degrees(
        distance_m=0.06,
        thickness_m=thickness,
        tilt_x_deg=tilt_x,
        tilt_y_deg=tilt_y,
        n_air=1.0,
        n_glass=1.5,
        n_water=1.333,
    )
    n = port.normal
    tr = port.trace_from_air(np.zeros(3), n)
    np.testing.assert_allclose(tr.directions_cam[0], n, rtol=0, atol=FLOAT64_UNIT)
    np.testing.assert_allclose(tr.entry_points_cam[0], 0.06 * n, rtol=0, atol=FLOAT64_GEOMETRY_M)
    np.testing.assert_allclose(tr.exit_points_cam[0], (0.06 + thickness) * n, rtol=0, atol=FLOAT64_GEOMETRY_M)

    def r(a, b):
        return ((a - b) / (a + b)) ** 2

    expected_t = (1 - r(1.0, 1.5)) * (1 - r(1.5, 1.333)) if thickness > 0 else 1 - r(1.0, 1.333)
    assert tr.transmittance[0] == pytest.approx(expected_t, abs=FLOAT64_UNIT)


@given(
    theta_deg=st.floats(0.0, 80.0),
    azimuth=st.floats(0.0, 2.0 * math.pi),
    tilt_x=st.floats(-30.0, 30.0),
    thickness=st.floats(1e-4, 0.03),
    n_glass=st.floats(1.2, 2.0),
)
def test_slab_lateral_shift_matches_textbook(theta_deg, azimuth, tilt_x, thickness, n_glass):
    port = FlatPort.from_degrees(
        distance_m=0.05, thickness_m=thickness, tilt_x_deg=tilt_x, n_air=1.0, n_glass=n_glass, n_water=1.0
    )
    n = port.normal
    theta = math.radians(theta_deg)
    d = direction_at(n, theta, azimuth)
    tr = port.trace_from_air(np.zeros(3), d)
    assert tr.valid[0]
    # Same medium on both sides: the ray leaves parallel to itself, shifted sideways by
    # t sin(theta - theta_t) / cos(theta_t).
    theta_t = math.asin(math.sin(theta) / n_glass)
    shift = thickness * math.sin(theta - theta_t) / math.cos(theta_t)
    np.testing.assert_allclose(tr.directions_cam[0], d, rtol=0, atol=FLOAT64_UNIT)
    assert distance_point_to_line(tr.exit_points_cam[0], np.zeros(3), d) == pytest.approx(shift, abs=FLOAT64_GEOMETRY_M)


def test_rays_parallel_or_away_or_starting_beyond_the_port_miss():
    port = FlatPort.from_degrees(distance_m=0.05, thickness_m=0.005, tilt_x_deg=20.0)
    n = port.normal
    along_face = np.array([1.0, 0.0, 0.0])  # exactly perpendicular to n = (0, -sin 20, cos 20)
    assert along_face @ n == 0.0
    origins = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], 0.2 * n])
    dirs = np.stack([n, along_face, -n, n])
    tr = port.trace_from_air(origins, dirs)
    np.testing.assert_array_equal(tr.misses, [False, True, True, True])
    np.testing.assert_array_equal(tr.tir, [False, False, False, False])
    np.testing.assert_array_equal(tr.valid, [True, False, False, False])
    for arr in (tr.entry_points_cam, tr.exit_points_cam, tr.directions_cam):
        assert np.all(np.isfinite(arr[0]))
        assert np.all(np.isnan(arr[1:]))
    np.testing.assert_array_equal(tr.transmittance[1:], 0.0)

    # From the water: light travelling away from the port (into the water) never reaches the camera.
    back = port.trace_from_water(np.stack([0.2 * n, 0.2 * n]), np.stack([-n, n]))
    np.testing.assert_array_equal(back.misses, [False, True])
    assert np.all(np.isnan(back.directions_cam[1]))


@pytest.mark.parametrize("thickness", [0.0, 0.01])
def test_tir_is_reported_not_dropped(thickness):
    # Dense medium on the camera side, glass index matched, water lighter: critical angle 41.81 deg.
    port = FlatPort(distance_m=0.05, thickness_m=thickness, n_air=1.5, n_glass=1.5, n_water=1.0)
    n = port.normal
    angles = [0.0, 30.0, 41.0, 42.5, 60.0, 80.0]
    dirs = np.stack([direction_at(n, math.radians(a), 1.0) for a in angles])
    tr = port.trace_from_air(np.zeros((len(angles), 3)), dirs)
    expected_tir = np.array([1.5 * math.sin(math.radians(a)) > 1.0 for a in angles])
    np.testing.assert_array_equal(expected_tir, [False, False, False, True, True, True])
    assert tr.directions_cam.shape == (len(angles), 3)
    np.testing.assert_array_equal(tr.tir, expected_tir)
    np.testing.assert_array_equal(tr.misses, False)
    np.testing.assert_array_equal(tr.valid, ~expected_tir)
    assert np.all(np.isnan(tr.directions_cam[expected_tir]))
    assert np.all(np.isnan(tr.exit_points_cam[expected_tir]))
    np.testing.assert_array_equal(tr.transmittance[expected_tir], 0.0)
    assert np.all(tr.transmittance[~expected_tir] > 0.0)
    # The surviving rays obey Snell across the port.
    sin_out = np.linalg.norm(np.cross(tr.directions_cam[~expected_tir], n), axis=1)
    np.testing.assert_allclose(sin_out, 1.5 * np.sin(np.radians(angles))[~expected_tir], rtol=0, atol=FLOAT64_UNIT)


def test_tir_inside_the_glass_from_the_water_side():
    # Water denser than glass on the way out: TIR at the glass face the light reaches second.
    port = FlatPort(distance_m=0.05, thickness_m=0.01, n_air=1.0, n_glass=1.2, n_water=1.6)
    n = port.normal
    # sin in water 0.8 -> sin in glass 1.0667 > 1: TIR at the first (water/glass) face.
    # sin in water 0.7 -> sin in glass 0.933 -> sin in air 1.12 > 1: TIR at the second face.
    # sin in water 0.5 -> 0.667 -> 0.8: transmitted.
    sines = np.array([0.8, 0.7, 0.5])
    dirs = np.stack([direction_at(-n, math.asin(s), 0.2) for s in sines])
    tr = port.trace_from_water(np.tile(0.2 * n, (3, 1)), dirs)
    np.testing.assert_array_equal(tr.tir, [True, True, False])
    np.testing.assert_array_equal(tr.misses, False)
    sin_air = np.linalg.norm(np.cross(tr.directions_cam[2], n))
    assert sin_air == pytest.approx(1.6 * 0.5, abs=FLOAT64_UNIT)


# =============================================================================== bad input
@pytest.mark.parametrize(
    ("kwargs", "pattern"),
    [
        ({"distance_m": 0.05, "thickness_m": -0.001}, "port.thickness_m must be non-negative, got -0.001"),
        ({"distance_m": float("nan")}, "port.distance_m must be finite, got nan"),
        ({"distance_m": 0.0}, "port.distance_m must be positive, got 0.0"),
        ({"distance_m": -0.05}, "port.distance_m must be positive, got -0.05"),
        ({"distance_m": 0.05, "n_glass": 0.0}, "port.n_glass=0.0 is not the refractive index of a real medium"),
        ({"distance_m": 0.05, "n_water": float("inf")}, "port.n_water must be finite, got inf"),
        ({"distance_m": 0.05, "tilt_x_rad": float("nan")}, "port.tilt_x_rad must be finite, got nan"),
        ({"distance_m": "0.05"}, "port.distance_m must be a real number, got '0.05'"),
    ],
)
def test_bad_port_parameters(kwargs, pattern):
    with pytest.raises(ParameterError, match=re.escape(pattern)):
        FlatPort(**kwargs)


@pytest.mark.parametrize(("tilt_x", "tilt_y"), [(90.0, 0.0), (0.0, 90.0), (120.0, 0.0), (0.0, -135.0)])
def test_port_behind_the_camera(tilt_x, tilt_y):
    with pytest.raises(ParameterError, match="behind the camera") as info:
        FlatPort(distance_m=0.05, tilt_x_rad=math.radians(tilt_x), tilt_y_rad=math.radians(tilt_y))
    assert "tilt_x_rad" in str(info.value)
    assert repr(math.radians(tilt_x)) in str(info.value)


@pytest.mark.parametrize(
    ("tilt_x", "tilt_y", "named"),
    [(90.0, 0.0, "tilt_x_deg"), (0.0, 90.0, "tilt_y_deg"), (120.0, 0.0, "tilt_x_deg"), (0.0, -135.0, "tilt_y_deg")],
)
def test_port_behind_the_camera_is_named_in_degrees_as_given(tilt_x, tilt_y, named):
    # A port file or scene gives degrees: the refusal names the key and the value it holds, not radians.
    with pytest.raises(ParameterError, match="behind the camera") as info:
        FlatPort.from_degrees(distance_m=0.05, tilt_x_deg=tilt_x, tilt_y_deg=tilt_y)
    assert f"port.{named} must lie in (-90, 90) deg, got {tilt_x if named == 'tilt_x_deg' else tilt_y!r}" in str(
        info.value
    )
    assert "_rad" not in str(info.value)
    with pytest.raises(ParameterError, match=re.escape("tilt_x_deg=89.99999999999, tilt_y_deg=0.0")):
        FlatPort.from_degrees(distance_m=0.05, tilt_x_deg=89.99999999999)  # nearer edge-on than 1e-9


def test_bad_tilt_degrees_are_named():
    with pytest.raises(ParameterError, match=re.escape("port.tilt_y_deg must be finite, got nan")):
        FlatPort.from_degrees(distance_m=0.05, tilt_y_deg=float("nan"))


@pytest.mark.parametrize(
    ("normal", "pattern"),
    [
        ((0.0, 0.0, 0.0), "normal must be a finite non-zero 3-vector"),
        ((0.0, float("nan"), 1.0), "normal must be a finite non-zero 3-vector"),
        ((0.0, 1.0), "normal must be a finite non-zero 3-vector"),
        ((0.0, 0.5, -1.0), "points towards the camera"),
        ((1.0, 0.0, 0.0), "points towards the camera"),
    ],
)
def test_bad_normals(normal, pattern):
    with pytest.raises(ParameterError, match=pattern):
        FlatPort.from_normal(normal, distance_m=0.05)


def test_from_dict_forms_and_unknown_keys():
    deg = FlatPort.from_dict({"distance_m": 0.05, "tilt_x_deg": 30.0, "n_water": 1.34})
    np.testing.assert_allclose(deg.normal, (0.0, -0.5, math.sqrt(3.0) / 2.0), rtol=0, atol=FLOAT64_UNIT)
    assert deg.n_water == 1.34
    rad = FlatPort.from_dict({"distance_m": 0.05, "tilt_y_rad": math.pi / 6})
    np.testing.assert_allclose(rad.normal, (0.5, 0.0, math.sqrt(3.0) / 2.0), rtol=0, atol=FLOAT64_UNIT)

    with pytest.raises(ParameterError, match=r"unknown key\(s\) in port: \['tilt_z_deg'\]"):
        FlatPort.from_dict({"distance_m": 0.05, "tilt_z_deg": 3.0})
    with pytest.raises(ParameterError, match=r"unknown key\(s\) in port: \['thickness'\]"):
        FlatPort.from_dict({"distance_m": 0.05, "thickness": 0.01})
    # Mixing degrees and radians is ambiguous and refused.
    with pytest.raises(ParameterError, match="tilt_y_rad"):
        FlatPort.from_dict({"distance_m": 0.05, "tilt_x_deg": 3.0, "tilt_y_rad": 0.1})


def test_to_dict_reports_normal_and_tilt():
    port = FlatPort.from_degrees(distance_m=0.05, thickness_m=0.002, tilt_x_deg=30.0)
    data = port.to_dict()
    np.testing.assert_allclose(data["normal"], (0.0, -0.5, math.sqrt(3.0) / 2.0), rtol=0, atol=FLOAT64_UNIT)
    assert data["total_tilt_deg"] == pytest.approx(30.0, abs=FLOAT64_ANGLE_DEG)
    assert data["tilt_x_rad"] == pytest.approx(math.pi / 6, abs=FLOAT64_ANGLE_RAD)
    assert data["distance_m"] == 0.05
    assert data["thickness_m"] == 0.002


@pytest.mark.parametrize(
    ("origins", "directions", "pattern"),
    [
        (np.zeros((2, 3)), np.tile([0.0, 0.0, 2.0], (2, 1)), "directions_cam must be unit vectors, got a norm of"),
        (np.zeros((2, 3)), np.tile([0.0, 0.0, 1.0], (3, 1)), "must have the same shape, got (2, 3) and (3, 3)"),
        (np.zeros((2, 2)), np.tile([0.0, 0.0, 1.0], (2, 1)), "origins_cam must have shape (N, 3), got shape (2, 2)"),
        (np.zeros(3), [[0.0, float("nan"), 1.0]], "directions_cam must be finite, got a row [0.0, nan, 1.0]"),
        ([[0.0, 0.0, float("inf")]], [0.0, 0.0, 1.0], "origins_cam must be finite"),
    ],
)
def test_bad_rays(origins, directions, pattern):
    port = FlatPort(distance_m=0.05)
    with pytest.raises(ParameterError, match=re.escape(pattern)) as from_air:
        port.trace_from_air(origins, directions)
    with pytest.raises(ParameterError, match=re.escape(pattern)):
        port.trace_from_water(origins, directions)
    if "norm" in pattern:
        assert "2.0" in str(from_air.value)


def test_bad_aperture_radius_for_clearance():
    with pytest.raises(ParameterError, match=re.escape("aperture_radius_m must be positive, got -1.0")):
        FlatPort(distance_m=0.05).clearance_m(-1.0)


def test_from_dict_reads_to_dict_back():
    port = FlatPort.from_degrees(distance_m=0.0592, thickness_m=0.003, tilt_x_deg=-26.6, tilt_y_deg=0.5, n_water=1.33)
    data = port.to_dict()
    assert FlatPort.from_dict(data) == port
    # A sidecar whose derived normal disagrees with its tilt angles is refused, not repaired.
    with pytest.raises(ParameterError, match=re.escape("port.normal=[0.0, 0.0, 1.0] disagrees with the tilt angles")):
        FlatPort.from_dict({**data, "normal": [0.0, 0.0, 1.0]})


# =============================================================================== hostile input (issue 12)
@pytest.mark.parametrize(
    ("kwargs", "pattern"),
    [
        ({"n_glass": 1e300, "thickness_m": 0.01}, "port.n_glass=1e+300 is not the refractive index of a real medium"),
        ({"n_water": 0.5}, "port.n_water=0.5 is not the refractive index of a real medium"),
        ({"n_air": 0.999}, "port.n_air=0.999 is not the refractive index of a real medium"),
        ({"n_glass": 5.01}, "port.n_glass=5.01 is not the refractive index of a real medium"),
        ({"distance_m": 1e300}, "port.distance_m=1e+300 exceeds 100.0 m"),
        ({"distance_m": 100.5}, "port.distance_m=100.5 exceeds 100.0 m"),
        ({"thickness_m": 1e300}, "port.thickness_m=1e+300 exceeds 1.0 m"),
        ({"thickness_m": 1.5}, "port.thickness_m=1.5 exceeds 1.0 m"),
        # (pi, pi) is a second name for the optical axis; 1e300 rad is no angle at all.
        ({"tilt_x_rad": math.pi, "tilt_y_rad": math.pi}, f"port.tilt_x_rad={math.pi!r} is outside (-pi/2, pi/2)"),
        ({"tilt_x_rad": 0.0, "tilt_y_rad": 2 * math.pi}, f"port.tilt_y_rad={2 * math.pi!r} is outside (-pi/2, pi/2)"),
    ],
)
def test_port_fields_have_physical_ranges(kwargs, pattern):
    """Issue 12: n_glass = 1e300 reached fresnel_transmittance and raised OverflowError; every
    numeric field now has a range, enforced by every constructor."""
    data = {"distance_m": 0.05, **kwargs}
    with pytest.raises(ParameterError, match=re.escape(pattern)):
        FlatPort(**data)
    with pytest.raises(ParameterError, match=re.escape(pattern)):
        FlatPort.from_dict(data)
    if "tilt_x_rad" not in kwargs:
        with pytest.raises(ParameterError, match=re.escape(pattern)):
            FlatPort.from_degrees(**data)
        with pytest.raises(ParameterError, match=re.escape(pattern)):
            FlatPort.from_dict({**data, "tilt_x_deg": 10.0})
        with pytest.raises(ParameterError, match=re.escape(pattern)):
            FlatPort.from_normal([0.1, -0.2, 1.0], **data)


def test_port_range_limits_are_accepted():
    for n in (N_MIN, N_MAX):
        port = FlatPort(distance_m=MAX_DISTANCE_M, thickness_m=MAX_THICKNESS_M, n_air=n, n_glass=n, n_water=n)
        assert port.trace_from_air(np.zeros(3), port.normal).valid[0]
    edge = math.pi / 2 - 1e-6
    assert FlatPort(distance_m=0.05, tilt_x_rad=edge).normal[2] == pytest.approx(1e-6, rel=1e-6)
    # from_normal's angles always lie inside the range, also for normals close to the face.
    port = FlatPort.from_normal([-1.0, 0.5, 1e-3], distance_m=0.05)
    assert abs(port.tilt_x_rad) < math.pi / 2
    assert abs(port.tilt_y_rad) < math.pi / 2


def test_refract_and_fresnel_refuse_impossible_indices_and_cosines():
    """Issue 12: fresnel_transmittance(cos, 1e300, 1.0) raised OverflowError (eta ** 2)."""
    d = np.array([[0.0, 0.0, 1.0]])
    with pytest.raises(ParameterError, match=re.escape("n_from=1e+300 is not the refractive index of a real medium")):
        fresnel_transmittance(np.array([0.5]), 1e300, 1.0)
    with pytest.raises(ParameterError, match=re.escape("n_to=0.5 is not the refractive index of a real medium")):
        fresnel_transmittance(np.array([0.5]), 1.0, 0.5)
    with pytest.raises(ParameterError, match=re.escape("n_from=1e-300 is not the refractive index")):
        refract(d, d[0], 1e-300, 1.5)
    with pytest.raises(ParameterError, match=re.escape("n_to must be finite, got nan")):
        refract(d, d[0], 1.0, float("nan"))
    with pytest.raises(ParameterError, match=re.escape("cos_i must be finite cosines in [-1, 1], got nan")):
        fresnel_transmittance(np.array([0.5, float("nan")]), 1.0, 1.5)
    with pytest.raises(ParameterError, match=re.escape("cos_i must be finite cosines in [-1, 1], got 2.0")):
        fresnel_transmittance(np.array([2.0]), 1.0, 1.5)


@pytest.mark.parametrize("cos", [0.0, 1e-300, 1e-10, 9.9e-7])
def test_grazing_rays_are_misses_not_nan(cos):
    """Issue 12: a ray at cos 1e-10 to the normal was valid with an infinite exit point (the
    refracted cosine rounded to 0, so the ray ran along the glass). Below GRAZING_COS_MIN a ray
    does not reach the face; from either side."""
    port = FlatPort(distance_m=0.02, thickness_m=0.006, n_air=1.0, n_glass=1.0, n_water=1.0)
    sin = math.sqrt(1.0 - cos * cos)
    fwd = port.trace_from_air([[0.0, 0.0, 0.0]], [[0.0, sin, cos]])
    back = port.trace_from_water([[0.0, 0.0, 0.5]], [[0.0, sin, -cos]])
    for tr in (fwd, back):
        np.testing.assert_array_equal(tr.misses, [True])
        np.testing.assert_array_equal(tr.valid, [False])
        assert np.all(np.isnan(tr.exit_points_cam))
        assert np.all(np.isnan(tr.directions_cam))
        assert tr.transmittance[0] == 0.0


def test_the_exact_grazing_repro_of_issue_12():
    port = FlatPort(distance_m=0.02, thickness_m=0.006, n_air=1, n_glass=1, n_water=1)
    tr = port.trace_from_air([[0, 0, 0]], [[0, 1, 1e-10]])
    assert not tr.valid[0]
    assert tr.misses[0]


def test_rays_just_above_grazing_stay_valid_and_exact():
    """cos = 1e-5 and 1.0001e-6: valid, and with equal indices on the straight line to 1e-9 of
    the distance travelled (GRAZING_COS_MIN's precision argument)."""
    port = FlatPort(distance_m=0.02, thickness_m=0.006, n_air=1.0, n_glass=1.0, n_water=1.0)
    cos = np.array([1e-5, 1.0001 * GRAZING_COS_MIN])
    d = np.stack([np.zeros(2), np.sqrt(1.0 - cos**2), cos], axis=1)
    tr = port.trace_from_air(np.zeros((2, 3)), d)
    assert tr.valid.all()
    np.testing.assert_allclose(tr.directions_cam, d, rtol=0, atol=FLOAT64_UNIT)
    reach = np.linalg.norm(tr.exit_points_cam, axis=1)
    np.testing.assert_allclose(reach, 0.026 / cos, rtol=PORT_REVERSAL_RELATIVE)
    assert np.all(distance_point_to_line(tr.exit_points_cam, np.zeros(3), d) <= PORT_REVERSAL_RELATIVE * reach)


def test_refraction_into_the_glass_at_the_critical_angle_is_flagged():
    """Dense air into light glass exactly at the critical sine: the refracted ray runs along the
    face and never reaches the water face (it was valid with an infinite exit point)."""
    port = FlatPort(distance_m=0.05, thickness_m=0.01, n_air=1.5, n_glass=1.0, n_water=1.0)
    sines = (1.0 / 1.5) * (1.0 + np.array([-1e-9, 0.0, 1e-16, 1e-9]))
    d = np.stack([sines, np.zeros(4), np.sqrt(1.0 - sines**2)], axis=1)
    tr = port.trace_from_air(np.zeros((4, 3)), d)
    np.testing.assert_array_equal(tr.valid, [True, False, False, False])
    np.testing.assert_array_equal(tr.tir, [False, False, False, True])
    assert not (tr.tir & tr.misses).any()
    assert np.all(np.isfinite(tr.exit_points_cam[tr.valid]))


def test_overflowing_origins_are_flagged_not_infinite():
    """Origins are only required to be finite; one at 1.5e308 m overflowed to an infinite entry
    point on a valid ray."""
    tr = FlatPort(distance_m=0.05).trace_from_air([[0.0, 1.5e308, -1e308]], [[0.0, 0.6, 0.8]])
    assert not tr.valid[0]
    assert tr.misses[0]


def test_a_port_seen_from_another_origin_keeps_its_faces_where_they_are():
    """The same plane from a frame whose origin sits at ``o``: ``n . (X - o) = d - n . o``; a point on
    the face stays on it, and moving back returns the port."""
    port = FlatPort.from_degrees(distance_m=0.02, thickness_m=0.004, tilt_x_deg=20.0, tilt_y_deg=-7.0)
    origin = np.array([0.001, -0.002, -0.0005])
    moved = port.seen_from(origin)
    on_face = port.normal * port.distance_m + np.cross(port.normal, [1.0, 0.0, 0.0]) * 0.01
    assert float(moved.normal @ (on_face - origin)) == pytest.approx(moved.distance_m, abs=1e-15)
    assert (moved.tilt_x_rad, moved.tilt_y_rad, moved.thickness_m) == (port.tilt_x_rad, port.tilt_y_rad, 0.004)
    assert moved.seen_from(-origin).distance_m == pytest.approx(port.distance_m, abs=1e-15)
    with pytest.raises(ParameterError, match="origin_cam must have 3 entries"):
        port.seen_from([0.0, 0.0])
    with pytest.raises(ParameterError, match="distance_m"):  # from beyond its face
        port.seen_from(port.normal * 0.03)
