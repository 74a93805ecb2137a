"""Stereo rigs (simulator/rig.py): each camera's port derived from the one wall, the stereo ground
truth, and a rendered rig whose two depth maps agree about the world."""

from __future__ import annotations

import numpy as np
import pytest

from lfrefract import FlatPort, ParameterError, PinholeCamera, Pose
from lfrefract.formats.capture import DEPTH_NAME, read_capture, read_ground_truth
from lfrefract.formats.exr import read_exr
from lfrefract.formats.jsonio import read_json
from simulator import cli as sim_cli
from simulator.rig import Wall, embedded_rigs, load_rig, parse_rig
from tests.tolerances import FLOAT64_GEOMETRY_M, RIG_DEPTH_AGREEMENT_RELATIVE

WALL = Wall(normal=(0.1, -0.3, 0.95), distance_m=0.03, thickness_m=0.005)
POSES = [
    Pose.from_euler_xyz_deg((0.0, 5.0, 0.0), (-0.03, 0.0, 0.0)),
    Pose.from_euler_xyz_deg((3.0, -8.0, 2.0), (0.04, 0.01, -0.005)),
]


def _rig_data(**changes) -> dict:
    data = {
        "wall": {"normal": [0.0, -0.2, 1.0], "distance_m": 0.02, "thickness_m": 0.006},
        "camera": [
            {"name": "left", "preset": "tiny", "position_m": [-0.03, 0, 0], "rotation_xyz_deg": [0, 5, 0]},
            {"name": "right", "preset": "tiny", "position_m": [0.03, 0, 0], "rotation_xyz_deg": [0, -5, 0]},
        ],
        "light": [{"type": "point", "position_m": [0.0, -0.2, 0.2], "intensity_w_sr": 0.5}],
        "object": [{"type": "textured_plane", "position_m": [0.0, 0.0, 0.6], "size_m": [1.0, 0.8]}],
    }
    data.update(changes)
    return data


@pytest.mark.parametrize("pose", POSES)
def test_each_camera_sees_the_one_wall_as_its_port(pose):
    port = WALL.port_for(pose)
    normal = np.asarray(WALL.normal)
    # Points on the wall's faces (world) lie on the port's faces (camera frame), and vice versa.
    rng = np.random.default_rng(0)
    in_plane = np.cross(normal, rng.normal(size=(20, 3)))
    for offset, port_offset in ((WALL.distance_m, port.distance_m), (WALL.distance_m + 0.005, port.distance_m + 0.005)):
        world = normal * offset + in_plane
        cam = pose.to_camera(world)
        np.testing.assert_allclose(cam @ port.normal, port_offset, atol=FLOAT64_GEOMETRY_M)
    assert port.thickness_m == WALL.thickness_m


def test_a_camera_in_the_water_is_refused():
    with pytest.raises(ParameterError, match="water side"):
        WALL.port_for(Pose.from_euler_xyz_deg((0, 0, 0), (0.0, 0.0, 0.1)))
    data = _rig_data()
    data["camera"][1]["position_m"] = [0.03, 0.0, 0.05]
    with pytest.raises(ParameterError, match=r"camera\[1\] \('right'\).*water side"):
        parse_rig(data)


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"camera": [{"name": "left", "preset": "tiny"}]}, "at least two"),
        ({"wall": {"normal": [0, 0, 1], "distance_m": 0.02}}, "thickness_m"),
        ({"wall": {"normal": [0, 0, 1], "distance_m": 0.02, "thickness_m": 0.006, "tilt": 3}}, "tilt"),
        ({"port": {}}, "port"),
    ],
)
def test_bad_rigs_are_rejected_before_rendering(changes, message):
    with pytest.raises(ParameterError, match=message):
        parse_rig(_rig_data(**changes))
    both = _rig_data()
    both["camera"][0]["optics"] = {}
    with pytest.raises(ParameterError, match="either preset or optics"):
        parse_rig(both)
    twins = _rig_data()
    twins["camera"][1]["name"] = "left"
    with pytest.raises(ParameterError, match="unique"):
        parse_rig(twins)


