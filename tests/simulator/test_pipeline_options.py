"""``lfsim experiment pipeline``'s port and ray-model options: checked at the boundary (errors name the
flag and value), turning the rig's wall by the port's tilt convention, and keying the kept renders.

Nothing here renders: the options are checked before any work, and a kept render's key is its scene.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from lfrefract import camera_preset
from lfrefract.errors import ParameterError
from lfrefract.optics.pinhole import virtual_camera_for
from lfrefract.optics.real_lens import RealLensCamera
from simulator import boards as board_scenes
from simulator import cli as sim_cli
from simulator.config import lens_option
from simulator.experiments import OPTION_FLAGS, ExperimentOptions, load_experiments
from simulator.experiments.kept import differs, keep
from simulator.experiments.pipeline import (
    _air_board_scene,
    _origins,
    _port_board_scene,
    _port_errors,
    _with_sensor,
    real_rig,
    row_label,
    scene_signature,
    setup_for_pipeline,
    synthesis_methods,
)
from simulator.experiments.rigstereo import (
    WALL_OPTIONS,
    capture_signature,
    chessboards,
    experiment_rig,
    wall_with_options,
    with_objects,
)
from tests.tolerances import FLOAT64_ANGLE_DEG, FLOAT64_UNIT

SETUP = setup_for_pipeline("tiny")
NEW_FLAGS = ("--port-tilt-x-deg", "--port-tilt-y-deg", "--n-glass", "--n-water", "--ray-model")


def _tilts_deg(port) -> tuple[float, float]:
    return math.degrees(port.tilt_x_rad), math.degrees(port.tilt_y_rad)


def test_the_pipeline_takes_the_port_and_ray_model_options_and_others_refuse_them(tmp_path, capsys):
    pipeline = load_experiments()["pipeline"]
    assert {OPTION_FLAGS[o] for o in pipeline.options} >= {"--port-distance-m", "--thickness-m", *NEW_FLAGS}
    out = tmp_path / "x"
    assert sim_cli.main(["experiment", "planes", "--out", str(out), "--ray-model", "polynomial"]) == 2
    assert (
        "option --ray-model (ray_model='polynomial') does not apply to experiment 'planes'" in capsys.readouterr().err
    )
    assert not out.exists()


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--port-tilt-x-deg", "90"], "--port-tilt-x-deg: port_tilt_x_deg must lie in (-90, 90) deg, got 90"),
        (["--port-tilt-y-deg=-95"], "--port-tilt-y-deg: port_tilt_y_deg must lie in (-90, 90) deg, got -95"),
        (["--port-tilt-y-deg=nan"], "--port-tilt-y-deg: port_tilt_y_deg must be finite, got nan"),
        (["--n-glass", "0.5"], "--n-glass: n_glass must lie in [1, 5], got 0.5"),
        (["--n-water", "13.3"], "--n-water: n_water must lie in [1, 5], got 13.3"),
        (["--ray-model", "spline"], "--ray-model: ray_model must be one of ['radial', 'polynomial'], got 'spline'"),
        # a method of the registry, but not one of lfrefract synth's
        (
            ["--methods", "depth-aware,ideal"],
            "--methods: the pipeline synthesizes with lfrefract synth's methods ['proposed', 'depth-aware'], "
            "got 'ideal'",
        ),
        # Valid each, but the wall turned 80 deg about y passes between the right camera and the rig's origin:
        # 15 mm - 30 mm sin(80 deg) = -14.54 mm.
        (
            ["--port-tilt-x-deg", "0", "--port-tilt-y-deg", "80"],
            "--port-tilt-x-deg, --port-tilt-y-deg: camera at position_m=[0.03, 0.0, 0.0] is 14.54 mm on the water side",
        ),
    ],
)
def test_invalid_port_and_ray_model_values_name_the_flag_before_any_work(tmp_path, capsys, argv, message):
    out = tmp_path / "x"
    assert sim_cli.main(["experiment", "pipeline", "--out", str(out), "--quiet", *argv]) == 2
    err = capsys.readouterr().err
    assert message in err
    assert "--lens" not in err  # the experiment's own lens is not the user's
    assert not out.exists()


def test_the_chains_synthesize_with_the_methods_given_each_its_own_rows():
    assert synthesis_methods(ExperimentOptions()) == ("proposed",)
    assert synthesis_methods(ExperimentOptions(methods=["depth-aware", "proposed"])) == (
        "depth-aware",
        "proposed",
    )
    assert [row_label(chain, "proposed") for chain in ("oracle", "data-only")] == ["oracle", "data-only"]
    assert row_label("data-only", "depth-aware") == "data-only depth-aware"


def test_a_runs_options_are_read_back_from_its_meta_json_lens_design_and_camera_included():
    """A run's meta.json records a lens design and a camera as tables (what the benchmarks that take a
    run folder read back); a preset's name stays a name."""
    design = lens_option(str(Path(__file__).resolve().parents[2] / "scenes" / "lenses" / "tessar.toml"))
    camera = camera_preset("tiny-2x")
    options = ExperimentOptions(lens=design, camera=camera, port_tilt_x_deg=20.0, methods=["proposed"])
    back = ExperimentOptions.from_dict(json.loads(json.dumps(options.to_dict())))
    assert back == options
    assert ExperimentOptions.from_dict(ExperimentOptions(lens="double-gauss").to_dict()).lens == "double-gauss"
    with pytest.raises(ParameterError, match=r"unknown keys \['tilt'\]"):
        ExperimentOptions.from_dict({"tilt": 3})


