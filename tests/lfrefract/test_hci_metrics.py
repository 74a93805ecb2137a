"""The HCI 4D light field benchmark's disparity scores (lfrefract.metrics.hci_*).

The expected figures are worked out by hand in the comments, from the definitions in the
benchmark's evaluation toolkit (toolkit/metrics/general_metrics.py: MSE x 100 over the evaluation
mask, BadPix as the percentage of mask pixels with |error| > t; toolkit/scenes/base_scene.py: a
15 px border left out).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from lfrefract.errors import ParameterError
from lfrefract.metrics import (
    HCI_BADPIX_THRESHOLDS_PX,
    HCI_BOUNDARY_PX,
    HciScores,
    hci_badpix,
    hci_mse_x100,
    hci_scores,
)
from tests.tolerances import HCI_SCORE_RELATIVE

# A 4 x 5 truth of powers of two and short sums of them, so that truth + error is exact.
TRUTH = np.array(
    [
        [1.0, 0.5, -0.5, 2.0, 0.25],
        [0.0, 1.5, -1.0, 0.75, 1.25],
        [-0.25, 0.125, 3.0, 1.0, -2.0],
        [0.5, 0.5, 0.5, 0.5, 0.5],
    ]
)
# Estimate - truth, px: eight non-zero errors, all powers of two.
ERRORS = np.array(
    [
        [0.0, 2.0**-7, -(2.0**-6), 2.0**-4, -(2.0**-3)],
        [0.0, 0.0, 2.0**-5, -(2.0**-2), 0.0],
        [0.0, -(2.0**-7), 0.0, 2.0**-1, 0.0],
        [0.0, 0.0, 0.0, 0.0, 0.0],
    ]
)
ESTIMATE = TRUTH + ERRORS
# By hand, over the 20 pixels:
#   |errors| = 0.0078125 (twice), 0.015625, 0.0625, 0.125, 0.03125, 0.25, 0.5, and twelve zeros.
#   > 0.01: 0.015625, 0.0625, 0.125, 0.03125, 0.25, 0.5 -> 6 pixels -> 6 / 20 = 30 %
#   > 0.03: 0.0625, 0.125, 0.03125, 0.25, 0.5           -> 5 pixels -> 25 %
#   > 0.07: 0.125, 0.25, 0.5                             -> 3 pixels -> 15 %
#   squares: 2 * 2^-14 + 2^-12 + 2^-8 + 2^-6 + 2^-10 + 2^-4 + 2^-2
#          = 0.0001220703125 + 0.000244140625 + 0.00390625 + 0.015625 + 0.0009765625 + 0.0625 + 0.25
#          = 0.3333740234375
#   MSE x 100 = 100 * 0.3333740234375 / 20 = 1.6668701171875
SUM_OF_SQUARES = 0.3333740234375
MSE_X100 = 1.6668701171875
BADPIX = {0.01: 30.0, 0.03: 25.0, 0.07: 15.0}


def approx(value: float):
    return pytest.approx(value, rel=HCI_SCORE_RELATIVE, abs=0.0)


def check(scores: HciScores, mse: float, bad: tuple[float, float, float], count: int, missing: int = 0) -> None:
    assert scores.mse_x100 == approx(mse)
    assert (scores.badpix_0_01, scores.badpix_0_03, scores.badpix_0_07) == tuple(approx(b) for b in bad)
    assert (scores.count, scores.missing) == (count, missing)


# =============================================================================== the benchmark's figures
def test_the_toolkit_constants():
    assert HCI_BOUNDARY_PX == 15
    assert HCI_BADPIX_THRESHOLDS_PX == (0.01, 0.03, 0.07)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_hand_computed_scores(dtype):
    est, truth = ESTIMATE.astype(dtype), TRUTH.astype(dtype)
    assert hci_mse_x100(est, truth, boundary_px=0) == approx(MSE_X100)
    for t, expected in BADPIX.items():
        assert hci_badpix(est, truth, threshold_px=t, boundary_px=0) == approx(expected)
    check(hci_scores(est, truth, boundary_px=0), MSE_X100, (30.0, 25.0, 15.0), 20)
    # The sign of the error does not matter; a perfect estimate scores 0 everywhere.
    check(hci_scores(truth - ERRORS.astype(dtype), truth, boundary_px=0), MSE_X100, (30.0, 25.0, 15.0), 20)
    check(hci_scores(truth, truth, boundary_px=0), 0.0, (0.0, 0.0, 0.0), 20)


def test_badpix_is_a_percentage_of_the_evaluated_pixels():
    # One pixel of 20 off by 1 px: 5 %, not 0.05.
    est = TRUTH.copy()
    est[3, 4] += 1.0
    assert hci_badpix(est, TRUTH, threshold_px=0.07, boundary_px=0) == approx(5.0)
    # MSE x 100: 100 * 1^2 / 20 = 5.
    assert hci_mse_x100(est, TRUTH, boundary_px=0) == approx(5.0)


def test_integer_maps_are_accepted():
    # Integer disparities (px): errors 0, 1, 0, 2 -> squares 0 + 1 + 0 + 4 = 5 -> 100 * 5 / 4 = 125.
    est = np.array([[1, 2], [3, 6]])
    truth = np.array([[1, 1], [3, 4]])
    assert hci_mse_x100(est, truth, boundary_px=0) == approx(125.0)
    assert hci_badpix(est, truth, threshold_px=1.0, boundary_px=0) == approx(25.0)  # only the 2 px error is > 1


# =============================================================================== boundary
def embedded(border: int, fill_estimate: float) -> tuple[np.ndarray, np.ndarray]:
    """The hand case inside a frame of ``border`` pixels whose estimates are ``fill_estimate`` (truth 0)."""
    est = np.full((4 + 2 * border, 5 + 2 * border), fill_estimate)
    truth = np.zeros_like(est)
    est[border : border + 4, border : border + 5] = ESTIMATE
    truth[border : border + 4, border : border + 5] = TRUTH
    return est, truth


@pytest.mark.parametrize("fill", [10.0, np.nan, -np.inf])
def test_the_border_is_left_out(fill):
    est, truth = embedded(1, fill)
    check(hci_scores(est, truth, boundary_px=1), MSE_X100, (30.0, 25.0, 15.0), 20)


def test_the_default_border_is_15_px():
    # A 34 x 35 map: rows 15..18 and columns 15..19 (the hand case) are all that is evaluated.
    est, truth = embedded(15, 1.0)
    check(hci_scores(est, truth), MSE_X100, (30.0, 25.0, 15.0), 20)
    assert hci_mse_x100(est, truth) == approx(MSE_X100)
    assert hci_badpix(est, truth, threshold_px=0.07) == approx(15.0)
    # A 14 px border takes in a ring of 2 * (6 + 7) - 4 = 22 more pixels, each off by 1 px:
    # 42 pixels, 6 + 22 = 28, 5 + 22 = 27 and 3 + 22 = 25 of them bad; squares 0.33337... + 22.
    check(
        hci_scores(est, truth, boundary_px=14),
        100 * (SUM_OF_SQUARES + 22) / 42,
        (100 * 28 / 42, 100 * 27 / 42, 100 * 25 / 42),
        42,
    )
    # No border: 34 * 35 = 1190 pixels, of which 1170 are off by 1 px.
    check(
        hci_scores(est, truth, boundary_px=0),
        100 * (SUM_OF_SQUARES + 1170) / 1190,
        (100 * 1176 / 1190, 100 * 1175 / 1190, 100 * 1173 / 1190),
        1190,
    )


def test_a_border_that_leaves_nothing_is_refused():
    with pytest.raises(ParameterError, match=r"boundary_px = 15 leaves no pixel of a 30 x 40 map"):
        hci_scores(np.zeros((30, 40)), np.zeros((30, 40)))
    with pytest.raises(ParameterError, match=r"boundary_px = 2 leaves no pixel of a 4 x 5 map"):
        hci_mse_x100(ESTIMATE, TRUTH, boundary_px=2)
    # One row left is enough: 31 x 40 keeps row 15, columns 15..24.
    assert hci_scores(np.zeros((31, 40)), np.zeros((31, 40))).count == 10


# =============================================================================== mask, missing values
def test_mask_selects_the_pixels():
    mask = np.ones(TRUTH.shape, dtype=bool)
    mask[2, 3] = False  # the 0.5 px error
    # 19 pixels; bad 5, 4, 2; squares 0.3333740234375 - 0.25 = 0.0833740234375.
    expected_mse = 100 * 0.0833740234375 / 19
    check(
        hci_scores(ESTIMATE, TRUTH, mask=mask, boundary_px=0),
        expected_mse,
        (100 * 5 / 19, 100 * 4 / 19, 100 * 2 / 19),
        19,
    )
    assert hci_mse_x100(ESTIMATE, TRUTH, mask=mask, boundary_px=0) == approx(expected_mse)
    assert hci_badpix(ESTIMATE, TRUTH, threshold_px=0.07, mask=mask, boundary_px=0) == approx(100 * 2 / 19)
    # The mask and the border combine: in the 6 x 7 frame only the hand case's 20 pixels remain
    # even though the mask selects everything.
    est, truth = embedded(1, 10.0)
    check(hci_scores(est, truth, mask=np.ones(est.shape, dtype=bool), boundary_px=1), MSE_X100, (30, 25, 15), 20)


@pytest.mark.parametrize("missing", [np.nan, np.inf, -np.inf])
@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_a_missing_estimate_is_bad_and_left_out_of_the_mse(missing, dtype):
    est = ESTIMATE.astype(dtype)
    est[0, 0] = missing  # its error was 0
    truth = TRUTH.astype(dtype)
    # BadPix: 6 + 1, 5 + 1, 3 + 1 of 20. MSE over the 19 pixels with an estimate: same squares.
    expected = (100 * SUM_OF_SQUARES / 19, (35.0, 30.0, 20.0))
    check(hci_scores(est, truth, boundary_px=0), expected[0], expected[1], 20, missing=1)
    assert hci_badpix(est, truth, threshold_px=0.07, boundary_px=0) == approx(20.0)
    assert hci_mse_x100(est, truth, boundary_px=0) == approx(expected[0])


def test_no_estimate_at_all():
    est = np.full(TRUTH.shape, np.nan)
    scores = hci_scores(est, TRUTH, boundary_px=0)
    assert np.isnan(scores.mse_x100)
    check(dataclasses.replace(scores, mse_x100=0.0), 0.0, (100.0, 100.0, 100.0), 20, missing=20)
    assert np.isnan(hci_mse_x100(est, TRUTH, boundary_px=0))


@pytest.mark.parametrize("no_truth", [np.nan, np.inf])
def test_pixels_without_truth_are_left_out(no_truth):
    truth = TRUTH.copy()
    truth[2, 3] = no_truth  # the 0.5 px error's pixel: as if masked
    check(
        hci_scores(ESTIMATE, truth, boundary_px=0),
        100 * 0.0833740234375 / 19,
        (100 * 5 / 19, 100 * 4 / 19, 100 * 2 / 19),
        19,
    )


# =============================================================================== threshold edge
def test_an_error_equal_to_the_threshold_is_not_bad():
    # The toolkit's test is |error| > t, strictly.
    truth = np.zeros((1, 3))
    est = np.array([[0.07, np.nextafter(0.07, 1.0), 0.03]])
    # At 0.07: only the second (one ulp above) is bad -> 1 / 3. At 0.03: the first two -> 2 / 3.
    assert hci_badpix(est, truth, threshold_px=0.07, boundary_px=0) == approx(100 / 3)
    assert hci_badpix(est, truth, threshold_px=0.03, boundary_px=0) == approx(200 / 3)
    assert hci_badpix(-est, truth, threshold_px=0.07, boundary_px=0) == approx(100 / 3)
    # Exactly representable: an error of 0.5 at t = 0.5 is good, at t = 0.25 bad.
    assert hci_badpix(np.array([[0.5]]), np.zeros((1, 1)), threshold_px=0.5, boundary_px=0) == 0.0
    assert hci_badpix(np.array([[0.5]]), np.zeros((1, 1)), threshold_px=0.25, boundary_px=0) == 100.0


def test_float32_maps_compare_in_float32_as_the_toolkit_does():
    # The toolkit reads float32 PFM maps and compares |algo - gt| with the threshold in float32, so
    # an error of float32(0.07) = 0.0700000003 is equal to the threshold there, not above it.
    truth = np.zeros((1, 2), dtype=np.float32)
    est = np.array([[0.07, np.nextafter(np.float32(0.07), np.float32(1.0))]], dtype=np.float32)
    assert hci_badpix(est, truth, threshold_px=0.07, boundary_px=0) == approx(50.0)
    assert hci_scores(est, truth, boundary_px=0).badpix_0_07 == approx(50.0)
    # With a float64 map involved the comparison is in float64, where 0.0700000003 > 0.07.
    assert hci_badpix(est, truth.astype(np.float64), threshold_px=0.07, boundary_px=0) == 100.0


# =============================================================================== bad input
@pytest.mark.parametrize(
    ("est", "truth", "pattern"),
    [
        (
            np.zeros((4, 5)),
            np.zeros((4, 6)),
            r"disparity_px and truth_px must have the same shape, got \(4, 5\) and \(4, 6",
        ),
        (np.zeros((4, 5, 1)), np.zeros((4, 5, 1)), r"disparity_px must have shape \(H, W\), got \(4, 5, 1\)"),
        (np.zeros((4, 5)), np.zeros(20), r"truth_px must have shape \(H, W\), got \(20,\)"),
        (np.zeros((4, 5), dtype=bool), np.zeros((4, 5)), r"disparity_px must hold real numbers .*got dtype bool"),
        (np.zeros((4, 5)), np.full((4, 5), "a"), r"truth_px must hold real numbers .*got dtype <U1"),
        (np.zeros((4, 5), dtype=complex), np.zeros((4, 5)), r"disparity_px must hold real numbers .*complex128"),
        ([[1.0, 2.0], [3.0]], np.zeros((2, 2)), r"disparity_px must be an \(H, W\) array of real numbers"),
    ],
)
def test_bad_maps_are_refused(est, truth, pattern):
    for call in (
        lambda: hci_mse_x100(est, truth, boundary_px=0),
        lambda: hci_badpix(est, truth, threshold_px=0.07, boundary_px=0),
        lambda: hci_scores(est, truth, boundary_px=0),
    ):
        with pytest.raises(ParameterError, match=pattern):
            call()


@pytest.mark.parametrize(
    ("kwargs", "pattern"),
    [
        ({"boundary_px": -1}, r"boundary_px must be a non-negative integer, got -1"),
        ({"boundary_px": 1.5}, r"boundary_px must be a non-negative integer, got 1.5"),
        ({"boundary_px": True}, r"boundary_px must be a non-negative integer, got True"),
        ({"mask": np.ones((4, 5), dtype=np.uint8)}, r"mask must be a boolean array of shape \(4, 5\), got uint8"),
        ({"mask": np.ones((5, 4), dtype=bool)}, r"mask must be a boolean array of shape \(4, 5\), got bool \(5, 4\)"),
        ({"mask": np.zeros((4, 5), dtype=bool)}, r"no pixel to evaluate: mask, the border of boundary_px = 0"),
    ],
)
def test_bad_options_are_refused(kwargs, pattern):
    options = {"boundary_px": 0, **kwargs}
    with pytest.raises(ParameterError, match=pattern):
        hci_scores(ESTIMATE, TRUTH, **options)
    with pytest.raises(ParameterError, match=pattern):
        hci_badpix(ESTIMATE, TRUTH, threshold_px=0.07, **options)


def test_no_truth_at_all_is_refused():
    with pytest.raises(ParameterError, match="finite values of truth_px leave none"):
        hci_mse_x100(ESTIMATE, np.full(TRUTH.shape, np.nan), boundary_px=0)


@pytest.mark.parametrize(
    ("threshold", "pattern"),
    [(0.0, "must be positive"), (-0.07, "must be positive"), (np.nan, "finite"), ("0.07", "")],
)
def test_bad_thresholds_are_refused(threshold, pattern):
    with pytest.raises(ParameterError, match=f"threshold_px.*{pattern}"):
        hci_badpix(ESTIMATE, TRUTH, threshold_px=threshold, boundary_px=0)


def test_scores_are_frozen():
    scores = hci_scores(ESTIMATE, TRUTH, boundary_px=0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        scores.mse_x100 = 0.0  # type: ignore[misc]
