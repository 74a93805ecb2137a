"""Rigid camera poses: camera-to-world transforms and their construction from config data."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from lfrefract import ParameterError, Pose
from lfrefract.optics.pose import rotation_from_euler_xyz
from tests.tolerances import FLOAT64_GEOMETRY_M, FLOAT64_UNIT

angles_deg = st.tuples(*(st.floats(-360.0, 360.0) for _ in range(3)))
positions = st.tuples(*(st.floats(-10.0, 10.0) for _ in range(3)))
point_sets = hnp.arrays(np.float64, (8, 3), elements=st.floats(-5.0, 5.0))


@given(angles=angles_deg, position=positions, points=point_sets)
def test_round_trip_preserves_points_and_distances(angles, position, points):
    pose = Pose.from_euler_xyz_deg(angles, position)
    world = pose.to_world(points)
    np.testing.assert_allclose(pose.to_camera(world), points, rtol=0, atol=FLOAT64_GEOMETRY_M * 10)
    # Rigid: pairwise distances are kept, and the camera centre maps to the position.
    np.testing.assert_allclose(
        np.linalg.norm(world[:, None] - world[None], axis=2),
        np.linalg.norm(points[:, None] - points[None], axis=2),
        rtol=0,
        atol=FLOAT64_GEOMETRY_M * 10,
    )
    np.testing.assert_allclose(pose.to_world(np.zeros(3))[0], position, rtol=0, atol=FLOAT64_GEOMETRY_M * 10)
    r = np.asarray(pose.rotation)
    np.testing.assert_allclose(r @ r.T, np.eye(3), rtol=0, atol=FLOAT64_UNIT)
    assert np.linalg.det(r) == pytest.approx(1.0, abs=FLOAT64_UNIT)


def test_ninety_degrees_about_z_maps_x_to_y():
    pose = Pose.from_euler_xyz_deg((0.0, 0.0, 90.0), (1.0, 2.0, 3.0))
    np.testing.assert_allclose(
        pose.to_world([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]),
        [[1.0, 3.0, 3.0], [0.0, 2.0, 3.0], [1.0, 2.0, 4.0]],
        rtol=0,
        atol=FLOAT64_GEOMETRY_M,
    )
    np.testing.assert_allclose(pose.to_camera([[1.0, 3.0, 3.0]]), [[1.0, 0.0, 0.0]], rtol=0, atol=FLOAT64_GEOMETRY_M)


def test_extrinsic_xyz_order():
    # Extrinsic x then y: y -> z (90 deg about x) -> x (90 deg about y).
    r = rotation_from_euler_xyz((math.pi / 2, math.pi / 2, 0.0))
    np.testing.assert_allclose(r @ [0.0, 1.0, 0.0], [1.0, 0.0, 0.0], rtol=0, atol=FLOAT64_UNIT)
    # The other order would send y -> y -> z; check x as well: x -> x -> -z.
    np.testing.assert_allclose(r @ [1.0, 0.0, 0.0], [0.0, 0.0, -1.0], rtol=0, atol=FLOAT64_UNIT)


def test_matrix_is_homogeneous_camera_to_world():
    pose = Pose.from_euler_xyz_deg((10.0, -20.0, 30.0), (0.5, -0.25, 2.0))
    m = pose.matrix
    np.testing.assert_array_equal(m[3], [0.0, 0.0, 0.0, 1.0])
    p = np.array([0.1, 0.2, 0.3])
    np.testing.assert_allclose((m @ np.append(p, 1.0))[:3], pose.to_world(p)[0], rtol=0, atol=FLOAT64_GEOMETRY_M)


def test_improper_and_non_orthonormal_rotations_are_rejected():
    with pytest.raises(ParameterError, match=re.escape("pose.rotation must be a proper rotation")):
        Pose(rotation=((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, -1.0)))
    with pytest.raises(ParameterError, match=re.escape("pose.rotation must be a proper rotation, got [[2.0, 0.0")):
        Pose(rotation=((2.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)))
    with pytest.raises(ParameterError, match=re.escape("pose.rotation must be a finite 3x3 matrix")):
        Pose(rotation=((1.0, 0.0), (0.0, 1.0)))
    with pytest.raises(ParameterError, match=re.escape("pose.rotation must be a finite 3x3 matrix")):
        Pose(rotation=((float("nan"), 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)))


def test_bad_positions_and_angles_are_named():
    with pytest.raises(ParameterError, match=re.escape("pose.position_m[2] must be finite, got inf")):
        Pose(position_m=(0.0, 0.0, float("inf")))
    with pytest.raises(ParameterError, match=re.escape("pose.rotation_xyz_deg must have 3 entries, got (1.0, 2.0)")):
        Pose.from_euler_xyz_deg((1.0, 2.0))
    with pytest.raises(ParameterError, match=re.escape("points_cam must have shape (N, 3), got shape (2, 2)")):
        Pose().to_world(np.zeros((2, 2)))


def test_dict_forms():
    pose = Pose.from_dict({"rotation_xyz_deg": [0.0, 0.0, 90.0], "position_m": [1.0, 2.0, 3.0]})
    np.testing.assert_allclose(pose.to_world([1.0, 0.0, 0.0]), [[1.0, 3.0, 3.0]], rtol=0, atol=FLOAT64_GEOMETRY_M)
    again = Pose.from_dict(pose.to_dict())
    assert again == pose
    with pytest.raises(ParameterError, match=r"unknown key\(s\) in pose: \['scale'\]"):
        Pose.from_dict({"rotation_xyz_deg": [0, 0, 0], "scale": 2})
    with pytest.raises(ParameterError, match=r"unknown key\(s\) in pose: \['rotation_xyz_deg'\]"):
        Pose.from_dict({"rotation": pose.to_dict()["rotation"], "rotation_xyz_deg": [0, 0, 0]})
