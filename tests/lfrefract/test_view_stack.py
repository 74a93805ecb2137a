"""Sub-aperture view stacks (lfrefract.synthesis.views.subaperture_stack) and their export in the HCI 4D light
field benchmark layout (lfrefract.formats.viewstack.write_view_stack), on raw images computed from the captured-ray
model: every pixel's chief ray onto a fronto-parallel textured plane at a known depth, so the
disparity between neighbouring views is known."""

from __future__ import annotations

import configparser
import dataclasses
import functools
import json
import math
import re

import cv2
import numpy as np
import pytest
from scipy import ndimage

from lfrefract import LightFieldCamera, ParameterError, PinholeCamera, camera_preset, virtual_camera_for
from lfrefract.cli import main
from lfrefract.errors import FileFormatError
from lfrefract.formats.exr import read_exr, write_exr
from lfrefract.formats.jsonio import SCHEMA_VERSION, write_json
from lfrefract.formats.viewstack import read_view_stack, view_file_names, write_view_stack
from lfrefract.methods import ConventionalView
from lfrefract.metrics import shift_px
from lfrefract.optics.camera_model import CameraModel
from lfrefract.optics.ray_correction import RayCorrection
from lfrefract.synthesis.views import (
    ViewStack,
    naive_view,
    subaperture_centre_m,
    subaperture_limit_px,
    subaperture_stack,
    subaperture_view,
)
from tests.tolerances import (
    FLOAT64_RELATIVE,
    VIEW_CALIBRATED_FLOOR_RATIO,
    VIEW_STACK_DISPARITY_RELATIVE,
    VIEW_STACK_SHIFT_RESIDUAL_PX,
)

TINY = camera_preset("tiny")  # views 92 x 69 px, f = 120 px; default 9 x 9 spacing 0.627 px, baseline 0.188 mm
TINY_OFF_FOCUS = dataclasses.replace(TINY, lens_to_mla_m=1.05 * TINY.focal_length_m)  # MLA off the focal plane


@functools.lru_cache(maxsize=4)
def _rays(camera: LightFieldCamera):
    return camera.captured_rays()


def plane_texture(points_cam: np.ndarray, camera: LightFieldCamera, depth_m: float, seed: int) -> np.ndarray:
    """The plane's texture at ``points_cam`` (N, 3, on z = ``depth_m``): 12 cosines of random
    orientation and phase, wavelengths 8-20 pixels of the default view at that depth (several
    microlenses per wavelength, so the views' one sample per lens resolves them)."""
    view_px_m = depth_m / virtual_camera_for(camera).focal_px
    rng = np.random.default_rng(seed)
    value = np.full(len(points_cam), 0.5)
    for _ in range(12):
        angle, wavelength, phase = rng.uniform(0, np.pi), 8 * view_px_m * rng.uniform(1, 2.5), rng.uniform(0, 2 * np.pi)
        along_wave = points_cam[:, 0] * np.cos(angle) + points_cam[:, 1] * np.sin(angle)
        value += 0.04 * np.cos(2 * np.pi * along_wave / wavelength + phase)
    return value


def plane_raw(
    camera: LightFieldCamera,
    depth_m: float,
    *,
    seed: int = 0,
    channels: int = 0,
    correction: RayCorrection | None = None,
) -> np.ndarray:
    """Each pixel's captured ray (thin lens, or ``correction``'s) onto the plane z = ``depth_m``
    textured by :func:`plane_texture`; 0 where the ray is vignetted. ``channels`` > 0 gives that many
    channels, scaled 1, 1/2, 1/4, ..."""
    rays = _rays(camera) if correction is None else correction.corrected(_rays(camera))
    along = (depth_m - rays.origins_cam[:, 2]) / rays.directions_cam[:, 2]
    points = rays.origins_cam + along[:, None] * rays.directions_cam
    value = plane_texture(points, camera, depth_m, seed)
    raw = np.where(rays.in_aperture, value, 0.0).reshape(camera.sensor.height_px, camera.sensor.width_px)
    if channels:
        raw = raw[..., None] * 0.5 ** np.arange(channels)
    return raw.astype(np.float32)


def srgb_8bit(linear: np.ndarray, white: float) -> np.ndarray:
    """The PNG encoding views.json states, written out independently of lfrefract.formats.viewstack."""
    x = np.clip(np.nan_to_num(np.asarray(linear, dtype=np.float64) / white, nan=0.0), 0.0, 1.0)
    return np.round(255 * np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)).astype(np.uint8)


def re_value(value) -> str:
    return re.escape(repr(value))


def read_png_rgb(path) -> np.ndarray:
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert image is not None, path
    return image if image.ndim == 2 else image[..., ::-1]


