"""MLA calibration from white images drawn here with numpy (no renderer).

The synthetic white image is the camera model's: a pixel's value is the fraction of a 4 x 4 grid of
points in it that lie inside the micro-image disc (radius ``micro_image_radius_px``) of their
nearest micro-image centre. Ground truth is the camera's own lattice.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy import ndimage
from scipy.spatial import cKDTree

from lfrefract import LightFieldCamera, MicrolensArray, ParameterError, SensorGeometry
from lfrefract.calibration import LENS_STATUS, MlaCalibration, calibrate_mla
from lfrefract.calibration.mla import _reindexed
from lfrefract.formats.jsonio import read_json, write_json
from tests.tolerances import (
    FLOAT64_PIXEL_PX,
    FLOAT64_RELATIVE,
    MLA_AFFINE_REGULAR_MIN_RMS_PX,
    MLA_PITCH_PX,
    MLA_ROTATION_RAD,
    MLA_SOFT_WHITE_FITTED_MAX_PX,
    MLA_SOFTER_WHITE_FITTED_MAX_PX,
    MLA_SYNTHETIC_FITTED_MAX_PX,
    MLA_SYNTHETIC_MEASURED_RMS_PX,
    MLA_UNROBUST_MIN_ERROR_PX,
    MLA_VIGNETTED_FITTED_MAX_PX,
)


def small_camera(grid: str = "hex", rotation_rad: float = 0.0, offset_m=(0.0, 0.0)) -> LightFieldCamera:
    """The tiny preset's optics on a 200 x 150 sensor with 80 um lenses: 8.2 px micro-image pitch."""
    return LightFieldCamera(
        focal_length_m=6e-3,
        lens_to_mla_m=6e-3,
        f_number=2.2,
        mla=MicrolensArray(
            grid=grid, pitch_m=80e-6, focal_length_m=160e-6, rotation_rad=rotation_rad, offset_m=offset_m
        ),
        sensor=SensorGeometry(width_px=200, height_px=150, pixel_pitch_m=10e-6),
    )


def synthetic_white(
    camera: LightFieldCamera, *, stretch_v: float = 1.0, cat_eye: float = 0.0, stop_ratio: float = 1.5
) -> np.ndarray:
    """White image (H, W) of ``camera`` by 4 x 4 point sampling of every pixel.

    ``stretch_v``: the image shows the camera's sensor stretched by this factor along v about the
    centre (an affine lattice). ``cat_eye``: each micro-image is also cut by the image of a second
    stop, a disc of ``stop_ratio`` times the micro-image radius centred ``cat_eye`` times the
    micro-image's distance from the axis further out: discs far from the axis are clipped on their
    outer side.
    """
    width, height = camera.sensor.width_px, camera.sensor.height_px
    axis = np.array(camera.sensor.centre_px)
    # Every micro-image centre within two pitches of the sensor (by brute force over the indices).
    reach = math.ceil(max(width, height) / camera.micro_image_pitch_px) + 2
    ij = np.stack(np.meshgrid(np.arange(-reach, reach + 1), np.arange(-reach, reach + 1)), axis=-1).reshape(-1, 2)
    centres = camera.micro_image_centres_px(ij)
    margin = 2 * camera.micro_image_pitch_px
    centres = centres[np.all((centres > -margin) & (centres < np.array([width, height]) + margin), axis=1)]
    s = (np.arange(4) + 0.5) / 4 - 0.5
    vv, uu, dv, du = np.meshgrid(np.arange(height), np.arange(width), s, s, indexing="ij")
    pts = np.stack([uu + du, vv + dv], axis=-1).reshape(-1, 2)
    pts[:, 1] = axis[1] + stretch_v * (pts[:, 1] - axis[1])
    distance, nearest = cKDTree(centres).query(pts)
    radius = camera.micro_image_radius_px
    lit = distance < radius
    if cat_eye:
        stop = centres[nearest] + cat_eye * (centres[nearest] - axis)
        lit &= np.sum((pts - stop) ** 2, axis=1) < (stop_ratio * radius) ** 2
    return lit.reshape(height, width, -1).mean(axis=2)


