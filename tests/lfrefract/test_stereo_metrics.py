"""Stereo evaluation: RANSAC plane fit, depth and disparity errors, PLY point clouds."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest

from lfrefract import ParameterError
from lfrefract.errors import FileFormatError
from lfrefract.formats.ply import read_ply, write_ply
from lfrefract.metrics import DepthErrors, depth_errors, disparity_errors, fit_plane_ransac
from tests.tolerances import (
    FLOAT64_UNIT,
    RANSAC_INLIER_RECALL_MIN,
    RANSAC_NORMAL_DEG,
    RANSAC_OFFSET_M,
    RANSAC_OUTLIERS_KEPT_MAX,
    RANSAC_RMSE_RELATIVE,
)

SIGMA_M = 1e-3
THRESHOLD_M = 4e-3


def noisy_plane_with_outliers(seed: int, n_in: int = 1400, n_out: int = 600):
    """Points of the plane n . X = 0.8 m (0.5 m square, 1 mm normal noise) plus 30 % uniform outliers
    in a 0.5 m cube around it; returns the shuffled points, the inlier truth, n and the offset."""
    rng = np.random.default_rng(seed)
    n = np.array([0.1, -0.2, 1.0]) / np.linalg.norm([0.1, -0.2, 1.0])
    offset = 0.8
    e1 = np.cross(n, [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    uv = rng.uniform(-0.25, 0.25, (n_in, 2))
    inliers = n * offset + uv[:, :1] * e1 + uv[:, 1:] * e2 + rng.normal(0.0, SIGMA_M, (n_in, 1)) * n
    outliers = n * offset + rng.uniform(-0.25, 0.25, (n_out, 3))
    order = rng.permutation(n_in + n_out)
    points = np.concatenate([inliers, outliers])[order]
    truth = np.concatenate([np.ones(n_in, bool), np.zeros(n_out, bool)])[order]
    return points, truth, n, offset


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_ransac_finds_the_plane_among_30_percent_outliers(seed):
    points, truth, n, offset = noisy_plane_with_outliers(seed)
    fit = fit_plane_ransac(points, threshold_m=THRESHOLD_M, seed=seed)
    np.testing.assert_allclose(np.linalg.norm(fit.normal), 1.0, atol=FLOAT64_UNIT)
    assert fit.offset_m > 0  # oriented away from the origin
    assert math.degrees(math.acos(min(1.0, float(fit.normal @ n)))) <= RANSAC_NORMAL_DEG
    assert abs(fit.offset_m - offset) <= RANSAC_OFFSET_M
    # The true inliers are kept; of the outliers, only about those that happen to lie in the
    # +-4 mm band around the plane (1.6 % of a 0.5 m cube).
    assert fit.inliers[truth].mean() >= RANSAC_INLIER_RECALL_MIN
    assert fit.inliers[~truth].mean() <= RANSAC_OUTLIERS_KEPT_MAX
    # The inlier residual is the added noise (a 4-sigma band truncates it by 0.1 %).
    assert abs(fit.rmse_m / SIGMA_M - 1.0) <= RANSAC_RMSE_RELATIVE
    residual = fit.distances_m(points[fit.inliers])
    assert math.sqrt(np.mean(residual**2)) == pytest.approx(fit.rmse_m, rel=1e-12)
    assert np.all(np.abs(residual) <= THRESHOLD_M)
    # Deterministic for a seed.
    again = fit_plane_ransac(points, threshold_m=THRESHOLD_M, seed=seed)
    np.testing.assert_array_equal(again.normal, fit.normal)
    # A plain least-squares fit through everything would be far off: the outliers dominate.
    centred = points - points.mean(axis=0)
    assert np.linalg.svd(centred, compute_uv=False)[-1] / math.sqrt(len(points)) > 20 * SIGMA_M


def test_ransac_bad_input():
    points = np.random.default_rng(0).random((10, 3))
    with pytest.raises(ParameterError, match="threshold_m must be positive"):
        fit_plane_ransac(points, threshold_m=0.0)
    with pytest.raises(ParameterError, match="iterations must be positive"):
        fit_plane_ransac(points, threshold_m=0.1, iterations=0)
    with pytest.raises(ParameterError, match="at least 3 points"):
        fit_plane_ransac(points[:2], threshold_m=0.1)
    with pytest.raises(ParameterError, match=r"points_m must have shape \(N, 3\)"):
        fit_plane_ransac(points[:, :2], threshold_m=0.1)
    bad = points.copy()
    bad[4, 1] = np.nan
    with pytest.raises(ParameterError, match="points_m must be finite"):
        fit_plane_ransac(bad, threshold_m=0.1)
    line = np.outer(np.arange(10.0), [1.0, 2.0, 3.0])
    with pytest.raises(ParameterError, match="collinear"):
        fit_plane_ransac(line, threshold_m=0.1)


def test_depth_errors_of_known_values():
    truth = np.array([[1.0, 2.0, np.inf], [1.0, 1.0, np.nan]])
    depth = np.array([[1.1, 1.8, 5.0], [np.nan, 1.0, 3.0]])
    got = depth_errors(depth, truth)
    # Truth-valid: 4 pixels; estimates on 3 of them, errors +0.1, -0.2, 0.
    assert isinstance(got, DepthErrors)
    assert got.count == 3
    assert got.completeness == pytest.approx(0.75)
    assert got.mean_abs_m == pytest.approx(0.1)
    assert got.rms_m == pytest.approx(math.sqrt(0.05 / 3))
    assert got.bias_m == pytest.approx(-0.1 / 3)
    only_first_row = depth_errors(depth, truth, valid=np.array([[True, True, True], [False, False, False]]))
    assert only_first_row.count == 2
    assert only_first_row.completeness == 1.0
    empty = depth_errors(np.full_like(depth, np.nan), truth)
    assert empty.completeness == 0.0
    assert math.isnan(empty.rms_m)
    with pytest.raises(ParameterError, match="same shape"):
        depth_errors(depth[:, :2], truth)
    with pytest.raises(ParameterError, match="no pixel has a finite truth"):
        depth_errors(depth, np.full_like(truth, np.inf))
    with pytest.raises(ParameterError, match="valid must be a boolean array"):
        depth_errors(depth, truth, valid=np.ones(truth.shape))


def test_disparity_errors_are_middlebury_bad_pixel_rates():
    truth = np.array([[10.0, 10.0, 10.0, 10.0, 10.0], [10.0, 10.0, 10.0, np.nan, np.inf]])
    est = np.array([[10.0, 10.4, 10.7, 11.5, 13.0], [5.0, np.nan, np.nan, 3.0, 3.0]])
    got = disparity_errors(est, truth)
    # 8 truth-valid pixels; errors 0, 0.4, 0.7, 1.5, 3, 5 and two missing (missing counts as bad).
    assert got.thresholds_px == (0.5, 1.0, 2.0, 4.0)
    np.testing.assert_allclose(got.bad_fractions, [6 / 8, 5 / 8, 4 / 8, 3 / 8])
    assert got.bad(1.0) == pytest.approx(5 / 8)
    assert got.count == 6
    assert got.completeness == pytest.approx(6 / 8)
    assert got.mean_abs_px == pytest.approx((0.4 + 0.7 + 1.5 + 3 + 5) / 6)
    assert got.rms_px == pytest.approx(math.sqrt((0.16 + 0.49 + 2.25 + 9 + 25) / 6))
    assert disparity_errors(est, truth, thresholds_px=(3.0,)).bad_fractions == (3 / 8,)  # |error| > 3 only
    with pytest.raises(ParameterError, match=r"thresholds_px\[1\] must be positive"):
        disparity_errors(est, truth, thresholds_px=(1.0, 0.0))
    with pytest.raises(ParameterError, match="threshold_px must be one of"):
        got.bad(3.0)
    with pytest.raises(ParameterError, match="infinite"):
        disparity_errors(np.full_like(est, np.inf), truth)


# =============================================================================== PLY
def test_ply_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    points = rng.normal(size=(500, 3))
    colors = rng.integers(0, 256, (500, 3), dtype=np.uint8)
    path = write_ply(tmp_path / "cloud.ply", points, colors)
    assert path == tmp_path / "cloud.ply"
    got, got_colors = read_ply(path)
    np.testing.assert_array_equal(got, points.astype(np.float32).astype(np.float64))
    np.testing.assert_array_equal(got_colors, colors)
    assert got_colors.dtype == np.uint8
    # Header, then 15 bytes per vertex (3 float32 + 3 uint8).
    data = path.read_bytes()
    assert data.startswith(b"ply\nformat binary_little_endian 1.0\n")
    assert b"property float x" in data
    assert b"property uchar red" in data
    assert len(data) - (data.index(b"end_header\n") + len(b"end_header\n")) == 500 * 15
    # Without colours; and an empty cloud; overwriting leaves only the file.
    write_ply(path, points[:7])
    got, got_colors = read_ply(path)
    assert got_colors is None
    assert got.shape == (7, 3)
    write_ply(tmp_path / "empty.ply", np.zeros((0, 3)))
    assert read_ply(tmp_path / "empty.ply")[0].shape == (0, 3)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cloud.ply", "empty.ply"]


def test_ply_bad_input_leaves_nothing_behind(tmp_path, monkeypatch):
    points = np.zeros((4, 3))
    cases = [
        (lambda: write_ply(tmp_path / "a.ply", np.zeros((4, 2))), r"points_m must have shape \(N, 3\)"),
        (lambda: write_ply(tmp_path / "a.ply", np.full((4, 3), np.nan)), "points_m must be finite"),
        (lambda: write_ply(tmp_path / "a.ply", points, np.zeros((3, 3), np.uint8)), r"colors must have shape"),
        (lambda: write_ply(tmp_path / "a.ply", points, np.full((4, 3), 0.5)), "colors must hold integers"),
        (lambda: write_ply(tmp_path / "a.ply", points, np.full((4, 3), 256)), r"colors must lie in 0..255"),
        (lambda: write_ply(tmp_path / "a.ply", np.full((4, 3), 1e39)), "beyond float32"),
    ]
    for call, message in cases:
        with pytest.raises(ParameterError, match=message):
            call()

    def fail(*args):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", fail)
    with pytest.raises(OSError, match="disk full"):
        write_ply(tmp_path / "a.ply", points)
    assert list(tmp_path.iterdir()) == []


def test_read_ply_refuses_other_files(tmp_path):
    with pytest.raises(FileFormatError, match="no such file"):
        read_ply(tmp_path / "missing.ply")
    (tmp_path / "text.ply").write_text("hello\n")
    with pytest.raises(FileFormatError, match="not a PLY file"):
        read_ply(tmp_path / "text.ply")
    (tmp_path / "ascii.ply").write_text("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n1\n")
    with pytest.raises(FileFormatError, match="not a binary little-endian"):
        read_ply(tmp_path / "ascii.ply")
    path = write_ply(tmp_path / "cut.ply", np.ones((10, 3)))
    path.write_bytes(path.read_bytes()[:-5])
    with pytest.raises(FileFormatError, match="truncated"):
        read_ply(path)
    header = "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n"
    (tmp_path / "flat.ply").write_bytes(header.encode() + bytes(8))
    with pytest.raises(FileFormatError, match="x, y and z"):
        read_ply(tmp_path / "flat.ply")