# =============================================================================== geometry
@pytest.mark.parametrize(
    ("camera", "grid", "depth_m"),
    [(camera_preset("tiny-2x"), 9, 0.2), (camera_preset("tiny-2x"), 9, 0.4), (TINY_OFF_FOCUS, 5, 0.1)],
    ids=["tiny-2x-9x9-0.2m", "tiny-2x-9x9-0.4m", "tiny-off-focus-5x5-0.1m"],
)
def test_neighbouring_views_are_f_baseline_over_depth_apart(camera, grid, depth_m):
    # Off focus every view has its own interpolation matrix (25 here, 0.05 s each): a 5 x 5 grid.
    stack = subaperture_stack(camera, plane_raw(camera, depth_m), grid=grid)
    expected = stack.output.focal_px * stack.baseline_m / depth_m
    assert stack.disparity_px(depth_m) == pytest.approx(expected, rel=FLOAT64_RELATIVE)
    assert stack.depth_m(expected) == pytest.approx(depth_m, rel=FLOAT64_RELATIVE)
    assert 0.2 < expected < 0.5  # a measurable shift, 1.8-4 px across the grid
    check_disparities(stack, expected)


def check_disparities(stack: ViewStack, expected: float) -> None:
    """Every view of ``stack`` is shifted against the central one by ``expected`` px per grid step."""
    grid, h = stack.grid, stack.centre_index
    # Every view's shift against the central view (ECC translation over pixels all views cover).
    covered = ndimage.binary_erosion(np.all(np.isfinite(stack.views), axis=(0, 1)), iterations=3)
    shifts = np.array([[shift_px(view, stack.central_view, mask=covered) for view in row] for row in stack.views])
    k = np.arange(grid) - h
    columns, rows = np.meshgrid(k, k)  # [r, c] = c - h, r - h
    # The view one step right sees the scene moved left by d; one step down, moved up by d.
    slope_u = -np.sum(columns * shifts[..., 0]) / np.sum(columns**2)
    slope_v = -np.sum(rows * shifts[..., 1]) / np.sum(rows**2)
    assert abs(slope_u / expected - 1) < VIEW_STACK_DISPARITY_RELATIVE, (slope_u, expected)
    assert abs(slope_v / expected - 1) < VIEW_STACK_DISPARITY_RELATIVE, (slope_v, expected)
    residual = np.hypot(shifts[..., 0] + columns * expected, shifts[..., 1] + rows * expected)
    assert residual.max() < VIEW_STACK_SHIFT_RESIDUAL_PX, residual.max()


@pytest.mark.parametrize("camera", [TINY, TINY_OFF_FOCUS], ids=["tiny", "tiny-off-focus"])
def test_views_are_the_subaperture_views_of_a_regular_grid(camera):
    raw = np.random.default_rng(1).random((camera.sensor.height_px, camera.sensor.width_px, 3)).astype(np.float32)
    stack = subaperture_stack(camera, raw, grid=3, spacing_px=1.5)
    assert stack.views.shape == (3, 3, stack.output.height_px, stack.output.width_px, 3)
    assert stack.views.dtype == np.float32
    np.testing.assert_array_equal(stack.central_view, subaperture_view(camera, raw, (0.0, 0.0)))
    np.testing.assert_array_equal(stack.offsets_px[0, 2], [1.5, -1.5])  # top right: +u, -v
    for r, c in ((0, 2), (2, 1)):  # other views too (off focus: their own principal-point shift)
        np.testing.assert_array_equal(stack.views[r, c], subaperture_view(camera, raw, tuple(stack.offsets_px[r, c])))
        np.testing.assert_array_equal(stack.centres_m[r, c], subaperture_centre_m(camera, stack.offsets_px[r, c]))
    pitch, f_mla = camera.sensor.pixel_pitch_m, camera.mla.focal_length_m
    assert stack.baseline_m == pytest.approx(1.5 * pitch * camera.lens_to_mla_m / f_mla, rel=FLOAT64_RELATIVE)
    assert stack.centres_m[0, 0, 0] < stack.centres_m[0, 1, 0]
    assert stack.centres_m[0, 0, 1] < stack.centres_m[1, 0, 1]
    grey = subaperture_stack(camera, raw[..., 0], grid=3, spacing_px=1.5)
    assert grey.views.shape == stack.views.shape[:4]
    np.testing.assert_array_equal(grey.views, stack.views[..., 0])


