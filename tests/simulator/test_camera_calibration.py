"""The camera's ray model calibrated from in-air chessboard light fields (lfrefract.calibration.camera),
scored against the simulator's true rays of a real main lens."""

from __future__ import annotations

import numpy as np
import pytest

from lfrefract import camera_preset, virtual_camera_for
from lfrefract import cli as core_cli
from lfrefract.calibration import (
    board_view_from_light_field,
    calibrate_camera,
    calibrate_port,
    calibrate_port_and_camera,
)
from lfrefract.calibration.camera import corrected_view
from lfrefract.errors import CalibrationError
from lfrefract.formats.jsonio import read_json, write_json
from lfrefract.metrics import ray_errors
from lfrefract.optics.real_lens import RealLensCamera
from lfrefract.synthesis.warp_map import PAPER_K, SynthesisOptions, build_warp_map
from simulator import boards
from simulator.config import RenderSettings, main_lens
from simulator.job import render_job, render_raw
from tests.tolerances import (
    CAMERA_CAL_ANGLE_GAIN,
    CAMERA_CAL_CORNER_GAIN,
    CAMERA_CAL_PORT_NORMAL_GAIN,
    CAMERA_CAL_RMS_GAIN,
    CAMERA_CAL_THIN_K1,
    CAMERA_CAL_THIN_SCALE,
)

CAMERA = camera_preset(boards.CAMERA)
VIEW = virtual_camera_for(CAMERA)


def board_views(mi, lens: str):
    views = []
    for table in boards.in_air_boards(VIEW):
        raw = render_raw(mi, boards.in_air_board_scene(table, lens=lens), progress=False)
        square = table["square_size_m"]
        views.append(board_view_from_light_field(CAMERA, raw, pattern=boards.PATTERN, square_size_m=square, view=VIEW))
    return views


@pytest.fixture(scope="module")
def double_gauss(mi):
    """The double Gauss's ray model, from its ten in-air board renders."""
    return calibrate_camera(CAMERA, board_views(mi, "double-gauss"), view=VIEW)


@pytest.mark.render
def test_a_real_lens_is_calibrated_closer_to_its_true_rays(double_gauss):
    calibration = double_gauss
    assert calibration.ray_rms_m < CAMERA_CAL_RMS_GAIN * calibration.initial_ray_rms_m
    real = RealLensCamera.from_preset(CAMERA, "double-gauss")
    vv, uu = np.mgrid[0 : CAMERA.sensor.height_px : 3, 0 : CAMERA.sensor.width_px : 3]
    uv = np.stack([uu.ravel(), vv.ravel()], axis=1).astype(float)
    true, thin, fitted = real.chief_rays(uv), CAMERA.captured_rays(uv), calibration.captured_rays(uv)
    keep = true.in_aperture & thin.in_aperture
    errors = {
        name: ray_errors(
            r.origins_cam, r.directions_cam, true.origins_cam, true.directions_cam, plane_distance_m=0.02, valid=keep
        )
        for name, r in (("thin", thin), ("fitted", fitted))
    }
    assert errors["fitted"].angle_rms_rad < CAMERA_CAL_ANGLE_GAIN * errors["thin"].angle_rms_rad


@pytest.mark.render
def test_the_thin_lens_calibrates_to_itself_by_the_command_line(mi, tmp_path, capsys):
    """A thin-lens camera needs no correction: the command line finds the identity (to the corners'
    noise) from five in-air board renders with their meta.json, and writes it."""
    tables = boards.in_air_boards(VIEW)[:5]
    paths = []
    for k, table in enumerate(tables):
        render_job(boards.in_air_board_scene(table), tmp_path / f"b{k}", progress=False, write_previews=False)
        paths.append(str(tmp_path / f"b{k}" / "raw.exr"))
    out = tmp_path / "camera.json"
    sizes = [str(t["square_size_m"]) for t in tables]
    argv = ["calibrate", "camera", *paths, "--squares", *map(str, boards.SQUARES), "--square-size-m", *sizes]
    assert core_cli.main([*argv, "--out", str(out)]) == 0
    assert "ray model from 5 captures" in capsys.readouterr().out
    written = read_json(out)
    assert written["kind"] == "lfrefract.calibrate.camera"
    c = written["correction"]
    assert abs(c["pupil_scale"] - 1.0) < CAMERA_CAL_THIN_SCALE
    assert abs(c["slope_scale"] - 1.0) < CAMERA_CAL_THIN_SCALE
    assert abs(c["k1"]) < CAMERA_CAL_THIN_K1
    assert written["ray_rms_m"] == pytest.approx(written["initial_ray_rms_m"], rel=0.05)
    # The covariance a refinement with the port takes: its diagonal is the standard deviations'.
    covariance = written["correction_covariance"]
    assert covariance["parameters"] == list(written["correction_std"])
    np.testing.assert_allclose(np.sqrt(np.diag(covariance["matrix"])), list(written["correction_std"].values()))
    assert core_cli.main([*argv[:-2], "--square-size-m", "0.01", "0.02", "--out", str(tmp_path / "x.json")]) == 2
    assert "one per capture (5), got 2" in capsys.readouterr().err
    with pytest.raises(CalibrationError, match="at least 3"):
        calibrate_camera(CAMERA, [], view=VIEW)