CASES = {
    "hex": small_camera(),
    "hex-rotated-offset": small_camera("hex", 0.3, (31e-6, -17e-6)),
    "square-rotated-offset": small_camera("square", -0.5, (11e-6, 29e-6)),
}


@pytest.fixture(scope="module")
def whites():
    return {name: synthetic_white(camera) for name, camera in CASES.items()}


def truth_indices(camera: LightFieldCamera, calibration: MlaCalibration) -> np.ndarray:
    """The camera's lattice index of each calibrated lens (the nearest true micro-image centre)."""
    return camera.lens_indices_for_pixels(calibration.centres_px)


def wrapped_angle(angle: float, period: float) -> float:
    return (angle + period / 2) % period - period / 2


# ========================================================================== accuracy
@pytest.mark.parametrize("name", list(CASES))
def test_recovers_lattice_and_every_centre(whites, name):
    camera = CASES[name]
    cal = calibrate_mla(whites[name])
    assert cal.grid == camera.mla.grid
    assert cal.pitch_px == pytest.approx(camera.micro_image_pitch_px, abs=MLA_PITCH_PX)
    period = math.pi / 3 if cal.grid == "hex" else math.pi / 2
    assert abs(wrapped_angle(cal.rotation_rad - camera.mla.rotation_rad, period)) < MLA_ROTATION_RAD
    # The calibration's indices are the camera's up to one constant shift, and it finds every lens.
    true_idx = truth_indices(camera, cal)
    shift = true_idx - cal.indices
    assert np.all(shift == shift[0])
    expected = camera.lens_indices_on_sensor()
    assert {tuple(r) for r in true_idx} == {tuple(r) for r in expected}
    error = np.linalg.norm(cal.centres_px - camera.micro_image_centres_px(true_idx), axis=1)
    assert error.max() < MLA_SYNTHETIC_FITTED_MAX_PX
    used = cal.used
    assert used.sum() > 0.8 * len(cal.indices)
    measured_error = np.linalg.norm(cal.measured_px[used] - camera.micro_image_centres_px(true_idx[used]), axis=1)
    assert np.sqrt(np.mean(measured_error**2)) < MLA_SYNTHETIC_MEASURED_RMS_PX
    assert cal.residual_rms_px == pytest.approx(np.sqrt(np.mean(cal.residuals_px[used] ** 2)))
    # Lens (0, 0) is the one nearest the sensor centre; the rotation lies in the canonical range.
    centre = np.array(camera.sensor.centre_px)
    assert np.linalg.norm(cal.origin_px - centre) == pytest.approx(
        np.min(np.linalg.norm(cal.centres_px - centre, axis=1))
    )
    assert abs(cal.rotation_rad) <= period / 2 + 1e-9
    # Unmeasured lenses are exactly the ones whose window leaves the sensor.
    assert set(cal.status_counts()) == set(LENS_STATUS)
    edge = cal.status == LENS_STATUS.index("edge")
    assert np.all(np.isnan(cal.measured_px[edge]))
    assert np.all(np.isfinite(cal.measured_px[~edge]))


def test_grid_option_and_colour_input(whites):
    white = whites["hex-rotated-offset"]
    plain = calibrate_mla(white)
    forced = calibrate_mla(np.repeat(white[..., None], 3, axis=2), grid="hex")
    np.testing.assert_allclose(forced.basis_px, plain.basis_px, rtol=FLOAT64_RELATIVE)
    with pytest.raises(ParameterError, match="grid='square' but white shows a hex lattice"):
        calibrate_mla(white, grid="square")