@pytest.mark.parametrize("grid", [3, 9, 11])
def test_the_default_spacing_puts_the_corner_views_at_the_limit(grid):
    raw = np.zeros((TINY.sensor.height_px, TINY.sensor.width_px), dtype=np.float32)
    stack = subaperture_stack(TINY, raw, grid=grid)
    limit = subaperture_limit_px(TINY)
    # One pixel inside the rim: the usable aperture with a 1 px margin, seen from the sensor.
    usable_px = TINY.usable_aperture_radius_m(1.0) * TINY.mla.focal_length_m / TINY.lens_to_mla_m / 10e-6
    assert limit == pytest.approx(usable_px, rel=FLOAT64_RELATIVE)
    corner = math.hypot(*stack.offsets_px[0, 0])
    assert limit * (1 - FLOAT64_RELATIVE) <= corner <= limit
    subaperture_view(TINY, raw, tuple(stack.offsets_px[0, 0]))  # the single view accepts it too
    with pytest.raises(ParameterError, match=r"spacing_px=.* puts the corner views .* beyond the limit"):
        subaperture_stack(TINY, raw, grid=grid, spacing_px=stack.spacing_px * 1.001)


def test_bad_grid_and_spacing_are_rejected_with_the_value_named():
    raw = np.zeros((TINY.sensor.height_px, TINY.sensor.width_px), dtype=np.float32)
    for grid in (4, 1, 0, -3, 3.0, True, "9"):
        with pytest.raises(ParameterError, match=rf"grid must be an odd integer >= 3.*got {re_value(grid)}$"):
            subaperture_stack(TINY, raw, grid=grid)
    for spacing in (0.0, -1.0, np.nan, np.inf, "1"):
        with pytest.raises(ParameterError, match=rf"spacing_px must be .*got {re_value(spacing)}$"):
            subaperture_stack(TINY, raw, spacing_px=spacing)
    with pytest.raises(ParameterError, match=r"spacing_px=2\.0 puts the corner views of the 9 x 9 grid 11\.31 px"):
        subaperture_stack(TINY, raw, spacing_px=2.0)
    with pytest.raises(ParameterError, match="output must be a PinholeCamera"):
        subaperture_stack(TINY, raw, output=TINY)
    with pytest.raises(ParameterError, match="raw must have shape"):
        subaperture_stack(TINY, raw[:-1])
    small = dataclasses.replace(TINY, f_number=11.0)  # micro-images of radius 0.9 px
    with pytest.raises(ParameterError, match=r"radius 0\.909 px: no sub-aperture view"):
        subaperture_stack(small, raw)


def test_a_view_stack_is_validated():
    raw = plane_raw(TINY, 0.1)
    stack = subaperture_stack(TINY, raw, grid=3)
    fields = {"views": stack.views, "offsets_px": stack.offsets_px, "centres_m": stack.centres_m}
    with pytest.raises(ParameterError, match="views must be a float32 array"):
        ViewStack(**{**fields, "views": stack.views.astype(np.float64)}, output=stack.output)
    skewed = stack.offsets_px.copy()
    skewed[2, 2] += 0.01
    with pytest.raises(ParameterError, match=r"offsets_px must be a regular grid .* offsets_px\[2, 2\]"):
        ViewStack(**{**fields, "offsets_px": skewed}, output=stack.output)
    with pytest.raises(ParameterError, match="centres_m are not subaperture_centre_m of offsets_px"):
        ViewStack(**{**fields, "centres_m": stack.centres_m * 2}, output=stack.output, camera=TINY)
    with pytest.raises(ParameterError, match=r"views must be 70 x 92 px"):
        ViewStack(**fields, output=dataclasses.replace(stack.output, height_px=70))
    with pytest.raises(ParameterError, match="depth_m must be positive"):
        stack.disparity_px(np.array([0.5, -1.0]))
    assert stack.disparity_px(np.inf) == 0.0
    assert stack.depth_m(0.0) == np.inf
    with pytest.raises(ValueError, match="read-only"):
        stack.views[0, 0, 0, 0] = 1.0


# =============================================================================== files
NEAR = 0.05  # disparity 0.45 px per step on the tiny camera: the views differ visibly
# Wider than the lenses' hull, so the views have NaN borders.
WIDE = PinholeCamera(focal_px=120.0, cx_px=50.5, cy_px=38.0, width_px=102, height_px=77)


@pytest.fixture(scope="module")
def rgb_stack() -> ViewStack:
    return subaperture_stack(TINY, plane_raw(TINY, NEAR, channels=3), grid=5, output=WIDE)