@pytest.mark.render
def test_the_synthesis_on_the_calibrated_model_finds_the_corners_closer(mi, double_gauss, tmp_path, capsys):
    """Behind a port tilted (25, 10) deg, a board at 0.6 m through the double Gauss: the thin-lens
    warp map puts its corners 0.31 px RMS off their true projection, the calibrated one 0.16 px
    (the thin lens's own: 0.11 px). ``synth --camera camera.json`` takes the calibration."""
    tilt, sight = (25.0, 10.0), (0.16, -0.125)
    empty = boards.empty_scene(tilt)
    thin_map = build_warp_map(empty.camera, empty.port, options=SynthesisOptions(k=PAPER_K))
    fitted_map = build_warp_map(
        empty.camera, empty.port, options=SynthesisOptions(k=PAPER_K, ray_correction=double_gauss.correction)
    )
    config = boards.board_scene(tilt, boards.slanted_board(0.6, sight, thin_map.output.focal_px))
    config = config.with_overrides(lens=main_lens("double-gauss", config.camera))
    expected = thin_map.output.project(boards.chessboard_corners_world(config.objects[0]))
    raw = render_raw(mi, config, progress=False)
    errors = {}
    for name, warp in (("thin", thin_map), ("fitted", fitted_map)):
        found = boards.find_corners(warp.apply(raw))
        assert found is not None
        errors[name] = boards.corner_rms_px(found, expected)
    assert errors["fitted"] < CAMERA_CAL_CORNER_GAIN * errors["thin"]
    # The command line: the calibration as --camera.
    capture = tmp_path / "board"
    render_job(
        config.with_overrides(render=RenderSettings(spp=4, ideal_spp=4)), capture, progress=False, write_previews=False
    )
    write_json(tmp_path / "camera.json", double_gauss.to_dict())
    argv = ["synth", str(capture / "raw.exr"), "--camera", str(tmp_path / "camera.json"), "--k", str(PAPER_K)]
    assert core_cli.main([*argv, "--out", str(tmp_path / "rf.exr"), "--quiet"]) == 0
    capsys.readouterr()
    options = read_json(tmp_path / "rf.json")["options"]
    assert options["ray_correction"] == double_gauss.correction.to_dict()


@pytest.mark.render
def test_the_port_is_calibrated_on_the_calibrated_model(mi, double_gauss):
    """Underwater boards through the double Gauss behind a port tilted (25, 10) deg: calibrated on
    the thin-lens model the port's normal is 1.6 deg off and its distance 9.8 mm long; on the
    calibrated model (``corrected_view``) 0.46 deg off and 2.1 mm short, measured where that model
    puts the camera (the lens's entrance pupil, 0.5 mm behind the simulator's origin)."""
    tilt = (25.0, 10.0)
    scene = boards.empty_scene(tilt)
    truth = scene.port  # where the thin-lens model puts the camera
    # where the calibrated model puts it: the lens's entrance pupil
    scene = scene.with_overrides(lens=main_lens("double-gauss", scene.camera))
    moved = scene.port.seen_from(scene.calibration_origin_cam)
    views = []
    for table in boards.port_boards(tilt, VIEW):
        config = boards.board_scene(tilt, table, spp=boards.PORT_SPP)
        raw = render_raw(mi, config.with_overrides(lens=main_lens("double-gauss", config.camera)), progress=False)
        found = board_view_from_light_field(
            CAMERA, raw, pattern=boards.PATTERN, square_size_m=table["square_size_m"], view=VIEW
        )
        assert found is not None
        views.append(found)
    known = {"thickness_m": truth.thickness_m, "n_glass": truth.n_glass, "n_water": truth.n_water}
    # On the thin-lens model the boards disagree with each other (its normal's spread by capture is 1.1
    # deg, beyond calibrate_port's default limit of 0.5, which refuses it): the limits are raised here to
    # see how far off it is.
    thin = calibrate_port(VIEW, views, **known, max_normal_std_deg=5.0, max_distance_std_m=0.05).port
    fitted = calibrate_port(VIEW, [corrected_view(v, double_gauss.correction, VIEW) for v in views], **known).port

    def normal_error_deg(port):
        return np.degrees(np.arccos(np.clip(port.normal @ truth.normal, -1.0, 1.0)))

    assert normal_error_deg(fitted) < CAMERA_CAL_PORT_NORMAL_GAIN * normal_error_deg(thin)
    assert abs(fitted.distance_m - moved.distance_m) < abs(thin.distance_m - truth.distance_m) / 2
    # Refined together with the ray model, the distance comes nearer still (2.1 -> 0.64 mm short).
    joint = calibrate_port_and_camera(VIEW, views, prior=double_gauss.estimate, **known)
    assert abs(joint.sequential.port.distance_m - fitted.distance_m) < 1e-9  # the same start
    # The joint fit's port, whether the held-back check keeps it or not.
    assert abs(joint.joint_port.port.distance_m - moved.distance_m) < abs(fitted.distance_m - moved.distance_m) / 2
