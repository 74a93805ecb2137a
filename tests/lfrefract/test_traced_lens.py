"""The traced ray model (:class:`lfrefract.optics.real_lens.TracedLens`): a render's recorded main lens
traced exactly, the oracle a data-only calibration of a real-lens capture is measured against.

It is a member of the ray-model family like the calibrated models: it maps each raw pixel's thin-lens
ray to the lens's true ray, so every consumer of a ray model (the warp map's k-d tree, the depth-aware
tracer, port and camera files) takes it unchanged.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from lfrefract import camera_preset
from lfrefract.errors import FileFormatError, ParameterError
from lfrefract.formats.capture import camera_model_from_option
from lfrefract.formats.jsonio import read_json, write_json
from lfrefract.optics.camera_model import CameraModel
from lfrefract.optics.ray_correction import correction_from_dict
from lfrefract.optics.real_lens import RealLensCamera, TracedLens
from lfrefract.synthesis.views import checked_correction
from lfrefract.synthesis.warp_map import SynthesisOptions
from simulator.config import main_lens


def _every_pixel(camera) -> np.ndarray:
    vv, uu = np.mgrid[0 : camera.sensor.height_px, 0 : camera.sensor.width_px]
    return np.stack([uu.ravel(), vv.ravel()], axis=1).astype(np.float64)


@pytest.fixture(scope="module", params=["double-gauss", "scenes/lenses/petzval.toml"])
def real(request) -> RealLensCamera:
    """The double Gauss and the Petzval design (whose micro-images lie 4.5 px from the thin lens's at
    the sensor's corner) on tiny-2x."""
    camera = camera_preset("tiny-2x")
    return RealLensCamera(camera=camera, lens=main_lens(request.param, camera))


def test_the_model_gives_every_pixels_true_ray(real):
    model = CameraModel(camera=real.lattice_camera, correction=TracedLens(real=real))
    assert model.ray_model == "traced"
    uv = _every_pixel(real.camera)
    rays, truth = model.captured_rays(uv), real.chief_rays(uv)
    passed = np.all(np.isfinite(truth.directions_cam), axis=1)
    # every pixel the lens passes and the lattice's aperture keeps is the true ray, to rounding
    assert np.array_equal(rays.in_aperture, model.camera.captured_rays(uv).in_aperture & passed)
    keep = rays.in_aperture
    assert keep.mean() > 0.2
    np.testing.assert_allclose(rays.directions_cam[keep], truth.directions_cam[keep], rtol=0, atol=1e-12)
    # the origins are where the true rays cross z = 0
    o, d = truth.origins_cam[keep], truth.directions_cam[keep]
    np.testing.assert_allclose(rays.origins_cam[keep], o - (o[:, 2:3] / d[:, 2:3]) * d, rtol=0, atol=1e-12)


def test_the_lattice_cameras_micro_images_are_the_lenss(real):
    lattice = real.lattice_camera
    uv = _every_pixel(real.camera)[::97]
    # the thin-lens lattice assigns every pixel to the microlens whose real micro-image holds it
    assert np.array_equal(lattice.captured_rays(uv).lens_indices, real.lens_indices_for_pixels(uv))
    thin = real.camera.captured_rays(uv).lens_indices
    if real.lens.name == "petzval":  # the preset's own lattice does not, off the centre
        assert not np.array_equal(thin, real.lens_indices_for_pixels(uv))


def test_the_thin_lens_twin_inverts_the_map(real):
    model = TracedLens(real=real)
    uv = _every_pixel(real.camera)[::7]
    thin = model.camera.captured_rays(uv)
    d = thin.directions_cam
    slopes = d[:, :2] / d[:, 2:3]
    origins, directions = model.apply(thin.origins_cam[:, :2], slopes)
    passed = np.all(np.isfinite(directions), axis=1)
    # a point 5 cm out on each ray (beyond the lens, where a port's face is)
    a, t, found = model.thin_lens_rays(origins + 0.05 * directions, directions)
    assert np.array_equal(found, passed)
    np.testing.assert_allclose(a[found], thin.origins_cam[found, :2], rtol=0, atol=1e-12)
    np.testing.assert_allclose(t[found], slopes[found], rtol=0, atol=1e-10)
    assert np.all(np.isnan(a[~found]))
    assert np.all(np.isnan(t[~found]))


def test_rays_between_the_pixels_map_smoothly_both_ways(real):
    """A board corner seen from a point of the aperture is a thin-lens ray between the pixels' rays.
    The map snapped such a ray to the pixel recording it, the true ray of the microlens's centre:
    the double Gauss's port-board observations pointed 1.0-1.2 mm from their corners 0.2-0.4 m out
    (0.02-0.03 mm through the thin lens), a third of them stopped, and a port fitted on the lens's
    true rays ran to the end of its distance range. Rays leaving a microlens off its centre now map
    to and from the thin-lens rays without loss."""
    model = TracedLens(real=real)
    uv = _every_pixel(real.camera)[::11]
    pitch = real.camera.mla.pitch_m
    offsets = np.random.default_rng(3).uniform(-0.4 * pitch, 0.4 * pitch, size=(len(uv), 2))
    true = real.rays_through_lenses(uv, lens_offsets_m=offsets)  # off the microlenses' centres
    keep = true.in_aperture
    assert keep.mean() > 0.2  # the Petzval's image circle lights 64 % of the sensor
    a, t, found = model.thin_lens_rays(true.origins_cam[keep], true.directions_cam[keep])
    assert found.all()
    origins, directions = model.apply(a, t)
    np.testing.assert_allclose(directions, true.directions_cam[keep], rtol=0, atol=1e-12)
    o, d = true.origins_cam[keep], true.directions_cam[keep]
    np.testing.assert_allclose(origins, o - (o[:, 2:3] / d[:, 2:3]) * d, rtol=0, atol=1e-12)


def test_its_table_round_trips_and_names_its_lens(real):
    model = TracedLens(real=real)
    table = json.loads(json.dumps(model.to_dict()))
    assert table["family"] == "traced"
    again = correction_from_dict(table)
    assert again == model
    assert again.name == f"traced {real.lens.name}"
    assert again.vector().shape == (0,)
    with pytest.raises(ParameterError, match="thin_lens_camera"):
        correction_from_dict({k: v for k, v in table.items() if k != "thin_lens_camera"})


def test_it_belongs_to_one_camera_and_moves_to_another_of_the_same_pixels():
    camera = camera_preset("tiny-2x")
    real = RealLensCamera(camera=camera, lens=main_lens("double-gauss", camera))
    traced = TracedLens(real=real)
    with pytest.raises(ParameterError, match="thin-lens rays of camera"):
        CameraModel(camera=camera, correction=traced)  # the preset's lattice is not the lens's
    moved = CameraModel(camera=real.lattice_camera, correction=traced).with_camera(camera)
    assert moved.correction.camera == camera
    assert moved.correction.real == real
    with pytest.raises(ParameterError, match="another sensor"):
        TracedLens(real=real, camera=camera_preset("tiny"))


def test_the_analytic_search_and_the_views_refuse_it():
    camera = camera_preset("tiny-2x")
    traced = TracedLens(real=RealLensCamera(camera=camera, lens=main_lens("double-gauss", camera)))
    with pytest.raises(ParameterError, match="search='analytic'"):
        SynthesisOptions(search="analytic", ray_correction=traced)
    assert SynthesisOptions(ray_correction=traced).to_dict()["ray_correction"]["family"] == "traced"
    with pytest.raises(ParameterError, match="no sub-aperture views"):
        checked_correction(traced)


def _render_meta(path, lens, *, camera=None) -> str:
    """A render's meta.json as ``lfsim render`` writes what the core reads of it: the camera, and the
    scene's lens (``"thin"`` or a prescription fitted to ``camera``, default the meta's own)."""
    meta = camera_preset("tiny-2x")
    table = lens if lens == "thin" else main_lens(lens, camera or meta).to_dict()
    write_json(path, {"camera": meta.to_dict(), "scene": {"lens": table}})
    return str(path)


def test_a_renders_meta_json_traces_its_recorded_lens(tmp_path):
    model = camera_model_from_option(_render_meta(tmp_path / "meta.json", "double-gauss"))
    assert model.ray_model == "traced"
    assert model.main_lens == "double-gauss"
    assert model.camera == model.correction.camera == model.correction.real.lattice_camera
    assert model.correction.real.camera == model.described_camera == camera_preset("tiny-2x")
    assert camera_model_from_option(_render_meta(tmp_path / "thin.json", "thin")).ray_model == "thin-lens"
    # a prescription that does not fit its camera is the file's error, named
    other = dataclasses.replace(camera_preset("tiny-2x"), focal_length_m=0.007)
    meta = _render_meta(tmp_path / "other.json", "double-gauss", camera=other)
    assert read_json(meta)["scene"]["lens"]["name"] == "double-gauss"
    with pytest.raises(FileFormatError, match=r"scene\.lens does not fit its camera"):
        camera_model_from_option(meta)


def test_a_board_views_observations_the_lens_stops_are_left_out():
    # A traced lens gives no ray (NaN) where its clear apertures stop one: a board view corrected by
    # it failed as "corners_px must be finite" (calibrate port --camera meta.json).
    from lfrefract.calibration.camera import corrected_view
    from lfrefract.calibration.port import BoardView
    from lfrefract.optics.pinhole import virtual_camera_for

    camera = camera_preset("tiny-2x")
    model = TracedLens(real=RealLensCamera(camera=camera, lens=main_lens("double-gauss", camera)))
    view = virtual_camera_for(model.camera)
    jj, ii = np.mgrid[0:3, 0:4]
    board = np.stack([ii.ravel(), jj.ravel()], axis=1) * 0.01
    pixels = np.array([view.K[0, 2], view.K[1, 2]]) + board * 500.0
    far = np.tile([0.02, 0.0, 0.0], (12, 1))  # 20 mm off the axis: outside the lens
    seen = BoardView(
        corners_px=np.concatenate([pixels, pixels]),
        board_points_m=np.concatenate([board, board]),
        centres_m=np.concatenate([np.zeros((12, 3)), far]),
        central_rows=np.repeat([True, False], 12),
    )
    kept = corrected_view(seen, model, view)
    assert len(kept.corners_px) == 12
    assert np.all(np.isfinite(kept.corners_px))
    assert kept.central.all()
    np.testing.assert_array_equal(kept.board_points_m, board)
    few = BoardView(
        corners_px=pixels,
        board_points_m=board,
        centres_m=np.where(np.arange(12)[:, None] < 6, 0.0, far),
        central_rows=None,
    )
    with pytest.raises(ParameterError, match="the camera's lens stops 6 of a board view's 12 observations"):
        corrected_view(few, model, view)