def test_options_hold_the_checked_values():
    options = ExperimentOptions(
        port_tilt_x_deg=20, port_tilt_y_deg=10, n_glass=1.52, n_water=1.34, ray_model="polynomial"
    )
    assert (options.port_tilt_x_deg, options.port_tilt_y_deg) == (20.0, 10.0)
    assert options.given() == ("port_tilt_x_deg", "port_tilt_y_deg", "n_glass", "n_water", "ray_model")
    assert options.to_dict()["ray_model"] == "polynomial"
    with pytest.raises(ParameterError, match="ray_model must be one of"):
        ExperimentOptions(ray_model="Radial")


def test_no_option_keeps_the_rig_as_it_was():
    rig = experiment_rig(SETUP.rig)
    assert wall_with_options(rig.wall, ExperimentOptions()) is rig.wall
    assert experiment_rig(SETUP.rig, ExperimentOptions(ray_model="polynomial")) == rig


def test_the_wall_turns_by_the_ports_tilt_convention_and_each_camera_sees_it_through_its_pose():
    """The tiny rig's cameras are turned 3 deg inwards about y (left +3, right -3), so a wall turned 10 deg
    about y is, in their frames, a port turned 7 and 13 deg, at 20 deg about x for both (rotations about
    y compose); the normal is R_y(10) R_x(20) (0, 0, 1) in the rig's frame."""
    rig = experiment_rig(SETUP.rig, ExperimentOptions(port_tilt_x_deg=20.0, port_tilt_y_deg=10.0))
    tx, ty = math.radians(20.0), math.radians(10.0)
    expected = [math.sin(ty) * math.cos(tx), -math.sin(tx), math.cos(ty) * math.cos(tx)]
    np.testing.assert_allclose(rig.wall.normal, expected, atol=FLOAT64_UNIT)
    tilts = {c.name: _tilts_deg(c.scene.port) for c in rig.cameras}
    np.testing.assert_allclose(tilts["left"], (20.0, 7.0), atol=FLOAT64_ANGLE_DEG)
    np.testing.assert_allclose(tilts["right"], (20.0, 13.0), atol=FLOAT64_ANGLE_DEG)


def test_a_tilt_left_out_keeps_the_rigs_own_and_the_indices_reach_every_port():
    own = experiment_rig(SETUP.rig)
    options = ExperimentOptions(port_tilt_y_deg=-5.0, n_glass=1.52, n_water=1.34)
    rig = experiment_rig(SETUP.rig, options)
    for before, after in zip(own.cameras, rig.cameras, strict=True):
        (x0, y0), (x1, y1) = _tilts_deg(before.scene.port), _tilts_deg(after.scene.port)
        assert x1 == pytest.approx(x0, abs=FLOAT64_ANGLE_DEG)  # the rig's 20 deg about x
        assert y1 - y0 == pytest.approx(-5.0, abs=FLOAT64_ANGLE_DEG)
        assert (after.scene.port.n_glass, after.scene.port.n_water) == (1.52, 1.34)
    assert (rig.wall.distance_m, rig.wall.thickness_m) == (own.wall.distance_m, own.wall.thickness_m)