def test_border_vignetting_is_rejected():
    """Cat's-eye vignetting clips the discs far from the axis on their outer side: their centroids
    move inwards by up to 0.7 px. The robust fit sets them aside; a plain fit would follow them."""
    camera = CASES["hex-rotated-offset"]
    white = synthetic_white(camera, cat_eye=0.03)
    robust = calibrate_mla(white)
    plain = calibrate_mla(white, outlier_sigma=1e9)
    counts = robust.status_counts()
    assert counts["outlier"] + counts["dim"] > 0.2 * len(robust.indices)
    assert plain.status_counts()["outlier"] == 0
    for cal, bound in ((robust, None), (plain, MLA_UNROBUST_MIN_ERROR_PX)):
        error = np.linalg.norm(cal.centres_px - camera.micro_image_centres_px(truth_indices(camera, cal)), axis=1)
        if bound is None:
            assert error.max() < MLA_VIGNETTED_FITTED_MAX_PX
        else:
            assert error.max() > bound
    # The rejected lenses are the outer ones.
    centre = np.array(camera.sensor.centre_px)
    distance = np.linalg.norm(robust.centres_px - centre, axis=1)
    rejected = np.isin(robust.status, [LENS_STATUS.index("outlier"), LENS_STATUS.index("dim")])
    assert np.median(distance[rejected]) > np.median(distance[robust.used]) * 1.3


def test_affine_model_fits_a_stretched_lattice():
    """A sensor whose rows are 1 % further apart than its columns: the affine model follows it, the
    regular one cannot."""
    camera = CASES["hex-rotated-offset"]
    stretch = 1.01
    white = synthetic_white(camera, stretch_v=stretch)
    affine = calibrate_mla(white, lattice_model="affine")
    regular = calibrate_mla(white)
    axis = np.array(camera.sensor.centre_px)
    true_idx = camera.lens_indices_for_pixels(axis + (affine.centres_px - axis) * [1.0, stretch])
    truth = camera.micro_image_centres_px(true_idx)
    truth = axis + (truth - axis) / [1.0, stretch]
    assert np.linalg.norm(affine.centres_px - truth, axis=1).max() < MLA_SYNTHETIC_FITTED_MAX_PX
    assert regular.residual_rms_px > MLA_AFFINE_REGULAR_MIN_RMS_PX


# ========================================================================== the physical MLA
def test_calibrated_camera_reproduces_the_centres(whites):
    camera = CASES["square-rotated-offset"]
    cal = calibrate_mla(whites["square-rotated-offset"])
    # Calibrate a camera that knows only the optics: its model then puts the micro-images where the
    # calibration found them.
    unknown = dataclasses.replace(camera, mla=MicrolensArray(grid="hex", pitch_m=81e-6, focal_length_m=160e-6))
    calibrated = cal.calibrated_camera(unknown)
    np.testing.assert_allclose(
        calibrated.micro_image_centres_px(cal.indices), cal.centres_px, atol=FLOAT64_PIXEL_PX, rtol=0
    )
    assert calibrated.mla.grid == "square"
    px_to_mla = camera.sensor.pixel_pitch_m / camera.micro_image_scale
    assert calibrated.mla.pitch_m == pytest.approx(camera.mla.pitch_m, abs=MLA_PITCH_PX * px_to_mla)
    shift = truth_indices(camera, cal)[0] - cal.indices[0]
    np.testing.assert_allclose(calibrated.mla.offset_m, camera.mla.centres_m(shift[None])[0], atol=0.01 * px_to_mla)
    wrong = dataclasses.replace(camera, sensor=SensorGeometry(width_px=201, height_px=150, pixel_pitch_m=10e-6))
    with pytest.raises(ParameterError, match="201 x 150 px but the white image was 200 x 150 px"):
        cal.calibrated_camera(wrong)
    with pytest.raises(ParameterError, match="lens_to_mla_m must be positive"):
        cal.microlens_array(pixel_pitch_m=1e-5, lens_to_mla_m=0.0, mla_focal_length_m=1e-4)


