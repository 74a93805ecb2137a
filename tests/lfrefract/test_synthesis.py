"""The warp map: structure, weights, geometry of the selected rays, files, and bad input."""

from __future__ import annotations

import dataclasses
import functools
import json
import re
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import lfrefract.synthesis.warp_map as synthesis
from lfrefract import FlatPort, ParameterError, PinholeCamera, camera_preset, virtual_camera_for
from lfrefract.errors import FileFormatError
from lfrefract.optics.ray_correction import RayCorrection
from lfrefract.synthesis._raytree import RayTree
from lfrefract.synthesis.warp_map import (
    SynthesisOptions,
    WarpMap,
    build_warp_map,
    lens_plane_hits,
    necessary_air_rays,
    warp_map_key,
)
from tests.tolerances import FLOAT32_WEIGHT_SUM, FLOAT64_RELATIVE, FLOAT64_UNIT

TINY = camera_preset("tiny")
PORT = FlatPort.from_degrees(distance_m=0.012, thickness_m=0.004, tilt_x_deg=15.0, tilt_y_deg=-5.0)
NO_PORT = FlatPort(distance_m=0.012, thickness_m=0.004, n_air=1.0, n_glass=1.0, n_water=1.0)


@pytest.fixture(scope="module")
def warp():
    return build_warp_map(TINY, PORT)


def test_rows_are_normalised_non_negative_and_in_range(warp):
    rows = np.diff(warp.indptr)
    sums = np.add.reduceat(warp.weights.astype(np.float64), warp.indptr[:-1][rows > 0])
    np.testing.assert_allclose(sums, 1.0, atol=FLOAT32_WEIGHT_SUM)
    assert np.all(np.isfinite(warp.weights))
    assert np.all(warp.weights > 0)
    assert warp.indices.min() >= 0
    assert warp.indices.max() < TINY.sensor.width_px * TINY.sensor.height_px
    # Within a row each raw pixel appears once (duplicates from sub-samples are merged).
    for p in np.flatnonzero(rows)[::97]:
        row = warp.indices[warp.indptr[p] : warp.indptr[p + 1]]
        assert len(np.unique(row)) == len(row)


@settings(max_examples=12, deadline=None)
@given(
    tilt_x=st.floats(-30, 30),
    tilt_y=st.floats(-30, 30),
    k=st.integers(1, 40),
    supersample=st.integers(1, 3),
    lam=st.sampled_from([0.0, 1e-3, 0.05]),
)
def test_weights_hold_for_any_port_and_options(tilt_x, tilt_y, k, supersample, lam):
    port = FlatPort.from_degrees(distance_m=0.01, thickness_m=0.003, tilt_x_deg=tilt_x, tilt_y_deg=tilt_y)
    options = SynthesisOptions(k=k, supersample=supersample, lambda_m_per_rad=lam)
    warp = build_warp_map(TINY, port, options=options)
    rows = np.diff(warp.indptr)
    assert rows.max() <= k * supersample**2
    filled = rows > 0
    sums = np.add.reduceat(warp.weights.astype(np.float64), warp.indptr[:-1][filled])
    np.testing.assert_allclose(sums, 1.0, atol=FLOAT32_WEIGHT_SUM)
    assert np.all(warp.weights > 0)
    assert np.all(np.isfinite(warp.gain))
    # Exactly covered pixels always get rays.
    assert np.all(warp.filled[warp.exact])


def test_map_does_not_depend_on_candidate_order(monkeypatch):
    plain = build_warp_map(TINY, PORT)
    original = synthesis._lens_offsets

    def shuffled(camera, rings):
        offsets = original(camera, rings)
        return offsets[np.random.default_rng(5).permutation(len(offsets))]

    monkeypatch.setattr(synthesis, "_lens_offsets", shuffled)
    permuted = build_warp_map(TINY, PORT)
    dense = lambda w: _dense_rows(w, np.arange(0, len(w.gain), 37))  # noqa: E731
    np.testing.assert_allclose(dense(permuted), dense(plain), atol=FLOAT32_WEIGHT_SUM)


def _dense_rows(warp, rows):
    out = np.zeros((len(rows), warp.raw_shape[0] * warp.raw_shape[1]))
    for n, p in enumerate(rows):
        sl = slice(warp.indptr[p], warp.indptr[p + 1])
        out[n, warp.indices[sl]] = warp.weights[sl]
    return out