def test_a_camera_may_be_given_by_its_optics():
    optics = load_rig("default").cameras[0].scene.camera.to_dict()
    optics["focal_length_m"] = optics["lens_to_mla_m"] = 0.012
    data = _rig_data()
    data["camera"][1] = {k: v for k, v in data["camera"][1].items() if k != "preset"} | {"optics": optics}
    rig = parse_rig(data)
    assert rig.cameras[1].scene.camera.focal_length_m == 0.012
    assert rig.cameras[0].scene.camera.focal_length_m == 0.006


def test_relative_pose_maps_the_first_camera_frame_to_each_camera():
    rig = load_rig("default")
    assert set(embedded_rigs()) >= {"default"}
    points = np.random.default_rng(1).uniform(-0.3, 0.3, (10, 3)) + np.array([0.0, 0.0, 0.6])
    first = rig.cameras[0].scene.pose.to_camera(points)
    for index, camera in enumerate(rig.cameras):
        rotation, translation = rig.relative_pose(index)
        np.testing.assert_allclose(first @ rotation.T + translation, camera.scene.pose.to_camera(points), atol=1e-12)
    rotation, translation = rig.relative_pose(1)
    assert (-rotation.T @ translation)[0] > 0.05  # the second camera is to the right (+x) of the first
    assert rig.cameras[0].scene.port != rig.cameras[1].scene.port


@pytest.mark.render
def test_rendered_rig_depth_maps_agree_about_the_world(tmp_path, capsys):
    out = tmp_path / "rig"
    assert sim_cli.main(["rig", "--out", str(out), "--spp", "2", "--quiet", "--no-previews"]) == 0
    assert "rendered rig" in capsys.readouterr().out
    meta = read_json(out / "meta.json")
    assert meta["kind"] == "lfsim.rig"
    cams = {}
    for name, entry in meta["cameras"].items():
        sidecar = read_json(out / entry["folder"] / "meta.json")
        assert sidecar["pose"] == entry["pose"]
        assert sidecar["port"] == entry["port"]
        pose = Pose.from_dict(sidecar["pose"])
        capture = read_capture(out / entry["folder"])  # each camera's folder is a capture folder
        assert (capture.pose, capture.port) == (pose, FlatPort.from_dict(entry["port"]))
        assert capture.ideal == PinholeCamera.from_dict(sidecar["ideal"])
        depth = read_exr(out / name / DEPTH_NAME, role="depth")
        np.testing.assert_array_equal(read_ground_truth(out / name).depth_m, depth)
        cams[name] = (pose, PinholeCamera.from_dict(sidecar["ideal"]), read_exr(out / name / "depth.exr", role="depth"))
    (pose_l, view_l, depth_l), (pose_r, view_r, depth_r) = cams["left"], cams["right"]
    # Every surface point of the left depth map, seen by the right camera, is where its depth map says.
    v, u = np.nonzero(np.isfinite(depth_l))
    rays = view_l.pixel_directions(np.stack([u, v], axis=1))
    world = pose_l.to_world(rays / rays[:, 2:3] * depth_l[v, u][:, None])
    in_right = pose_r.to_camera(world)
    uv = np.rint(view_r.project(in_right)).astype(int)
    inside = (uv[:, 0] >= 0) & (uv[:, 0] < view_r.width_px) & (uv[:, 1] >= 0) & (uv[:, 1] < view_r.height_px)
    seen = depth_r[uv[inside, 1], uv[inside, 0]]
    relative = np.abs(seen - in_right[inside, 2]) / in_right[inside, 2]
    assert inside.mean() > 0.5
    assert np.nanmedian(relative) < RIG_DEPTH_AGREEMENT_RELATIVE


def test_rig_metadata_may_not_replace_the_rigs_own_keys(tmp_path):
    """``render_rig(..., metadata={"cameras": ...})`` silently replaced the rig's camera table in its meta.json."""
    from simulator.rig_render import render_rig

    for key in ("cameras", "kind", "wall"):
        with pytest.raises(ParameterError, match=rf"metadata may not set \['{key}'\]"):
            render_rig(load_rig(), tmp_path / "rig", metadata={key: 1})
    assert not (tmp_path / "rig").exists()