# ========================================================================== sidecar
def test_sidecar_round_trip(whites, tmp_path):
    cal = calibrate_mla(whites["hex"])
    assert np.isnan(cal.measured_px).any()
    path = write_json(tmp_path / "mla.json", cal.to_dict())
    back = MlaCalibration.from_dict(read_json(path))
    for name in ("grid", "lattice_model", "image_size_px", "window_radius_px"):
        assert getattr(back, name) == getattr(cal, name)
    for name in ("origin_px", "basis_px", "indices", "measured_px", "status", "centres_px"):
        np.testing.assert_array_equal(getattr(back, name), getattr(cal, name))
    assert back.residual_rms_px == cal.residual_rms_px
    assert read_json(path)["summary"]["status_counts"] == cal.status_counts()


def test_sidecar_rejects_bad_data(whites):
    data = calibrate_mla(whites["hex"]).to_dict()
    with pytest.raises(ParameterError, match=r"unknown key\(s\) in mla calibration: \['pitch'\]"):
        MlaCalibration.from_dict({**data, "pitch": 3})
    with pytest.raises(ParameterError, match=r"missing key\(s\) in mla calibration: \['basis_px'\]"):
        MlaCalibration.from_dict({k: v for k, v in data.items() if k != "basis_px"})
    with pytest.raises(ParameterError, match="grid must be one of"):
        MlaCalibration.from_dict({**data, "grid": "triangle"})
    used = data["lenses"]["status"].index(0)
    lenses = {**data["lenses"], "measured_px": list(data["lenses"]["measured_px"])}
    lenses["measured_px"][used] = None
    with pytest.raises(ParameterError, match="measured_px must be given for every lens with status 'used'"):
        MlaCalibration.from_dict({**data, "lenses": lenses})
    with pytest.raises(ParameterError, match="basis_px must be a finite, non-singular"):
        MlaCalibration.from_dict({**data, "basis_px": [[1.0, 2.0], [2.0, 4.0]]})
    ragged = {**data["lenses"], "indices": [[0, 0], [1], *data["lenses"]["indices"][2:]]}
    with pytest.raises(ParameterError, match=r"mla calibration\.lenses\.indices must be an array of numbers"):
        MlaCalibration.from_dict({**data, "lenses": ragged})
    with pytest.raises(ParameterError, match=r"status_names must be \['used', 'edge', 'dim', 'outlier'\]"):
        MlaCalibration.from_dict({**data, "status_names": ["used", "dim", "edge", "outlier"]})


def test_reindexed_carries_lenses_over():
    indices = np.array([[0, 0], [1, 0], [0, 1]])
    measured = np.array([[1.0, 2.0], [3.0, 4.0], [np.nan, np.nan]])
    status = np.array([0, 3, 1], dtype=np.int8)
    new = np.array([[-1, 0], [0, 0], [0, 1]])
    got_measured, got_status = _reindexed(indices, measured, status, new)
    np.testing.assert_array_equal(got_measured, [[np.nan, np.nan], [1.0, 2.0], [np.nan, np.nan]])
    np.testing.assert_array_equal(got_status, [1, 0, 1])


# ========================================================================== bad input
def _noise(shape=(150, 200), seed=0):
    return np.random.default_rng(seed).random(shape)


@pytest.mark.parametrize(
    ("image", "message"),
    [
        (np.zeros(100), r"white must have shape \(H, W\) or \(H, W, 3\), got shape \(100,\)"),
        (np.zeros((150, 200, 2)), r"got shape \(150, 200, 2\)"),
        (np.zeros((2, 150, 200, 3)), r"got shape \(2, 150, 200, 3\)"),
        (np.ones((150, 200), dtype=bool), "white must be a real-valued image, got dtype bool"),
        (np.array([["a"] * 20] * 20), "white must be a real-valued image"),
        (np.ones((10, 200)), r"white must be at least 16 x 16 px, got shape \(10, 200\)"),
        (np.full((150, 200), 0.7), "white has no contrast: every pixel is 0.7"),
        (_noise(), "white shows no micro-image lattice"),
        (ndimage.gaussian_filter(_noise(), 3), "white shows no micro-image lattice"),
        (np.sin(0.7 * np.arange(200))[None, :].repeat(150, axis=0), "strong peaks in one direction only"),
        (np.add.outer(np.arange(150.0), np.arange(200.0)), "white"),
    ],
    ids=[
        "1d",
        "2-channels",
        "4d",
        "bool",
        "strings",
        "too-small",
        "uniform",
        "noise",
        "blurred-noise",
        "stripes",
        "ramp",
    ],
)
def test_bad_white_is_an_error(image, message):
    with pytest.raises(ParameterError, match=message):
        calibrate_mla(image)