def test_the_data_only_chain_is_measured_where_a_calibration_puts_the_camera():
    """A calibration from boards in air reports a real lens's camera with its origin at the paraxial
    entrance pupil (0.5 mm behind the simulator's origin for the double Gauss): a port calibrated
    without error reads 0 there, and about 0.48 mm long (0.514 mm times the normal's z) in the
    simulator's frame, which the thin-lens chains keep."""
    real = real_rig(SETUP, ExperimentOptions(lens="double-gauss", port_tilt_x_deg=20.0, port_tilt_y_deg=10.0))
    moved, kept = _origins(real, moved=True), _origins(real, moved=False)
    for camera in real.cameras:
        pupil = RealLensCamera(camera=camera.scene.camera, lens=camera.scene.lens).first_order.entrance_pupil_z_m
        np.testing.assert_allclose(moved[camera.name], [0.0, 0.0, pupil], atol=FLOAT64_UNIT)
        assert pupil == pytest.approx(-0.514e-3, abs=1e-6)
        assert not np.any(kept[camera.name])
    # each camera's true port as a flawless calibration reports it: from its entrance pupil
    reported = {c.name: c.scene.port.seen_from(c.scene.calibration_origin_cam) for c in real.cameras}
    angle_deg, distance_mm = _port_errors(reported, real, moved)
    assert angle_deg < 1e-5  # arccos of a unit dot product: about 1e-6 deg of rounding
    assert distance_mm == pytest.approx(0.0, abs=1e-9)
    _, distance_mm = _port_errors(reported, real, kept)
    expected = max(-c.scene.port.normal[2] * moved[c.name][2] for c in real.cameras) * 1e3
    assert distance_mm == pytest.approx(expected, rel=1e-9)
    assert 0.45 < distance_mm < 0.52


@pytest.mark.parametrize("option", [*WALL_OPTIONS, "port_distance_m", "thickness_m"])
def test_a_kept_render_is_not_reused_behind_another_port(tmp_path, option):
    """Each port option changes the key of the kept rig captures and port boards (rendered again), not
    that of the in-air boards (no port in them: reused)."""
    value = {"port_tilt_x_deg": 25.0, "port_tilt_y_deg": 10.0, "n_glass": 1.52, "n_water": 1.34}
    value |= {"port_distance_m": 0.02, "thickness_m": 0.006}
    keys = {}
    for name, options in (("own", ExperimentOptions()), ("moved", ExperimentOptions(**{option: value[option]}))):
        rig = _with_sensor(experiment_rig(SETUP.rig, options), SETUP.sensor)  # as the pipeline's real captures
        camera = rig.cameras[0].scene
        table = board_scenes.port_boards(camera.port, virtual_camera_for(camera.camera))[0]
        air = board_scenes.in_air_boards(virtual_camera_for(camera.camera))[0]
        keys[name] = {
            "rig": capture_signature(with_objects(rig, chessboards(rig, SETUP.rig, 0.3)[:1]), write_lfr=True),
            "port": scene_signature(_port_board_scene(camera, table, spp=8, seed=1, frames=2)),
            "air": scene_signature(_air_board_scene(air, camera, "double-gauss", spp=8, seed=1, frames=2)),
        }
    for kind, reused in (("rig", False), ("port", False), ("air", True)):
        folder = tmp_path / kind
        folder.mkdir()
        keep(folder, keys["own"][kind])
        assert differs(folder, keys["own"][kind]) is None
        assert differs(folder, keys["moved"][kind]) == (None if reused else "rendered for another scene"), kind


def test_a_failing_synthesis_method_fails_its_own_rows_only(tmp_path):
    """``--methods proposed,depth-aware``: a depth-aware synth that failed on one capture (the
    retrofocus design, whose white lights 13 % of the rays fully) failed the whole data-only chain, so
    the proposed rows of its calibrated ports were lost too. It now fails the depth-aware rows alone."""
    from simulator.experiments.pipeline import _Models, _synth_all

    calls = []

    def core(*args):
        calls.append(args)
        if "depth-aware" in args:
            raise RuntimeError("lfrefract synth: no output pixel has a depth")

    models = _Models()
    captures = {"board-0": tmp_path / "board-0.lfr", "board-1": tmp_path / "board-1.lfr"}
    _synth_all(core, captures, [], tmp_path, "data-only", "left", ("proposed", "depth-aware"), models)
    assert len(calls) == 3  # both proposed, the first depth-aware
    assert models.error is None
    assert models.error_of("proposed") is None
    assert models.error_of("depth-aware").startswith("left: RuntimeError: lfrefract synth: no output pixel has a depth")
    models.fail("right", ValueError("no board"))
    assert models.error_of("proposed").startswith("right: ValueError: no board")