def test_the_hci_layout_on_disk(tmp_path, rgb_stack):
    out = write_view_stack(tmp_path / "lf", rgb_stack, metadata={"source": "analytic"})
    names = [f"input_Cam{i:03d}.png" for i in range(25)]
    assert view_file_names(5, "png") == names
    assert sorted(p.name for p in out.iterdir()) == sorted(
        [*names, ".lfrefract-output.json", "parameters.cfg", "stack.npz", "valid_mask.png", "views.json"]
    )
    meta = json.loads((out / "views.json").read_text())
    assert meta["central_view"] == "input_Cam012.png"
    assert meta["files"]["views"] == names
    assert meta["metadata"] == {"source": "analytic"}
    white = meta["encoding"]["white_level"]
    finite = rgb_stack.central_view[np.isfinite(rgb_stack.central_view)]
    assert white == pytest.approx(np.percentile(finite, 99.5))
    # Read as the benchmark's own reader does: sorted input_* names, index // num_cams_x is the row.
    files = sorted(p.name for p in out.iterdir() if p.name.startswith("input_") and p.name.endswith(".png"))
    assert files == names
    for index, name in enumerate(files):
        expected = srgb_8bit(rgb_stack.views[index // 5, index % 5], white)
        np.testing.assert_array_equal(read_png_rgb(out / name), expected)
    # The order is visible: the scene moves left from Cam000 to Cam001 and up from Cam000 to Cam005.
    first, right, down = (read_png_rgb(out / names[i]).astype(np.float32) for i in (0, 1, 5))
    valid = read_png_rgb(out / "valid_mask.png") == 255
    inner = ndimage.binary_erosion(valid, iterations=3)  # ECC's smoothing must not reach the black border
    (right_u, right_v), (down_u, down_v) = shift_px(right, first, mask=inner), shift_px(down, first, mask=inner)
    step = rgb_stack.disparity_px(NEAR)  # 0.90 px; measured -0.93 and -0.90 px, 0.01 px across
    assert right_u == pytest.approx(-step, abs=VIEW_STACK_SHIFT_RESIDUAL_PX)
    assert abs(right_v) < 0.1
    assert down_v == pytest.approx(-step, abs=VIEW_STACK_SHIFT_RESIDUAL_PX)
    assert abs(down_u) < 0.1
    # NaN pixels are written as 0 and marked in the mask, which holds exactly the pixels all views cover.
    covered = np.all(np.isfinite(rgb_stack.views), axis=(0, 1, 4))
    assert 0.3 < covered.mean() < 0.99
    np.testing.assert_array_equal(valid, covered)
    assert np.all(read_png_rgb(out / names[0])[~np.isfinite(rgb_stack.views[0, 0, ..., 0])] == 0)


def test_parameters_cfg_parses_and_agrees_with_the_stack(tmp_path, rgb_stack):
    out = write_view_stack(tmp_path / "lf", rgb_stack)
    cfg = configparser.ConfigParser()
    assert cfg.read(out / "parameters.cfg") == [str(out / "parameters.cfg")]
    intr, extr = cfg["intrinsics"], cfg["extrinsics"]
    assert (intr.getint("image_resolution_x_px"), intr.getint("image_resolution_y_px")) == (102, 77)
    assert extr.getint("num_cams_x") == extr.getint("num_cams_y") == 5
    assert extr.getfloat("baseline_mm") == pytest.approx(rgb_stack.baseline_m * 1e3, rel=FLOAT64_RELATIVE)
    assert intr.getfloat("focal_length_mm") == pytest.approx(TINY.lens_to_mla_m * 1e3, rel=FLOAT64_RELATIVE)
    # The benchmark's tools derive the focal length in pixels as f_mm * max(resolution) / sensor_mm.
    f_px = intr.getfloat("focal_length_mm") * 102 / intr.getfloat("sensor_size_mm")
    assert f_px == pytest.approx(WIDE.focal_px, rel=FLOAT64_RELATIVE) == intr.getfloat("focal_length_px")
    assert (intr.getfloat("principal_point_x_px"), intr.getfloat("principal_point_y_px")) == (50.5, 38.0)
    assert extr.getfloat("focus_distance_m") == math.inf
    # Their disparity-to-depth conversion (evaluation toolkit, BaseScene.disp2depth) gives our depths.
    q = extr.getfloat("baseline_mm") * intr.getfloat("focal_length_mm") * 102
    for depth in (0.05, 0.3, 2.0):
        disparity = rgb_stack.disparity_px(depth)
        inverse_focus = 1.0 / extr.getfloat("focus_distance_m")
        hci_depth = 1.0 / (1000.0 * intr.getfloat("sensor_size_mm") * disparity / q + inverse_focus)
        assert hci_depth == pytest.approx(depth, rel=1e-9)


def test_read_view_stack_round_trips_png_and_exr(tmp_path, rgb_stack):
    for image_format in ("png", "exr"):
        out = write_view_stack(tmp_path / image_format, rgb_stack, image_format=image_format)
        back = read_view_stack(out)
        np.testing.assert_array_equal(back.views, rgb_stack.views)  # NaN where NaN
        np.testing.assert_array_equal(back.offsets_px, rgb_stack.offsets_px)
        np.testing.assert_array_equal(back.centres_m, rgb_stack.centres_m)
        np.testing.assert_array_equal(back.K, rgb_stack.K)
        assert back.output == rgb_stack.output
        assert back.camera == TINY
        assert back.baseline_m == rgb_stack.baseline_m
    np.testing.assert_array_equal(read_exr(tmp_path / "exr" / "input_Cam012.exr"), rgb_stack.central_view)
    assert json.loads((tmp_path / "exr" / "views.json").read_text())["encoding"]["nan"] == "kept (no value)"


def test_writing_is_atomic_and_never_replaces_a_foreign_directory(tmp_path, rgb_stack, monkeypatch):
    out = write_view_stack(tmp_path / "lf", rgb_stack)
    with pytest.raises(FileExistsError, match="is not empty"):
        write_view_stack(out, rgb_stack, image_format="exr")
    write_view_stack(out, rgb_stack, image_format="exr", overwrite=True)
    assert (out / "input_Cam000.exr").is_file()
    assert not (out / "input_Cam000.png").exists()
    foreign = tmp_path / "thesis"
    foreign.mkdir()
    (foreign / "thesis.tex").write_text("precious")
    with pytest.raises(FileExistsError, match=r"is not an lfrefract output"):
        write_view_stack(foreign, rgb_stack, overwrite=True)
    # A failure half-way leaves the earlier output as it was and no staging directory behind.
    import lfrefract.formats.viewstack

    calls = []
    real = lfrefract.formats.viewstack._write_png

    def failing(path, image):
        calls.append(path)
        if len(calls) == 7:
            raise OSError("disk full")
        real(path, image)

    monkeypatch.setattr(lfrefract.formats.viewstack, "_write_png", failing)
    with pytest.raises(OSError, match="disk full"):
        write_view_stack(out, rgb_stack, overwrite=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lf", "thesis"]
    assert (out / "input_Cam000.exr").is_file()


def test_bad_exports_and_files_are_refused(tmp_path, rgb_stack):
    two = dataclasses.replace(rgb_stack, views=np.ascontiguousarray(rgb_stack.views[..., :2]))
    with pytest.raises(ParameterError, match=r"1 or 3 channels .* got 2 channels"):
        write_view_stack(tmp_path / "a", two)
    with pytest.raises(ParameterError, match=r"image_format must be one of \['png', 'exr'\], got 'jpg'"):
        write_view_stack(tmp_path / "a", rgb_stack, image_format="jpg")
    with pytest.raises(ParameterError, match=r"white_level must be positive, got -1\.0"):
        write_view_stack(tmp_path / "a", rgb_stack, white_level=-1.0)
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(FileFormatError, match="no such file"):
        read_view_stack(tmp_path / "missing")
    (tmp_path / "bad").mkdir()
    (tmp_path / "bad" / "stack.npz").write_bytes(b"not a zip")
    with pytest.raises(FileFormatError, match=r"not a readable \.npz file"):
        read_view_stack(tmp_path / "bad")
    np.savez(tmp_path / "bad" / "stack.npz", views=rgb_stack.views)
    with pytest.raises(FileFormatError, match=r"lacks \['K', 'camera', 'centres_m', 'offsets_px', 'schema_version'\]"):
        read_view_stack(tmp_path / "bad")


# ====================================================================== a calibrated camera
#: A strong correction of the tiny camera (a 15 % larger pupil, 4 % longer focal length, barrel
#: distortion moving the image corners by about 2.5 view pixels); no drift, so the views are pinholes.
CORRECTION = RayCorrection(pupil_scale=1.15, slope_scale=1.04, k1=-0.4)
CALIBRATED = CameraModel(camera=TINY, correction=CORRECTION)


def pinhole_image(camera: LightFieldCamera, depth_m: float, seed: int = 0) -> np.ndarray:
    """The plane of :func:`plane_raw` as the default view's pinhole at the origin sees it (H, W)."""
    view = virtual_camera_for(camera)
    vv, uu = np.mgrid[0 : view.height_px, 0 : view.width_px]
    pixels = np.stack([uu.ravel(), vv.ravel(), np.ones(uu.size)], axis=1)
    points = depth_m * pixels @ np.linalg.inv(view.K).T
    return plane_texture(points, camera, depth_m, seed).reshape(view.height_px, view.width_px)


def test_a_calibrated_cameras_central_view_is_the_pinhole_image_of_its_rays():
    depth = 0.3
    truth = pinhole_image(TINY, depth)
    raw = plane_raw(TINY, depth, correction=CORRECTION)

    def rms(image):
        covered = ndimage.binary_erosion(np.isfinite(image), iterations=2)
        return float(np.sqrt(np.mean((image - truth)[covered] ** 2)))

    floor = rms(naive_view(TINY, plane_raw(TINY, depth)))  # the thin lens's own view of its own rays
    calibrated = rms(naive_view(CALIBRATED, raw))
    uncorrected = rms(naive_view(TINY, raw))
    assert calibrated < VIEW_CALIBRATED_FLOOR_RATIO * floor, (calibrated, floor)  # measured: 0.0064 / 0.0066
    assert calibrated < uncorrected / 2, (calibrated, uncorrected)  # measured: 0.0064 against 0.0187
    # The resampling is the conventional image's too (the approximation baseline's input).
    conventional = ConventionalView(camera=CALIBRATED, view=virtual_camera_for(TINY))
    np.testing.assert_allclose(conventional.apply(raw), naive_view(CALIBRATED, raw), atol=1e-6)


# The pupil and focal scales, then the distortion: with all of them OpenCV's ECC stops with "NaN
# encountered" on the anti-diagonal corner views of this stack, which a brute-force search finds
# shifted by the expected 2.08 px like the others (residual 0.0076, as the diagonal's).
@pytest.mark.parametrize(
    "correction", [RayCorrection(pupil_scale=1.15, slope_scale=1.04), RayCorrection(k1=-0.4)], ids=["scales", "k1"]
)
def test_a_calibrated_cameras_views_are_a_pupil_scale_wider_grid(correction):
    depth = 0.2
    camera = camera_preset("tiny-2x")
    stack = subaperture_stack(
        CameraModel(camera=camera, correction=correction), plane_raw(camera, depth, correction=correction), grid=9
    )
    thin = subaperture_centre_m(camera, (1.0, 0.0))[0] * stack.spacing_px
    assert stack.baseline_m == pytest.approx(correction.pupil_scale * thin, rel=FLOAT64_RELATIVE)
    assert stack.ray_correction == correction
    check_disparities(stack, stack.disparity_px(depth))


def test_a_stack_of_a_calibrated_camera_round_trips_and_is_validated(tmp_path):
    raw = plane_raw(TINY, 0.1, correction=CORRECTION)
    stack = subaperture_stack(CALIBRATED, raw, grid=3)
    write_view_stack(tmp_path / "views", stack, image_format="exr")
    back = read_view_stack(tmp_path / "views")
    assert back.ray_correction == CORRECTION
    assert json.loads((tmp_path / "views" / "views.json").read_text())["ray_correction"] == CORRECTION.to_dict()
    fields = {f.name: getattr(stack, f.name) for f in dataclasses.fields(stack)}
    with pytest.raises(ParameterError, match="centres_m are not subaperture_centre_m"):
        ViewStack(**(fields | {"ray_correction": None}))
    with pytest.raises(ParameterError, match="correction must be a RayCorrection"):
        subaperture_stack(CameraModel(camera=TINY, correction={"pupil_scale": 1.1}), raw, grid=3)


def test_the_cli_takes_a_camera_calibration_for_views_and_naive(tmp_path, capsys):
    raw = plane_raw(TINY, 0.3, correction=CORRECTION)
    write_exr(tmp_path / "cap" / "raw.exr", raw, role="raw")
    write_json(tmp_path / "cap" / "meta.json", {"camera": TINY.to_dict()})
    calibration = tmp_path / "camera.json"
    write_json(
        calibration,
        {"kind": "lfrefract.calibrate.camera", "camera": TINY.to_dict(), "correction": CORRECTION.to_dict()},
    )
    source = str(tmp_path / "cap" / "raw.exr")
    assert main(["views", source, "--out", str(tmp_path / "views"), "--grid", "3", "--camera", str(calibration)]) == 0
    written = read_view_stack(tmp_path / "views")
    assert written.ray_correction == CORRECTION
    np.testing.assert_array_equal(written.views, subaperture_stack(CALIBRATED, raw, grid=3).views)
    out = tmp_path / "naive.exr"
    assert main(["naive", source, "--out", str(out), "--camera", str(calibration)]) == 0
    np.testing.assert_array_equal(read_exr(out), naive_view(CALIBRATED, raw))
    capsys.readouterr()


# =============================================================================== command line
def test_cli_writes_the_view_stack_of_a_capture(tmp_path, capsys):
    raw = plane_raw(TINY, 0.1)
    write_exr(tmp_path / "cap" / "raw.exr", raw, role="raw")
    write_json(tmp_path / "cap" / "meta.json", {"camera": TINY.to_dict()})
    out = tmp_path / "views"
    assert main(["views", str(tmp_path / "cap" / "raw.exr"), "--out", str(out), "--grid", "3"]) == 0
    assert "3 x 3 views of 92 x 69 px" in capsys.readouterr().out
    assert sorted(p.name for p in out.glob("input_Cam*.png")) == view_file_names(3, "png")
    written = read_view_stack(out)
    expected = subaperture_stack(TINY, raw, grid=3)
    np.testing.assert_array_equal(written.views, expected.views)
    assert written.spacing_px == expected.spacing_px
    assert written.camera == TINY
    assert json.loads((out / "views.json").read_text())["metadata"]["source"] == str(tmp_path / "cap" / "raw.exr")
    args = ["views", str(tmp_path / "cap" / "raw.exr"), "--out", str(out)]
    assert main(args) == 2
    assert "is not empty" in capsys.readouterr().err
    assert main([*args, "--overwrite", "--format", "exr", "--spacing-px", "1.0", "--grid", "5"]) == 0
    assert read_view_stack(out).spacing_px == 1.0
    assert (out / "input_Cam024.exr").is_file()
    assert main([*args, "--overwrite", "--grid", "4"]) == 2
    assert "grid must be an odd integer >= 3" in capsys.readouterr().err


# =============================================================================== review fixes
def test_an_off_focus_stack_keeps_one_interpolation_matrix_alive(monkeypatch):
    # Off the focal plane every view has its own matrix (33 MB each at Illum size); holding all of
    # them held 81 at once for a 9 x 9 stack. Count the matrices still alive when each is built.
    import weakref

    import lfrefract.synthesis.views

    real = lfrefract.synthesis.views._resampling_matrix
    built: list[weakref.ref] = []
    alive_at_build: list[int] = []

    def counting(*args, **kwargs):
        alive_at_build.append(sum(ref() is not None for ref in built))
        result = real(*args, **kwargs)
        built.append(weakref.ref(result[1]))
        return result

    monkeypatch.setattr(lfrefract.synthesis.views, "_resampling_matrix", counting)
    raw = plane_raw(TINY_OFF_FOCUS, 0.1)
    stack = subaperture_stack(TINY_OFF_FOCUS, raw, grid=3)
    assert len(alive_at_build) == 9  # one shift per view
    assert max(alive_at_build) == 0, alive_at_build
    monkeypatch.setattr(lfrefract.synthesis.views, "_resampling_matrix", real)
    np.testing.assert_array_equal(
        stack.views[0, 2], subaperture_view(TINY_OFF_FOCUS, raw, tuple(stack.offsets_px[0, 2]))
    )
    alive_at_build.clear()
    monkeypatch.setattr(lfrefract.synthesis.views, "_resampling_matrix", counting)
    subaperture_stack(TINY, plane_raw(TINY, 0.1), grid=3)
    assert alive_at_build == [0]  # f' = f: one matrix for every view


def test_corner_views_at_the_limit_are_barely_vignetted():
    # subaperture_limit_px keeps the sample point a pixel inside the rim; its bilinear neighbours may
    # reach beyond it. On a uniform field only the corner views darken, and only slightly.
    from tests.tolerances import VIEW_STACK_CORNER_DARKENING_MAX

    raw = TINY.captured_rays().in_aperture.reshape(TINY.sensor.height_px, TINY.sensor.width_px).astype(np.float32)
    stack = subaperture_stack(TINY, raw, grid=9)
    means = np.nanmean(stack.views, axis=(2, 3)) / np.nanmean(stack.central_view)
    assert means.min() >= 1.0 - VIEW_STACK_CORNER_DARKENING_MAX, means.min()
    assert means[0, 0] < 1.0  # the effect the docstring states is there


def test_overwrite_never_replaces_a_views_json_of_another_kind(tmp_path, rgb_stack):
    # ``lfrefract synth RAW --out DIR/views.exr`` writes DIR/views.json (kind lfrefract.synth), here in
    # the capture directory: overwriting it with a view stack would delete the capture.
    capture = tmp_path / "cap"
    write_exr(capture / "raw.exr", np.zeros((4, 4), dtype=np.float32), role="raw")
    write_json(capture / "views.json", {"kind": "lfrefract.synth", "files": {"image": "views.exr"}})
    with pytest.raises(FileExistsError, match=r"is not an lfrefract output.*refusing"):
        write_view_stack(capture, rgb_stack, overwrite=True)
    assert sorted(p.name for p in capture.iterdir()) == ["raw.exr", "views.json"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cap"]


def test_a_truncated_or_garbled_stack_npz_is_a_file_format_error(tmp_path, rgb_stack):
    out = write_view_stack(tmp_path / "lf", rgb_stack, image_format="exr")
    data = (out / "stack.npz").read_bytes()
    (out / "stack.npz").write_bytes(data[: len(data) // 2])  # an interrupted copy: zip magic, no directory
    with pytest.raises(FileFormatError, match=r"not a readable \.npz file"):
        read_view_stack(out)
    arrays = {"views": rgb_stack.views, "offsets_px": rgb_stack.offsets_px, "centres_m": rgb_stack.centres_m}
    np.savez(
        out / "stack.npz", **arrays, K=np.asarray("K"), camera=np.asarray(""), schema_version=np.asarray(SCHEMA_VERSION)
    )
    with pytest.raises(FileFormatError, match="does not hold a valid view stack"):
        read_view_stack(out)


def test_view_file_names_rejects_a_bad_grid():
    for grid in (0, -3, 2.5, True):
        with pytest.raises(ParameterError, match=rf"grid must be .*got {re_value(grid)}$"):
            view_file_names(grid, "png")


# =============================================================================== unrecorded pixels, memory (issue 12)
def test_a_stack_with_unrecorded_pixels_is_each_view_with_them_masked():
    raw = plane_raw(TINY, 0.1, channels=3)
    holes = np.random.default_rng(4).random(raw.shape[:2]) < 0.03
    raw[holes, 1] = np.nan
    stack = subaperture_stack(TINY, raw, grid=3, recorded=~holes)
    assert not np.isnan(stack.views).any()  # spreading the NaN left about 30 % of every view NaN
    for r, c in ((0, 0), (1, 1), (2, 1)):
        np.testing.assert_array_equal(
            stack.views[r, c], subaperture_view(TINY, raw, tuple(stack.offsets_px[r, c]), recorded=~holes)
        )
    with pytest.raises(ParameterError, match=r"recorded must be a bool array of shape \(360, 480\)"):
        subaperture_stack(TINY, raw, grid=3, recorded=~holes[:10])


def test_a_stack_beyond_the_memory_is_refused_before_any_view_is_allocated(monkeypatch):
    # Issue 12: `lfrefract views --grid 1001` tried to allocate 71 GiB (1001^2 views of 92 x 69 x 3 float32).
    import time

    import lfrefract._memory
    from lfrefract.synthesis.views import view_stack_bytes
    from tests.tolerances import OVERSIZE_REFUSAL_SECONDS

    views_bytes = 1001**2 * 92 * 69 * 3 * 4
    assert views_bytes / 2**30 == pytest.approx(71.1, abs=0.05)
    estimate = view_stack_bytes(TINY, virtual_camera_for(TINY), grid=1001, channels=3)
    assert views_bytes <= estimate <= 1.01 * views_bytes  # the views dominate; the rest is a few MB
    raw = plane_raw(TINY, 0.1, channels=3)
    monkeypatch.setattr(lfrefract._memory, "available_memory", lambda: (16 * 2**30, "MemAvailable (test)"))
    monkeypatch.setattr(np, "empty", lambda *a, **k: pytest.fail("allocated before the check"))
    start = time.perf_counter()
    with pytest.raises(
        ParameterError, match=r"1001 x 1001 stack of 92 x 69 px views .* needs about 71\.\d GiB .* 16 GiB"
    ):
        subaperture_stack(TINY, raw, grid=1001)
    assert time.perf_counter() - start < OVERSIZE_REFUSAL_SECONDS


def test_ground_truth_disparity_is_written_in_the_benchmark_layout(tmp_path, rgb_stack):
    from lfrefract.formats.pfm import read_pfm
    from lfrefract.formats.viewstack import read_view_disparity

    g, h, w = rgb_stack.grid, rgb_stack.output.height_px, rgb_stack.output.width_px
    dx = np.random.default_rng(4).uniform(0.1, 2.0, (g, g, h, w)).astype(np.float32)
    dy = dx + 0.25
    dx[0, 0, 0, 0] = np.nan  # a view pixel that sees nothing
    out = write_view_stack(tmp_path / "lf", rgb_stack, disparity_px=(dx, dy))
    got_x, got_y = read_view_disparity(out)
    assert np.array_equal(got_x, dx, equal_nan=True)
    assert np.array_equal(got_y, dy)
    centre = rgb_stack.centre_index
    assert np.array_equal(read_pfm(out / "gt_disp_lowres.pfm"), dx[centre, centre])
    for index in range(g * g):
        view = read_pfm(out / f"gt_disp_lowres_Cam{index:03d}.pfm")
        assert np.array_equal(view, dx[index // g, index % g], equal_nan=True)
    sidecar = json.loads((out / "views.json").read_text())
    assert sidecar["disparity"]["ground_truth"]["central"] == "gt_disp_lowres.pfm"
    assert read_view_disparity(write_view_stack(tmp_path / "plain", rgb_stack)) is None
    with pytest.raises(ParameterError, match="vertical array must be float of shape"):
        write_view_stack(tmp_path / "bad", rgb_stack, disparity_px=(dx, dy[:, :, :-1]))
    assert not (tmp_path / "bad").exists()
