"""Image metrics: PSNR, SSIM inside a mask, and the aligning shift."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from lfrefract import ParameterError
from lfrefract.metrics import psnr, shift_px, ssim


def _texture(shape=(80, 100), seed=0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return ndimage.gaussian_filter(rng.random(shape), 2.0)


def test_psnr_of_a_known_error():
    a = np.zeros((10, 10))
    b = np.full((10, 10), 0.1)
    assert psnr(a, b, data_range=1.0) == pytest.approx(20.0)
    assert psnr(a, a, data_range=1.0) == float("inf")


def test_ssim_is_one_for_equal_images_and_ignores_pixels_outside_the_mask():
    img = _texture()
    assert ssim(img, img, data_range=1.0) == pytest.approx(1.0)
    other = img.copy()
    mask = np.zeros(img.shape, dtype=bool)
    mask[:, :50] = True
    other[:, 50:] = np.random.default_rng(1).random((80, 50))  # only outside the mask
    assert ssim(other, img, data_range=1.0, mask=mask) == pytest.approx(1.0)
    assert psnr(other, img, data_range=1.0, mask=mask) == float("inf")
    assert ssim(other, img, data_range=1.0) < 0.9


@pytest.mark.parametrize(("dx", "dy"), [(0.0, 0.0), (0.3, -0.7), (-1.25, 0.5)])
def test_shift_px_recovers_a_known_translation(dx, dy):
    reference = _texture((120, 140))
    # image(x + dx, y + dy) = reference(x, y): the content moves by (dx, dy).
    image = ndimage.shift(reference, (dy, dx), order=3, mode="nearest")
    mask = np.zeros(reference.shape, dtype=bool)
    mask[10:-10, 10:-10] = True
    got = shift_px(np.stack([image] * 3, axis=2), np.stack([reference] * 3, axis=2), mask=mask)
    np.testing.assert_allclose(got, (dx, dy), atol=0.05)  # spline shift and ECC convergence


def test_bad_input():
    a = np.zeros((4, 4))
    with pytest.raises(ParameterError, match="same shape"):
        psnr(a, np.zeros((4, 5)), data_range=1.0)
    with pytest.raises(ParameterError, match="mask selects no pixel"):
        ssim(a, a, data_range=1.0, mask=np.zeros((4, 4), dtype=bool))
    with pytest.raises(ParameterError, match="data_range must be positive"):
        psnr(a, a + 1, data_range=0.0)


def test_ray_errors_of_a_hand_computed_pair():
    """Two rays from the origin, one along +z, one tilted 0.01 rad about y: at the plane z = 2 m they
    are 2 tan(0.01) m apart and 0.01 rad; a NaN row (a vignetted pixel) is left out."""
    from lfrefract.metrics import ray_errors

    tilt = 0.01
    origins = np.zeros((3, 3))
    true = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [np.nan, np.nan, np.nan]])
    model = np.array([[np.sin(tilt), 0.0, np.cos(tilt)], [0.0, 0.0, 5.0], [0.0, 0.0, 1.0]])
    errors = ray_errors(origins, model, origins, true, plane_distance_m=2.0)
    assert errors.count == 2
    assert errors.position_max_m == pytest.approx(2.0 * np.tan(tilt), rel=1e-12)
    assert errors.position_rms_m == pytest.approx(2.0 * np.tan(tilt) / np.sqrt(2.0), rel=1e-12)
    assert errors.angle_max_rad == pytest.approx(tilt, rel=1e-9)
    tilted = ray_errors(origins, model, origins, true, plane_normal=(0.0, 0.0, 2.0), plane_distance_m=2.0)
    assert tilted.position_max_m == pytest.approx(errors.position_max_m, rel=1e-12)
    with pytest.raises(ParameterError, match="no pair"):
        ray_errors(origins, model, origins, true, plane_distance_m=2.0, valid=[False, False, False])


def test_ray_errors_along_the_axis_find_a_frame_moved_along_it():
    """A camera's rays with its frame's origin 1 mm off along the axis (what in-air boards leave
    free) are 0 from the truth up to that shift, found to 1e-12 m; without it they are not; a tilted
    comparison plane and an error that no shift removes are measured alike."""
    from lfrefract.metrics import ray_errors

    rng = np.random.default_rng(0)
    directions = np.column_stack([rng.uniform(-0.3, 0.3, (50, 2)), np.ones(50)])
    origins = np.column_stack([rng.uniform(-2e-3, 2e-3, (50, 2)), np.zeros(50)])
    moved = origins + np.array([0.0, 0.0, 1e-3])
    plane = {"plane_normal": (0.1, -0.2, 1.0), "plane_distance_m": 0.015}
    plain = ray_errors(moved, directions, origins, directions, **plane)
    assert plain.position_rms_m > 1e-4
    assert plain.axis_shift_m == 0.0
    aligned = ray_errors(moved, directions, origins, directions, along_axis=True, **plane)
    assert aligned.position_max_m < 1e-12
    assert aligned.axis_shift_m == pytest.approx(-1e-3, abs=1e-12)
    # A lateral offset no shift along z removes stays.
    lateral = ray_errors(moved + np.array([5e-5, 0.0, 0.0]), directions, origins, directions, along_axis=True, **plane)
    assert lateral.position_rms_m == pytest.approx(5e-5, rel=0.05)