def test_without_refraction_the_chosen_rays_follow_the_line_of_sight():
    """k = 1, one ray per pixel, equal indices: the selected captured ray passes the necessary
    ray's point on the port within the spacing of captured rays, with the line of sight's direction
    to within one microlens's angular pitch."""
    options = SynthesisOptions(k=1, supersample=1)
    warp = build_warp_map(TINY, NO_PORT, options=options)
    assert warp.exact.all()
    assert warp.filled.all()
    out = warp.output
    directions = out.pixel_directions()
    chosen = warp.indices[warp.indptr[:-1]]
    uv = np.stack([chosen % TINY.sensor.width_px, chosen // TINY.sensor.width_px], axis=1).astype(float)
    rays = TINY.captured_rays(uv)
    assert rays.in_aperture.all()
    angle = np.arccos(np.clip(np.sum(rays.directions_cam * directions, axis=1), -1, 1))
    # With lambda = 0 only the position on the face counts, so a ray from a neighbouring lens
    # (one lens pitch seen from the main lens is pitch / f' of angle) may win.
    lens_angle = TINY.mla.pitch_m / TINY.lens_to_mla_m
    assert np.max(angle) < (options.lens_rings + 1) * lens_angle
    trace = NO_PORT.trace_from_air(rays.origins_cam, rays.directions_cam)
    points, _, _, _ = necessary_air_rays(NO_PORT, directions)
    miss_m = np.linalg.norm(trace.entry_points_cam - points, axis=1)
    # Neighbouring pixels' rays are this far apart on the face: pixel pitch * f' / f_mla (+ the face).
    spacing = TINY.sensor.pixel_pitch_m * TINY.lens_to_mla_m / TINY.mla.focal_length_m
    assert np.median(miss_m) < spacing
    np.testing.assert_allclose(warp.gain, 1.0, atol=FLOAT64_UNIT)  # no port, no radiometric factor


def test_a_large_angle_weight_keeps_the_direction():
    """lambda >> port distance: the direction dominates D, so the chosen ray comes from the lens
    the necessary ray crosses, within half a lens pitch of angle (plus the pixel's own step)."""
    warp = build_warp_map(TINY, NO_PORT, options=SynthesisOptions(k=1, supersample=1, lambda_m_per_rad=10.0))
    chosen = warp.indices[warp.indptr[:-1]]
    uv = np.stack([chosen % TINY.sensor.width_px, chosen // TINY.sensor.width_px], axis=1).astype(float)
    rays = TINY.captured_rays(uv)
    angle = np.arccos(np.clip(np.sum(rays.directions_cam * warp.output.pixel_directions(), axis=1), -1, 1))
    lens_angle = TINY.mla.pitch_m / TINY.lens_to_mla_m
    assert np.max(angle) < 0.6 * lens_angle


def test_necessary_air_rays_reverse_the_port():
    directions = virtual_camera_for(TINY).pixel_directions()
    points, out_dirs, transmittance, valid = necessary_air_rays(PORT, directions)
    assert valid.all()
    # Tracing the air ray outwards again lands on the line of sight in the water.
    forward = PORT.trace_from_air(points - out_dirs * 1e-9, out_dirs)
    cross = np.cross(forward.exit_points_cam, directions)
    np.testing.assert_allclose(cross, 0.0, atol=1e-9)
    np.testing.assert_allclose(forward.directions_cam, directions, atol=1e-9)
    assert np.all((transmittance > 0.8) & (transmittance <= 1.0))


def test_save_load_round_trip_and_stale_key(tmp_path, warp):
    path = warp.save(tmp_path / "map.npz")
    loaded = WarpMap.load(path, expected_key=warp.key)
    for name in ("indptr", "indices", "weights", "gain", "coverage"):
        np.testing.assert_array_equal(getattr(loaded, name), getattr(warp, name))
    assert loaded.output == warp.output
    other = warp_map_key(TINY, PORT, warp.output, SynthesisOptions(k=warp.meta["options"]["k"] + 1))
    with pytest.raises(FileFormatError, match="other parameters"):
        WarpMap.load(path, expected_key=other)
    with pytest.raises(FileFormatError, match="no such file"):
        WarpMap.load(tmp_path / "none.npz")
    (tmp_path / "bad.npz").write_bytes(b"not a map")
    with pytest.raises(FileFormatError, match="is not a warp map"):
        WarpMap.load(tmp_path / "bad.npz")
    # A map cut short (an interrupted copy) is a format error too, not a zipfile exception.
    data = path.read_bytes()
    (tmp_path / "cut.npz").write_bytes(data[: len(data) // 2])
    with pytest.raises(FileFormatError, match="is not a warp map"):
        WarpMap.load(tmp_path / "cut.npz")


def test_key_changes_with_every_input(warp):
    out = warp.output
    keys = {
        warp.key,
        warp_map_key(TINY, PORT, out, SynthesisOptions(k=31)),
        warp_map_key(TINY, PORT, out, SynthesisOptions(supersample=3)),
        warp_map_key(
            TINY,
            FlatPort.from_degrees(distance_m=0.012, thickness_m=0.004, tilt_x_deg=15.0001, tilt_y_deg=-5.0),
            out,
            SynthesisOptions(),
        ),
        warp_map_key(camera_preset("f01"), PORT, out, SynthesisOptions()),
    }
    assert len(keys) == 5


def test_apply_accepts_rgb_grey_and_integers(warp):
    rng = np.random.default_rng(0)
    raw = rng.uniform(0, 1, size=(*warp.raw_shape, 3)).astype(np.float32)
    rgb = warp.apply(raw)
    grey = warp.apply(raw[..., 1])
    assert rgb.shape == (warp.output.height_px, warp.output.width_px, 3)
    np.testing.assert_allclose(grey, rgb[..., 1], rtol=1e-6)
    ints = warp.apply((raw * 1000).astype(np.uint16))
    np.testing.assert_allclose(ints, warp.apply(np.floor(raw * 1000)), rtol=1e-6)
    # A constant raw image gives that constant times the gain wherever rays were found.
    constant = warp.apply(np.full(warp.raw_shape, 2.0, dtype=np.float32))
    np.testing.assert_allclose(constant[warp.filled], 2.0 * warp.gain.reshape(constant.shape)[warp.filled], rtol=1e-5)
    assert np.all(constant[~warp.filled] == 0.0)
    with pytest.raises(ParameterError, match="raw must have shape"):
        warp.apply(raw[:-1])


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"k": 0}, "k must be positive, got 0"),
        ({"supersample": -1}, "supersample must be positive, got -1"),
        ({"lambda_m_per_rad": float("nan")}, "lambda_m_per_rad must be finite, got nan"),
        ({"lambda_m_per_rad": -1.0}, "lambda_m_per_rad must be non-negative, got -1.0"),
        ({"window": -1}, "window must be a non-negative integer, got -1"),
        (
            {"k": 500, "window": 1},
            "k=500 exceeds the 63 candidates searched (7 lenses x 9 pixels): choose k at most 63 (--k",
        ),
        ({"compensate_port": "yes"}, "compensate_port must be True or False, got 'yes'"),
        ({"search": "brute"}, "search must be one of"),
    ],
)
def test_bad_options(kwargs, message):
    with pytest.raises(ParameterError, match=message.replace("(", r"\(").replace(")", r"\)")):
        SynthesisOptions(**kwargs)


def test_bad_geometry():
    with pytest.raises(ParameterError, match="cuts the main-lens aperture"):
        build_warp_map(TINY, FlatPort.from_degrees(distance_m=0.0005, tilt_x_deg=60.0))
    with pytest.raises(ParameterError, match="camera must be a LightFieldCamera"):
        build_warp_map("tiny", PORT)


# ---------------------------------------------------------------------------- k-d tree search
def test_analytic_search_finds_the_global_nearest_ray_inside_the_exact_coverage():
    """k = 1: inside the exact coverage the analytic search (a window of pixels under a ring of
    lenses) picks the same captured ray as the exact search over all rays (k-d tree)."""
    options = SynthesisOptions(k=1, supersample=1)
    analytic = build_warp_map(TINY, PORT, options=options)
    tree = build_warp_map(TINY, PORT, options=dataclasses.replace(options, search="kdtree"))
    exact = analytic.exact.ravel()
    assert exact.mean() > 0.2
    first = analytic.indptr[:-1]
    np.testing.assert_array_equal(analytic.indices[first[exact]], tree.indices[tree.indptr[:-1][exact]])
    # The tree also fills pixels outside the coverage, with the globally nearest rays.
    assert tree.filled.all()


#: A calibrated camera's departure from the thin lens, larger than the Illum's fitted one
#: (pupil 1.0015, slope 1.0011, k1 0.083, k2 0.077, drift -5.5 mm) in every term.
CALIBRATED = RayCorrection(pupil_scale=1.02, slope_scale=0.98, k1=0.12, k2=0.08, pupil_drift_m=-0.006)


@pytest.mark.parametrize("correction", [None, CALIBRATED], ids=["thin-lens", "calibrated"])
def test_analytic_search_on_a_calibrated_model_finds_the_trees_nearest_ray(correction):
    """k = 1, on the calibrated rays too: the analytic search predicts the pixels from each
    necessary ray's thin-lens twin and measures D on the calibrated rays, and inside the exact
    coverage picks the ray the exact search over all calibrated rays picks."""
    options = SynthesisOptions(k=1, supersample=1, ray_correction=correction)
    analytic = build_warp_map(TINY, PORT, options=dataclasses.replace(options, search="analytic"))
    tree = build_warp_map(TINY, PORT, options=dataclasses.replace(options, search="kdtree"))
    np.testing.assert_array_equal(analytic.coverage, tree.coverage)
    exact = analytic.exact.ravel()
    assert exact.mean() > 0.2
    np.testing.assert_array_equal(analytic.indices[analytic.indptr[:-1][exact]], tree.indices[tree.indptr[:-1][exact]])
    assert build_warp_map(TINY, PORT, options=options).key == warp_map_key(TINY, PORT, analytic.output, options)


def test_the_exact_coverage_is_judged_on_the_calibrated_rays():
    """With pupil scale 0.8 the camera's rays cross the lens plane within 0.8 of the usable
    aperture: the necessary rays of exact pixels do too (judged on the thin lens, they reached
    the whole aperture), and the coverage shrinks."""
    options = SynthesisOptions(supersample=1)
    thin = build_warp_map(TINY, PORT, options=options)
    narrowed = dataclasses.replace(options, ray_correction=RayCorrection(pupil_scale=0.8))
    narrow = build_warp_map(TINY, PORT, options=narrowed)
    v, u = np.divmod(np.arange(thin.exact.size), thin.output.width_px)
    points, dirs, _, _ = necessary_air_rays(PORT, thin.output.pixel_directions(np.column_stack([u, v]).astype(float)))
    radius_m = np.hypot(*lens_plane_hits(points, dirs).T)
    usable_m = TINY.usable_aperture_radius_m(options.rim_margin_px)
    assert radius_m[thin.exact.ravel()].max() > 0.9 * usable_m
    assert radius_m[narrow.exact.ravel()].max() <= 0.8 * usable_m * (1 + FLOAT64_RELATIVE)
    assert 0 < narrow.exact.sum() < thin.exact.sum()


def test_rays_a_folding_correction_has_no_twin_for_go_to_the_tree():
    """k1 = -10 folds the field beyond slope 0.12 (the slope equation has no root there): those
    samples have no thin-lens twin to predict pixels from, and ``auto`` searches them exactly."""
    folding = RayCorrection(k1=-10.0)
    small = PinholeCamera(focal_px=60.0, cx_px=11.5, cy_px=8.5, width_px=24, height_px=18)
    options = SynthesisOptions(k=2, supersample=1, ray_correction=folding)
    auto = build_warp_map(TINY, PORT, output=small, options=options)
    tree = build_warp_map(TINY, PORT, output=small, options=dataclasses.replace(options, search="kdtree"))
    v, u = np.divmod(np.arange(small.width_px * small.height_px), small.width_px)
    _, dirs, _, valid = necessary_air_rays(PORT, small.pixel_directions(np.column_stack([u, v]).astype(float)))
    folded = valid & (np.hypot(dirs[:, 0], dirs[:, 1]) / dirs[:, 2] > 0.13)
    assert folded.sum() > 10
    assert auto.filled.ravel()[folded].all()
    for p in np.flatnonzero(folded):
        rows = slice(auto.indptr[p], auto.indptr[p + 1])
        np.testing.assert_array_equal(auto.indices[rows], tree.indices[tree.indptr[p] : tree.indptr[p + 1]])


@functools.cache
def _ray_tree(lam: float) -> RayTree:
    return RayTree(TINY, PORT, usable_radius_m=TINY.aperture_radius_m, lambda_m_per_rad=lam)


@settings(max_examples=8, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), k=st.integers(1, 12), lam=st.sampled_from([0.0, 0.01, 0.3]))
def test_ray_tree_matches_brute_force(seed, k, lam):
    rng = np.random.default_rng(seed)
    tree = _ray_tree(lam)
    n = 16  # necessary rays near captured ones (jittered), a few far away
    pick = rng.integers(0, len(tree.raw_index), size=n)
    points = tree.points_cam[pick] + rng.normal(scale=2e-4, size=(n, 3)) * [1, 1, 0]
    directions = tree.directions_cam[pick] + rng.normal(scale=0.02, size=(n, 3))
    points[:3, :2] += 0.01
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    index, dist = tree.nearest(points, directions, k)
    every = np.broadcast_to(np.arange(len(tree.raw_index)), (n, len(tree.raw_index)))
    brute = tree.distances(every, points, directions)
    order = np.lexsort((np.broadcast_to(tree.raw_index, brute.shape), brute), axis=-1)[:, :k]
    np.testing.assert_array_equal(index, tree.raw_index[order])
    np.testing.assert_allclose(dist, np.take_along_axis(brute, order, axis=1), rtol=1e-12)


def test_conjugate_port_face_falls_back_to_the_tree():
    """f' != f puts the MLA's conjugate plane in front of the camera; an air-side face there sends
    every pixel of a lens through one point, where the analytic prediction is undefined."""
    camera = dataclasses.replace(TINY, lens_to_mla_m=6.3e-3)
    f, f_prime = camera.focal_length_m, camera.lens_to_mla_m
    port = FlatPort(distance_m=f * f_prime / (f_prime - f), thickness_m=0.004, n_glass=1.5, n_water=1.333)
    small = PinholeCamera(focal_px=60.0, cx_px=11.5, cy_px=8.5, width_px=24, height_px=18)
    with pytest.raises(ParameterError, match=r"conjugate to the MLA.*use search='auto' or 'kdtree'"):
        build_warp_map(camera, port, output=small, options=SynthesisOptions(search="analytic"))
    warp = build_warp_map(camera, port, output=small, options=SynthesisOptions(supersample=1))
    assert warp.filled.all()
    rows = np.diff(warp.indptr)
    np.testing.assert_allclose(
        np.add.reduceat(warp.weights.astype(np.float64), warp.indptr[:-1]), 1.0, atol=FLOAT32_WEIGHT_SUM
    )
    assert rows.max() <= 32


def test_map_does_not_depend_on_blocks_or_threads(monkeypatch, warp):
    monkeypatch.setattr(synthesis, "BLOCK_PIXELS", 777)
    for workers in (1, 3):
        other = build_warp_map(TINY, PORT, workers=workers)
        for name in ("indptr", "indices", "weights", "gain", "coverage"):
            np.testing.assert_array_equal(getattr(other, name), getattr(warp, name))
    with pytest.raises(ParameterError, match="workers must be positive, got 0"):
        build_warp_map(TINY, PORT, workers=0)
    with pytest.raises(ParameterError, match="output must be a PinholeCamera"):
        build_warp_map(TINY, PORT, output=(92, 69))


def test_auto_search_uses_the_tree_off_the_focal_plane():
    """With f' != f the rays of one microlens fan out and the analytic window can miss the
    nearest ones, so ``auto`` takes the exact search there (and the analytic one where f' = f)."""
    camera = dataclasses.replace(TINY, lens_to_mla_m=6.3e-3)
    small = PinholeCamera(focal_px=60.0, cx_px=11.5, cy_px=8.5, width_px=24, height_px=18)
    options = SynthesisOptions(k=4, supersample=1)
    auto = build_warp_map(camera, PORT, output=small, options=options)
    tree = build_warp_map(camera, PORT, output=small, options=dataclasses.replace(options, search="kdtree"))
    for name in ("indptr", "indices", "weights"):
        np.testing.assert_array_equal(getattr(auto, name), getattr(tree, name))


def test_a_rim_margin_that_leaves_no_aperture_is_refused():
    with pytest.raises(ParameterError, match=r"rim_margin_px=5\.0 leaves no usable aperture"):
        build_warp_map(TINY, PORT, options=SynthesisOptions(rim_margin_px=5.0))


# ---------------------------------------------------------------------------- hostile map files (issue 12)
def _map_arrays(warp) -> dict:
    """The arrays :meth:`WarpMap.save` writes, as numpy arrays."""
    return {
        "indptr": warp.indptr,
        "indices": warp.indices,
        "weights": warp.weights,
        "gain": warp.gain,
        "coverage": warp.coverage,
        "raw_shape": np.asarray(warp.raw_shape),
        "key": np.asarray(warp.key),
        "meta": np.asarray(json.dumps(warp.meta)),
    }


def _corrupt(warp, **changes) -> dict:
    arrays = _map_arrays(warp)
    for name, value in changes.items():
        if value is None:
            del arrays[name]
        else:
            arrays[name] = value(arrays[name]) if callable(value) else value
    return arrays


def _raw_pixels(warp) -> int:
    return warp.raw_shape[0] * warp.raw_shape[1]


def _with(arr, index, value):
    out = arr.copy()
    out[index] = value
    return out


def _non_monotone(indptr):
    """Rows that overlap but keep the ends: one entry of indptr moved below its predecessor."""
    out = indptr.copy()
    row = int(np.flatnonzero(np.diff(indptr) > 1)[len(indptr) // 10])
    out[row + 1] = out[row] - 1
    return out


CORRUPT_MAPS = [
    # (id, changes, fragment of the message)
    ("index past the raw", {"indices": lambda a: _with(a, 5, 10**9)}, "indices must lie in [0, "),
    ("index just past the raw", {"indices": "RAW_PIXELS"}, "indices must lie in [0, "),
    ("negative index", {"indices": lambda a: _with(a, 0, -1)}, "got -1"),
    ("truncated indptr", {"indptr": lambda a: a[:-10]}, "indptr must have one entry per output pixel plus one"),
    ("indptr not from 0", {"indptr": lambda a: a + 1}, "indptr must run from 0 to len(indices)"),
    (
        "indptr short of the end",
        {"indptr": lambda a: _with(a, -1, a[-1] - 1)},
        "indptr must run from 0 to len(indices)",
    ),
    ("indptr decreasing", {"indptr": _non_monotone}, "indptr must be non-decreasing"),
    ("weights shorter", {"weights": lambda a: a[:-1]}, "weights must match indices in length"),
    ("NaN weight", {"weights": lambda a: _with(a, 3, np.nan)}, "weights must be finite, got nan"),
    ("negative weight", {"weights": lambda a: _with(a, 3, -0.5)}, "weights must be non-negative"),
    ("rows not normalised", {"weights": lambda a: a * 2}, "must sum to 1"),
    ("infinite gain", {"gain": lambda a: _with(a, 0, np.inf)}, "gain must be finite, got inf"),
    ("gain of another size", {"gain": lambda a: a[:-1]}, "gain must have one entry per output pixel"),
    ("coverage transposed", {"coverage": lambda a: a.T.copy()}, "coverage must have the output's shape"),
    ("coverage above 1", {"coverage": lambda a: a * 2 + 0.1}, "coverage must lie in [0, 1]"),
    ("float indices", {"indices": lambda a: a.astype(np.float64)}, "indices must be an integer array"),
    ("integer weights", {"weights": lambda a: (a * 0 + 1).astype(np.int32)}, "weights must be a float32/float64 array"),
    ("half-float weights", {"weights": lambda a: a.astype(np.float16)}, "weights must be a float32/float64 array"),
    ("big-endian weights", {"weights": lambda a: a.astype(">f4")}, "native byte order"),
    ("2-D indices", {"indices": lambda a: a.reshape(1, -1)}, "indices must be an integer array (1-D"),
    ("raw_shape zero", {"raw_shape": lambda a: _with(a, 0, 0)}, "raw_shape[0] must be positive, got 0"),
    ("raw_shape huge", {"raw_shape": lambda a: _with(a, 1, 10**7)}, "raw_shape[1] must be at most 65536 px"),
    ("raw_shape of 3", {"raw_shape": np.array([1, 2, 3])}, "raw_shape must be 2 integers"),
    ("raw_shape float", {"raw_shape": lambda a: a.astype(float)}, "raw_shape must be 2 integers"),
    ("no indices", {"indices": None}, "lacks the array(s) ['indices']"),
    ("no key", {"key": None}, "lacks the array(s) ['key']"),
    ("numeric key", {"key": np.asarray(7)}, "'key' is not a string"),
    ("meta not JSON", {"meta": np.asarray("{not json")}, "'meta' is not a JSON object with an 'output'"),
    ("meta without output", {"meta": np.asarray("{}")}, "'meta' is not a JSON object with an 'output'"),
    ("output of another size", {"meta": "OTHER_OUTPUT"}, "indptr must have one entry per output pixel plus one"),
]


@pytest.mark.parametrize(("changes", "fragment"), [c[1:] for c in CORRUPT_MAPS], ids=[c[0] for c in CORRUPT_MAPS])
def test_corrupt_maps_are_file_format_errors_at_load(tmp_path, warp, changes, fragment):
    """Issue 12: a map with the right key and out-of-range indices crashed the process (SIGSEGV
    in the gather); a truncated indptr gave a reshape ValueError later. Every array is checked
    at load, before any kernel sees it, and the error names the file."""
    changes = dict(changes)
    if changes.get("indices") == "RAW_PIXELS":
        changes["indices"] = lambda a: _with(a, len(a) // 2, _raw_pixels(warp))
    if changes.get("meta") == "OTHER_OUTPUT":
        meta = {**warp.meta, "output": {**warp.meta["output"], "width_px": warp.output.width_px + 1}}
        changes["meta"] = np.asarray(json.dumps(meta))
    path = tmp_path / "map.npz"
    np.savez(path, **_corrupt(warp, **changes))
    with pytest.raises(FileFormatError, match=re.escape(str(path))) as info:
        WarpMap.load(path, expected_key=warp.key if "key" not in changes else None)
    assert fragment in str(info.value)


def test_empty_and_foreign_files_are_file_format_errors(tmp_path, warp):
    """An empty file gave EOFError; a lone .npy array or an archive without arrays are no maps."""
    empty = tmp_path / "empty.npz"
    empty.write_bytes(b"")
    with pytest.raises(FileFormatError, match=re.escape(f"{str(empty)!r} is not a warp map: EOFError")):
        WarpMap.load(empty)
    nothing = tmp_path / "nothing.npz"
    np.savez(nothing)
    with pytest.raises(FileFormatError, match=re.escape("lacks the array(s)")):
        WarpMap.load(nothing)
    lone = tmp_path / "lone.npz"
    with lone.open("wb") as fh:
        np.save(fh, warp.indices)
    with pytest.raises(FileFormatError, match=re.escape("a single array (.npy), not an .npz archive")):
        WarpMap.load(lone)
    pickled = tmp_path / "pickled.npz"
    np.save(pickled.with_suffix(""), np.array([object()], dtype=object), allow_pickle=True)
    pickled.with_suffix(".npy").rename(pickled)
    with pytest.raises(FileFormatError, match=re.escape(f"{str(pickled)!r} is not a warp map")):
        WarpMap.load(pickled)


def test_a_map_with_an_index_past_the_raw_never_reaches_the_gather(tmp_path, warp):
    """The SIGSEGV case end to end, in a subprocess so that a crash cannot take pytest down:
    load refuses the file, apply is never reached, the process exits normally."""
    path = tmp_path / "map.npz"
    np.savez(path, **_corrupt(warp, indices=lambda a: _with(a, len(a) // 2, 2**31 - 1)))
    script = (
        "import sys, numpy as np\n"
        "from lfrefract.errors import FileFormatError\n"
        "from lfrefract.synthesis.warp_map import WarpMap\n"
        "try:\n"
        "    warp = WarpMap.load(sys.argv[1])\n"
        "except FileFormatError as exc:\n"
        "    print(exc)\n"
        "    sys.exit(3)\n"
        "warp.apply(np.zeros(warp.raw_shape, dtype=np.float32))\n"
    )
    done = subprocess.run([sys.executable, "-c", script, str(path)], capture_output=True, text=True, timeout=300)
    assert done.returncode == 3, (done.returncode, done.stderr[-2000:])
    assert "indices must lie in [0, " in done.stdout


def test_maps_built_in_memory_are_checked_too(warp):
    """The checks live in the constructor: a WarpMap with bad arrays cannot be made at all."""
    bad_index = _with(warp.indices, 0, _raw_pixels(warp))
    with pytest.raises(ParameterError, match=re.escape("indices must lie in [0, ")):
        dataclasses.replace(warp, indices=bad_index)
    with pytest.raises(ParameterError, match="indptr must have one entry per output pixel plus one"):
        dataclasses.replace(warp, indptr=warp.indptr[:-1])
    with pytest.raises(ParameterError, match="weights must be a float32/float64 numpy array, got list"):
        dataclasses.replace(warp, weights=warp.weights.tolist())
    with pytest.raises(ParameterError, match="raw_shape must be a"):
        dataclasses.replace(warp, raw_shape=[warp.raw_shape[0], warp.raw_shape[1]])
    with pytest.raises(ParameterError, match="output must be a PinholeCamera"):
        dataclasses.replace(warp, output=warp.output.to_dict())
    # A smaller raw image than the map was built for puts its indices out of range.
    with pytest.raises(ParameterError, match=re.escape("indices must lie in [0, ")):
        dataclasses.replace(warp, raw_shape=(warp.raw_shape[0] // 2, warp.raw_shape[1]))
    # The map as built passes, also through a file.
    assert dataclasses.replace(warp).key == warp.key


def test_cfa_maps_gather_each_colour_from_its_own_sites_only():
    """A map of one colour of a Bayer mosaic uses only that colour's raw pixels (analytic search and
    k-d tree alike), keeps the coverage of the map of every pixel, and has a key of its own."""
    from lfrefract import FlatPort, camera_preset
    from lfrefract.formats.mosaic import cfa_channels
    from lfrefract.synthesis.warp_map import build_cfa_warp_maps, build_warp_map

    camera = camera_preset("tiny")
    port = FlatPort.from_degrees(distance_m=0.02, thickness_m=0.006, tilt_x_deg=20.0)
    every = build_warp_map(camera, port)
    channels = cfa_channels("BGGR", (camera.sensor.height_px, camera.sensor.width_px)).ravel()
    maps = build_cfa_warp_maps(camera, port, "BGGR")
    for colour, warp in maps.items():
        assert set(channels[warp.indices]) == {"RGB".index(colour)}
        np.testing.assert_array_equal(warp.coverage, every.coverage)
        assert warp.filled.mean() > 0.95 * every.filled.mean()
        assert warp.key != every.key
    tree = build_warp_map(
        camera, port, options=SynthesisOptions(search="kdtree", cfa_pattern="BGGR", cfa_colour="R", k=4)
    )
    assert set(channels[tree.indices]) == {0}
    with pytest.raises(ParameterError, match="go together"):
        SynthesisOptions(cfa_pattern="BGGR")
    with pytest.raises(ParameterError, match="cfa_colour"):
        SynthesisOptions(cfa_pattern="BGGR", cfa_colour="Y")
    assert "cfa_pattern" not in SynthesisOptions().to_dict()  # the maps of every pixel keep their keys


# ---------------------------------------------------------------------------- results with no value (issue 36)
def _looking_away(output: PinholeCamera, shift_px: float) -> PinholeCamera:
    """``output`` with its principal point ``shift_px`` to the right: its lines of sight point far left."""
    data = output.to_dict()
    K = np.array(data["K"])
    K[0, 2] += shift_px
    return PinholeCamera.from_dict({**data, "K": K.tolist()})


def test_a_port_that_reflects_every_line_of_sight_is_refused_naming_it():
    """A 70 deg port reflects the light of every line of sight of tiny's image totally: the map had no entry,
    and ``synth`` wrote an image of NaN with exit status 0."""
    port = FlatPort.from_degrees(distance_m=0.03, thickness_m=0.005, tilt_x_deg=70.0)
    with pytest.raises(ParameterError, match=r"no value anywhere: .*totally internally reflected.*tilt 70 deg"):
        build_warp_map(TINY, port)


def test_an_output_that_looks_away_from_the_port_is_refused_naming_its_geometry():
    """An output whose principal point lies 10 000 px off (a K typed wrong) sees nothing through the port."""
    output = _looking_away(virtual_camera_for(TINY), 1e4)
    with pytest.raises(ParameterError, match=r"no value anywhere: .*92 x 69 px output.*cx 1\.005e\+04"):
        build_warp_map(TINY, PORT, output=output)


def test_a_map_whose_every_ray_is_masked_is_refused_when_applied(warp):
    """Masking every raw pixel as unrecorded empties every row (``--nonfinite mask`` on an all-NaN raw): the
    image would have no value anywhere, which is refused naming the masked pixels, not returned as zeros."""
    from lfrefract.formats.capture import mask_warp_map

    raw = np.ones(warp.raw_shape, dtype=np.float32)
    emptied = mask_warp_map(warp, np.zeros(warp.raw_shape, dtype=bool))
    with pytest.raises(
        ParameterError,
        match=r"no value anywhere: every ray it needs lies on the 172800 of 172800 raw pixels masked as unrecorded "
        r".*--nonfinite mask",
    ):
        emptied.apply(raw)
    some = np.zeros(warp.raw_shape, dtype=bool)
    some[::2] = True
    assert np.count_nonzero(mask_warp_map(warp, some).apply(raw)) > 0  # some rows left: a result
