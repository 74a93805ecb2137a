"""The rig experiments' shared parts (simulator/experiments/rigstereo.py) that need no render."""

from __future__ import annotations

import numpy as np
import pytest

from lfrefract import ParameterError
from simulator.boards import CALIBRATION_ROTATIONS_DEG, SQUARES
from simulator.config import Chessboard
from simulator.experiments import ExperimentOptions
from simulator.experiments.rigstereo import (
    LIGHTS,
    MATCHERS,
    RigSetup,
    aim,
    chessboards,
    exact_coverage,
    experiment_rig,
    match,
    warp_maps,
    with_objects,
)
from simulator.rig import load_rig

SETUP = RigSetup(rig="default", calibration_depths_m=(0.3, 0.6), px_per_square=10.0, spp=16)


@pytest.fixture(scope="module")
def rig_and_warps():
    rig = experiment_rig(SETUP)
    return rig, warp_maps(rig)


def _left_frame(rig, points_world: np.ndarray) -> np.ndarray:
    return rig.cameras[0].scene.pose.to_camera(points_world)


def test_exact_coverage_is_the_cameras_exact_pixels(rig_and_warps):
    rig, warps = rig_and_warps
    # Where both cameras look (the experiments' aim) is exact on the default rig; far to the side
    # (30 deg, outside both images) and behind the cameras is not.
    ahead = _left_frame(rig, np.array([aim(rig, 0.45)]))
    aside = _left_frame(rig, np.array([[0.5 * np.tan(np.radians(30)), 0.0, 0.5]]))
    behind = np.array([[0.0, 0.0, -0.5]])
    inside = exact_coverage(np.concatenate([ahead, aside, behind]), rig, warps)
    assert inside.tolist() == [True, False, False]
    # Points that project onto exact pixels of the left view and of the right view are inside, and
    # only they: check a grid of directions against the warp maps directly.
    left = rig.cameras[0]
    output = warps[left.name].output
    directions = output.pixel_directions()
    points = directions * (0.45 / directions[:, 2:3])
    result = exact_coverage(points, rig, warps)
    assert result.shape == (len(points),)
    assert not np.any(result & ~warps[left.name].exact.ravel())  # never outside the left's exact pixels
    assert 0.1 < result.mean() < warps[left.name].exact.mean()  # the right camera cuts some away


def test_match_dispatches_and_refuses_unknown_matchers():
    rng = np.random.default_rng(0)
    texture = rng.random((40, 80)).astype(np.float32)
    left, right = texture[:, :64], texture[:, 4:68]  # x_left - x_right = 4 px everywhere
    for matcher in MATCHERS:
        disparity = match(matcher, left, right, min_disparity_px=0, num_disparities=8)
        assert np.nanmedian(disparity) == pytest.approx(4.0, abs=0.25), matcher
    with pytest.raises(ParameterError, match="matcher must be one of"):
        match("census", left, right, min_disparity_px=0, num_disparities=8)


def test_experiment_rig_is_typed_and_takes_the_options():
    """The embedded rig with the experiment's lights and render settings; the options replace the
    cameras' optics and move the wall, and every camera's port follows the moved wall."""
    rig = experiment_rig(SETUP)
    embedded = load_rig("default")
    assert [c.name for c in rig.cameras] == [c.name for c in embedded.cameras]
    for camera, original in zip(rig.cameras, embedded.cameras, strict=True):
        assert camera.scene.lights == LIGHTS
        assert camera.scene.objects == ()
        assert camera.scene.render.spp == SETUP.spp
        assert camera.scene.port == original.scene.port
    moved = experiment_rig(SETUP, ExperimentOptions(camera="tiny", port_distance_m=0.03, thickness_m=0.002))
    assert moved.wall.distance_m == 0.03
    assert moved.wall.thickness_m == 0.002
    for camera in moved.cameras:
        assert camera.scene.camera.name == "tiny"
        assert camera.scene.port == moved.wall.port_for(camera.scene.pose)
        assert camera.scene.port.thickness_m == 0.002
    with pytest.raises(ParameterError, match="thickness_m"):
        experiment_rig(SETUP, ExperimentOptions(thickness_m=0.0))  # a wall is glass


def test_chessboards_are_typed_boards_on_the_line_of_sight():
    rig = experiment_rig(SETUP)
    boards = chessboards(rig, SETUP, 0.45)
    assert all(isinstance(b, Chessboard) and b.squares == SQUARES for b in boards)
    assert [b.placement.rotation_xyz_deg for b in boards] == [tuple(map(float, r)) for r in CALIBRATION_ROTATIONS_DEG]
    centre = np.mean([b.placement.position_m for b in boards], axis=0)
    assert np.allclose(centre[2], 0.45)
    placed = with_objects(rig, boards[:1])
    assert all(c.scene.objects == boards[:1] for c in placed.cameras)