@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf])
def test_non_finite_pixel_is_an_error(whites, value):
    white = whites["hex"].copy()
    white[7, 42] = value
    with pytest.raises(ParameterError, match=rf"1 pixel\(s\) are not, the first at \(u, v\) = \(42, 7\): {value}"):
        calibrate_mla(white)


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"grid": "triangle"}, "grid must be one of"),
        ({"lattice_model": "projective"}, "lattice_model must be one of"),
        ({"min_relative_flux": 1.0}, r"min_relative_flux must be in \[0, 1\), got 1.0"),
        ({"min_relative_flux": np.nan}, "min_relative_flux must be finite"),
        ({"outlier_sigma": 0.0}, "outlier_sigma must be positive, got 0.0"),
        ({"window_radius_px": -1.0}, "window_radius_px must be positive, got -1.0"),
        ({"window_radius_px": 9.0}, r"window_radius_px must be below the micro-image pitch \(8.2\d* px\), got 9.0"),
        ({"min_pitch_px": 1.5}, "min_pitch_px must be at least 2"),
        ({"min_pitch_px": 5.0, "max_pitch_px": 4.0}, "max_pitch_px must exceed min_pitch_px=5.0, got 4.0"),
        ({"min_pitch_px": 10.0, "max_pitch_px": 30.0}, "no micro-image lattice: .* between pitches 10 and 30 px"),
    ],
)
def test_bad_options_are_errors(whites, options, message):
    with pytest.raises(ParameterError, match=message):
        calibrate_mla(whites["hex"], **options)


def test_pitch_outside_the_range_is_an_error(whites):
    # The square lattice's first spectral shell (1 / pitch) lies inside the band searched for
    # pitches from 8.5 px (up to 2 / (sqrt(3) 8.5 px)), but its pitch does not.
    with pytest.raises(ParameterError, match=r"white's micro-image pitch 8.2\d* px is outside \[8.5, 30\]"):
        calibrate_mla(whites["square-rotated-offset"], min_pitch_px=8.5, max_pitch_px=30.0)


def test_few_micro_images_is_an_error(whites):
    """Micro-images only in a corner patch of an otherwise dark image: too few to fit."""
    white = np.zeros_like(whites["hex"])
    white[:24, :24] = whites["hex"][:24, :24]
    with pytest.raises(ParameterError, match="white"):
        calibrate_mla(white)


@pytest.mark.parametrize(
    ("sigma_px", "bound_px"), [(1.2, MLA_SOFT_WHITE_FITTED_MAX_PX), (1.5, MLA_SOFTER_WHITE_FITTED_MAX_PX)]
)
def test_soft_white_images_are_calibrated_without_bias(whites, sigma_px, bound_px):
    """A real white's micro-images have soft edges: the centroid windows must settle on them (a fixed
    three re-centring steps left 0.008 px of bias at 1.2 px), and gaps at 60 % of the centres (1.5 px)
    are still a white image's (a fixed gap ratio of 0.5 refused it)."""
    camera = small_camera()
    soft = ndimage.gaussian_filter(whites["hex"], sigma_px)
    cal = calibrate_mla(soft)
    truth = camera.micro_image_centres_px(camera.lens_indices_on_sensor())
    distance, _ = cKDTree(truth).query(cal.centres_px[cal.used])
    assert distance.max() < bound_px
