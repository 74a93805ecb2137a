"""Tests of the procedural content in simulator.assets: textures, chessboard, meshes, PLY."""

from __future__ import annotations

import math
import os
import subprocess
import sys
import time

import cv2
import numpy as np
import pytest
from scipy import ndimage

from lfrefract.errors import ParameterError
from simulator.assets import (
    BLACK,
    WHITE,
    bowl_cap_geometry,
    bowl_mesh,
    chessboard_inner_corners,
    chessboard_size_m,
    chessboard_texture,
    figurine_mesh,
    random_texture,
    vertex_normals,
    write_ply,
)
from tests.tolerances import (
    BOWL_VOLUME_RELATIVE,
    CORNER_TOL_TEXELS,
    FLOAT64_FEW_OPS,
    FLOAT64_PIXEL_PX,
    FLOAT64_RELATIVE,
    FLOAT64_UNIT,
    TEXTURE_BAND_STD_MIN,
)

# ------------------------------------------------------------------------------------------
# helpers
# ------------------------------------------------------------------------------------------


def _signed_volume(v: np.ndarray, f: np.ndarray) -> float:
    """Volume enclosed by a closed mesh (divergence theorem); positive for outward winding."""
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def _assert_closed_and_oriented(f: np.ndarray) -> None:
    directed = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]).astype(np.int64)
    _, directed_counts = np.unique(directed, axis=0, return_counts=True)
    assert directed_counts.max() == 1, "a directed edge appears twice: inconsistent winding"
    undirected = np.sort(directed, axis=1)
    _, counts = np.unique(undirected, axis=0, return_counts=True)
    assert np.all(counts == 2), f"edges used by {sorted(set(counts.tolist()))} faces, expected exactly 2"


def _assert_well_formed(v: np.ndarray, f: np.ndarray, n: np.ndarray) -> None:
    assert v.dtype == np.float64
    assert f.dtype == np.int32
    assert n.dtype == np.float64
    assert v.ndim == 2
    assert v.shape[1] == 3
    assert f.ndim == 2
    assert f.shape[1] == 3
    assert n.shape == v.shape
    assert np.all(np.isfinite(v))
    assert np.all(np.isfinite(n))
    assert f.min() == 0
    assert f.max() == len(v) - 1
    assert len(np.unique(f)) == len(v), "unreferenced vertices"
    assert len(np.unique(v, axis=0)) == len(v), "duplicated vertex positions"
    # no degenerate triangles: distinct indices and an area well above rounding
    assert np.all((f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 2] != f[:, 0]))
    cross = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    area = 0.5 * np.linalg.norm(cross, axis=1)
    diag = np.linalg.norm(v.max(axis=0) - v.min(axis=0))
    assert area.min() > 1e-9 * diag**2
    # unit normals that agree with the winding of every adjacent face
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, rtol=0, atol=FLOAT64_UNIT)
    face_n = cross / (2.0 * area[:, None])
    for k in range(3):
        assert np.einsum("ij,ij->i", face_n, n[f[:, k]]).min() > 0.0


# ------------------------------------------------------------------------------------------
# random_texture
# ------------------------------------------------------------------------------------------


def test_random_texture_shape_dtype_and_range():
    tex = random_texture(size_px=128, seed=3)
    assert tex.shape == (128, 128, 3)
    assert tex.dtype == np.float32
    assert tex.min() >= np.float32(0.05)
    assert tex.max() <= np.float32(0.95)
    # contrast-normalised: each channel uses a good part of the range and is not constant
    assert np.all(tex.std(axis=(0, 1)) > 0.15)
    assert np.all(np.abs(tex.mean(axis=(0, 1)) - 0.5) < 0.05)
    # coloured: the channels differ
    assert np.abs(tex[..., 0] - tex[..., 1]).mean() > 0.05


def test_random_texture_is_deterministic_per_seed():
    a = random_texture(size_px=96, seed=7, octaves=5)
    b = random_texture(size_px=96, seed=7, octaves=5)
    c = random_texture(size_px=96, seed=8, octaves=5)
    np.testing.assert_array_equal(a, b)
    assert np.abs(a - c).mean() > 0.1


@pytest.mark.parametrize("seed", [0, 1])
def test_random_texture_has_energy_at_several_scales(seed):
    lum = random_texture(size_px=256, seed=seed).mean(axis=2)
    for scale in (2, 8, 32):
        band = ndimage.uniform_filter(lum, scale, mode="wrap") - ndimage.uniform_filter(lum, 2 * scale, mode="wrap")
        assert band.std() > TEXTURE_BAND_STD_MIN, f"too little energy at {scale} px: {band.std():.4f}"


def test_random_texture_single_octave_lacks_coarse_energy():
    """The band test above can fail: one 2 px octave has no 32 px structure."""
    lum = random_texture(size_px=256, seed=0, octaves=1).mean(axis=2)
    band = ndimage.uniform_filter(lum, 32, mode="wrap") - ndimage.uniform_filter(lum, 64, mode="wrap")
    assert band.std() < TEXTURE_BAND_STD_MIN


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"size_px": 0, "seed": 0}, "size_px"),
        ({"size_px": 64.0, "seed": 0}, "size_px"),
        ({"size_px": 64, "seed": -1}, "seed"),
        ({"size_px": 64, "seed": 1.5}, "seed"),
        ({"size_px": 64, "seed": 0, "octaves": 0}, "octaves"),
        ({"size_px": 32, "seed": 0, "octaves": 6}, "size_px"),
    ],
)
def test_random_texture_rejects_bad_input(kwargs, name):
    with pytest.raises(ParameterError, match=name):
        random_texture(**kwargs)


# ------------------------------------------------------------------------------------------
# chessboard
# ------------------------------------------------------------------------------------------


def test_chessboard_texture_layout():
    tps, cols, rows = 6, 5, 4
    tex = chessboard_texture(squares=(cols, rows), texels_per_square=tps, margin_squares=1.5)
    m = 9  # 1.5 squares of 6 texels
    assert tex.shape == (rows * tps + 2 * m, cols * tps + 2 * m, 3)
    assert tex.dtype == np.float32
    np.testing.assert_array_equal(tex[..., 0], tex[..., 1])
    np.testing.assert_array_equal(tex[..., 0], tex[..., 2])
    assert set(np.unique(tex).tolist()) == {np.float32(BLACK), np.float32(WHITE)}
    assert BLACK == 0.05
    assert WHITE == 0.9
    grey = tex[..., 0]
    # white margin on every side
    assert np.all(grey[:m] == np.float32(WHITE))
    assert np.all(grey[-m:] == np.float32(WHITE))
    assert np.all(grey[:, :m] == np.float32(WHITE))
    assert np.all(grey[:, -m:] == np.float32(WHITE))
    # every square is uniform and square (i, j) is black when i + j is even: top-left is black
    for j in range(rows):
        for i in range(cols):
            block = grey[m + j * tps : m + (j + 1) * tps, m + i * tps : m + (i + 1) * tps]
            expected = BLACK if (i + j) % 2 == 0 else WHITE
            assert np.all(block == np.float32(expected)), (i, j)


def test_chessboard_size_matches_texture():
    squares, tps, margin, s = (7, 4), 10, 0.5, 0.025
    tex = chessboard_texture(squares=squares, texels_per_square=tps, margin_squares=margin)
    width, height = chessboard_size_m(squares=squares, square_size_m=s, margin_squares=margin)
    assert width == pytest.approx(tex.shape[1] * s / tps, rel=FLOAT64_RELATIVE)
    assert height == pytest.approx(tex.shape[0] * s / tps, rel=FLOAT64_RELATIVE)
    assert width == pytest.approx(8 * s, rel=FLOAT64_RELATIVE)
    assert height == pytest.approx(5 * s, rel=FLOAT64_RELATIVE)


def _metres_to_texels(xy: np.ndarray, tex_shape: tuple[int, ...], texel_m: float) -> np.ndarray:
    """Board-frame metres -> continuous texture pixel (u, v), pixel centres at integers."""
    h, w = tex_shape[:2]
    return np.stack([(xy[:, 0] + 0.5 * w * texel_m) / texel_m - 0.5, (xy[:, 1] + 0.5 * h * texel_m) / texel_m - 0.5], 1)


@pytest.mark.parametrize(("squares", "margin"), [((7, 4), 1.0), ((4, 5), 0.5), ((2, 2), 0.0)])
def test_chessboard_inner_corners_lie_on_junctions(squares, margin):
    tps, s = 8, 0.03
    tex = chessboard_texture(squares=squares, texels_per_square=tps, margin_squares=margin)
    corners = chessboard_inner_corners(squares=squares, square_size_m=s, margin_squares=margin)
    cols, rows = squares
    assert corners.shape == ((cols - 1) * (rows - 1), 2)
    assert corners.dtype == np.float64
    uv = _metres_to_texels(corners, tex.shape, s / tps)
    # a junction lies on texel edges: half-integer pixel coordinates
    np.testing.assert_allclose(uv - np.floor(uv), 0.5, atol=FLOAT64_PIXEL_PX)
    grey = tex[..., 0]
    for k, (u, v) in enumerate(uv):
        c0, r0 = math.floor(u), math.floor(v)  # texel up-left of the junction
        tl, tr = grey[r0, c0], grey[r0, c0 + 1]
        bl, br = grey[r0 + 1, c0], grey[r0 + 1, c0 + 1]
        assert tl == br
        assert tr == bl
        assert tl != tr
        # row-by-row order: corner k is between squares (i-1, j-1) and (i, j)
        i, j = k % (cols - 1) + 1, k // (cols - 1) + 1
        assert tl == np.float32(BLACK if (i + j) % 2 == 0 else WHITE)


@pytest.mark.parametrize(("squares", "tps", "margin"), [((9, 6), 12, 1.0), ((7, 4), 10, 1.5), ((5, 6), 16, 2.0)])
def test_chessboard_matches_opencv_detection(squares, tps, margin):
    """OpenCV finds the board, and its corners in metres match chessboard_inner_corners."""
    s = 0.02
    tex = chessboard_texture(squares=squares, texels_per_square=tps, margin_squares=margin)
    img = np.round(tex[..., 0] * 255.0).astype(np.uint8)
    pattern = (squares[0] - 1, squares[1] - 1)
    found, detected = cv2.findChessboardCorners(img, pattern)
    assert found
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-3)
    detected = cv2.cornerSubPix(img, detected, (3, 3), (-1, -1), criteria).reshape(-1, 2).astype(np.float64)
    texel_m = s / tps
    width, height = chessboard_size_m(squares=squares, square_size_m=s, margin_squares=margin)
    detected_m = np.stack(
        [(detected[:, 0] + 0.5) * texel_m - 0.5 * width, (detected[:, 1] + 0.5) * texel_m - 0.5 * height], 1
    )
    expected = chessboard_inner_corners(squares=squares, square_size_m=s, margin_squares=margin)
    assert detected_m.shape == expected.shape
    np.testing.assert_allclose(detected_m, expected, rtol=0, atol=CORNER_TOL_TEXELS * texel_m)
    # the board is centred on the texture centre
    np.testing.assert_allclose(expected.mean(axis=0), 0.0, atol=FLOAT64_FEW_OPS)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"squares": (1, 5), "texels_per_square": 8}, "squares"),
        ({"squares": (5, 0), "texels_per_square": 8}, "squares"),
        ({"squares": (5,), "texels_per_square": 8}, "squares"),
        ({"squares": 5, "texels_per_square": 8}, "squares"),
        ({"squares": (5.5, 4), "texels_per_square": 8}, "squares"),
        ({"squares": (5, 4), "texels_per_square": 0}, "texels_per_square"),
        ({"squares": (5, 4), "texels_per_square": 8, "margin_squares": -1.0}, "margin_squares"),
        ({"squares": (5, 4), "texels_per_square": 8, "margin_squares": 0.3}, "margin_squares"),
        ({"squares": (5, 4), "texels_per_square": 8, "margin_squares": float("nan")}, "margin_squares"),
    ],
)
def test_chessboard_texture_rejects_bad_input(kwargs, name):
    with pytest.raises(ParameterError, match=name):
        chessboard_texture(**kwargs)


@pytest.mark.parametrize("func", [chessboard_inner_corners, chessboard_size_m])
@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"squares": (1, 5), "square_size_m": 0.02}, "squares"),
        ({"squares": (5, 4), "square_size_m": 0.0}, "square_size_m"),
        ({"squares": (5, 4), "square_size_m": -0.02}, "square_size_m"),
        ({"squares": (5, 4), "square_size_m": 0.02, "margin_squares": -0.5}, "margin_squares"),
    ],
)
def test_chessboard_geometry_rejects_bad_input(func, kwargs, name):
    with pytest.raises(ParameterError, match=name):
        func(**kwargs)


# ------------------------------------------------------------------------------------------
# bowl
# ------------------------------------------------------------------------------------------


def _expected_bowl_volume(a: float, h: float, t: float) -> float:
    """Volume of a spherical-cap wall of thickness t with a half-torus rim, outer size (a, h).

    The mid-surface is a cap of rim radius a - t/2 and depth h - t; the wall spans radii
    rho +- t/2 over polar angles [0, theta]; the rim is a half-disc of radius t/2 swept about
    the axis (Pappus), its flat side on the radial cut at theta.
    """
    am, hm = a - t / 2, h - t
    rho = (am**2 + hm**2) / (2 * hm)
    theta = math.asin(am / rho)
    wall = 2 * math.pi / 3 * ((rho + t / 2) ** 3 - (rho - t / 2) ** 3) * (1 - math.cos(theta))
    centroid = am + 4 * (t / 2) / (3 * math.pi) * math.cos(theta)
    return wall + 2 * math.pi * centroid * math.pi * (t / 2) ** 2 / 2


@pytest.mark.parametrize(
    ("a", "h", "t"),
    [(0.1, 0.06, 0.005), (0.08, 0.08, 0.01), (0.05, 0.012, 0.002)],
)
def test_bowl_is_closed_outward_and_of_the_right_volume(a, h, t):
    v, f, n = bowl_mesh(radius_m=a, depth_m=h, thickness_m=t)
    _assert_well_formed(v, f, n)
    _assert_closed_and_oriented(f)
    volume = _signed_volume(v, f)
    assert volume > 0.0
    assert volume == pytest.approx(_expected_bowl_volume(a, h, t), rel=BOWL_VOLUME_RELATIVE)


def test_bowl_volume_detects_a_wrong_thickness():
    """The volume check can fail: a wall 2% thicker is outside the tolerance."""
    v, f, _ = bowl_mesh(radius_m=0.1, depth_m=0.06, thickness_m=0.0051)
    assert _signed_volume(v, f) != pytest.approx(_expected_bowl_volume(0.1, 0.06, 0.005), rel=BOWL_VOLUME_RELATIVE)


@pytest.mark.parametrize(("a", "h", "t", "segments", "rings"), [(0.1, 0.06, 0.005, 96, 32), (0.03, 0.02, 0.004, 24, 8)])
def test_bowl_frame_and_bounding_box(a, h, t, segments, rings):
    v, _, n = bowl_mesh(radius_m=a, depth_m=h, thickness_m=t, segments=segments, rings=rings)
    n_rim = max(4, rings // 2)
    # the rim's extremes are mesh vertices; the rim circle's widest point may fall between samples
    tol = 0.5 * t * (1 - math.cos(math.pi / n_rim)) + 1e-12
    np.testing.assert_allclose(v.max(axis=0), [a, a, h / 2], rtol=0, atol=tol)
    np.testing.assert_allclose(v.min(axis=0), [-a, -a, -h / 2], rtol=0, atol=tol)
    assert v[:, 2].max() == pytest.approx(h / 2, abs=FLOAT64_FEW_OPS)  # outside of the bottom, exact
    assert v[:, 2].min() == pytest.approx(-h / 2, abs=FLOAT64_FEW_OPS)  # rim, nearest the viewer, exact
    # the outer and inner bottoms on the axis, a wall thickness apart
    on_axis = np.sort(v[np.hypot(v[:, 0], v[:, 1]) < 1e-15, 2])
    np.testing.assert_allclose(on_axis, [h / 2 - t, h / 2], rtol=0, atol=FLOAT64_FEW_OPS)
    # open towards the viewer (-z): near the axis everything is in the back half
    r = np.hypot(v[:, 0], v[:, 1])
    assert np.all(v[r < 0.5 * a, 2] > 0.0)
    # the inside faces the viewer: the inner bottom's normal points to -z, the outer one to +z
    bottom = np.flatnonzero(r < 1e-15)
    inner, outer = bottom[np.argsort(v[bottom, 2])]
    np.testing.assert_allclose(n[inner], [0, 0, -1], atol=FLOAT64_UNIT)
    np.testing.assert_allclose(n[outer], [0, 0, 1], atol=FLOAT64_UNIT)
    # a surface of revolution: two poles and `segments` vertices per interior profile point
    assert len(v) == 2 + segments * (2 * (rings + 1) - 2 + n_rim - 1)


def test_bowl_walls_lie_on_the_documented_spheres():
    a, h, t = 0.1, 0.06, 0.005
    geo = bowl_cap_geometry(radius_m=a, depth_m=h, thickness_m=t)
    assert geo["volume_m3"] == pytest.approx(_expected_bowl_volume(a, h, t), rel=FLOAT64_RELATIVE)
    v, _, n = bowl_mesh(radius_m=a, depth_m=h, thickness_m=t)
    rel = v - [0.0, 0.0, geo["centre_z_m"]]
    dist = np.linalg.norm(rel, axis=1)
    polar = np.arccos(np.clip(rel[:, 2] / dist, -1.0, 1.0))
    wall = polar < geo["half_angle_rad"] - 1e-9  # the rim starts at the half angle
    rho = geo["sphere_radius_m"]
    on_outer = np.abs(dist - (rho + t / 2)) < 1e-12
    on_inner = np.abs(dist - (rho - t / 2)) < 1e-12
    assert np.all(on_outer[wall] | on_inner[wall])
    assert on_outer[wall].sum() == on_inner[wall].sum()
    # smooth normals on the walls are close to radial: outward on the outer wall, inward on the inner
    radial = rel / dist[:, None]
    assert np.einsum("ij,ij->i", n[wall & on_outer], radial[wall & on_outer]).min() > 0.999
    assert np.einsum("ij,ij->i", n[wall & on_inner], radial[wall & on_inner]).max() < -0.999


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"radius_m": -1.0}, "radius_m"),
        ({"radius_m": float("nan")}, "radius_m"),
        ({"depth_m": 0.0}, "depth_m"),
        ({"depth_m": 0.2}, "depth_m"),
        ({"thickness_m": 0.0}, "thickness_m"),
        ({"thickness_m": 0.06}, "thickness_m"),
        ({"segments": 7}, "segments"),
        ({"rings": 1}, "rings"),
        ({"rings": 8.0}, "rings"),
    ],
)
def test_bowl_rejects_bad_input(kwargs, name):
    args = {"radius_m": 0.1, "depth_m": 0.06, "thickness_m": 0.005} | kwargs
    with pytest.raises(ParameterError, match=name):
        bowl_mesh(**args)


# ------------------------------------------------------------------------------------------
# figurine
# ------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("seed", "resolution"), [(0, 64), (1, 40), (2, 40), (3, 40), (4, 40), (5, 96)])
def test_figurine_is_closed_outward_and_of_the_right_height(seed, resolution):
    height = 0.15
    v, f, n = figurine_mesh(height_m=height, seed=seed, resolution=resolution)
    _assert_well_formed(v, f, n)
    _assert_closed_and_oriented(f)
    assert len(v) == (resolution - 1) * 2 * resolution + 2
    lo, hi = v.min(axis=0), v.max(axis=0)
    assert hi[1] - lo[1] == pytest.approx(height, rel=FLOAT64_RELATIVE)
    np.testing.assert_allclose(lo + hi, 0.0, atol=FLOAT64_UNIT)  # bounding box centred on the origin
    # a figurine: narrower and shallower than tall, but not a sliver
    assert 0.4 * height < hi[0] - lo[0] < height
    assert 0.3 * height < hi[2] - lo[2] < height
    volume = _signed_volume(v, f)
    box = float(np.prod(hi - lo))
    assert 0.1 * box < volume < 0.7 * box


def test_figurine_head_is_up():
    """The head (a single lobe) is at -y, the two feet at +y."""
    v, _, _ = figurine_mesh(height_m=1.0, resolution=40)
    top = v[v[:, 1] < -0.4]  # the top 10%
    bottom = v[v[:, 1] > 0.45]  # the bottom 5%
    # the top is the head: centred, with ears on both sides; the bottom is two feet apart
    assert abs(top[:, 0].mean()) < 0.05
    assert np.any(bottom[:, 0] < -0.1)
    assert np.any(bottom[:, 0] > 0.1)
    assert not np.any(np.abs(bottom[:, 0]) < 0.02)


def test_figurine_is_deterministic_per_seed():
    a = figurine_mesh(height_m=0.1, seed=3, resolution=40)
    b = figurine_mesh(height_m=0.1, seed=3, resolution=40)
    c = figurine_mesh(height_m=0.1, seed=4, resolution=40)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x, y)
    assert np.abs(a[0] - c[0]).max() > 1e-3


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"height_m": 0.0}, "height_m"),
        ({"height_m": float("inf")}, "height_m"),
        ({"seed": -2}, "seed"),
        ({"resolution": 39}, "resolution"),
    ],
)
def test_figurine_rejects_bad_input(kwargs, name):
    with pytest.raises(ParameterError, match=name):
        figurine_mesh(**({"height_m": 0.1} | kwargs))


# ------------------------------------------------------------------------------------------
# PLY
# ------------------------------------------------------------------------------------------


def _read_ply(path):
    data = path.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode("ascii").splitlines()
    assert header[0] == "ply"
    assert header[1] == "format binary_little_endian 1.0"
    n_vert = int(next(line for line in header if line.startswith("element vertex")).split()[-1])
    n_face = int(next(line for line in header if line.startswith("element face")).split()[-1])
    props = [line.split() for line in header if line.startswith("property ")]
    vert_props = [p[2] for p in props if p[1] == "float"]
    assert props[-1] == ["property", "list", "uchar", "int", "vertex_indices"]
    vdt = np.dtype([(name, "<f4") for name in vert_props])
    fdt = np.dtype([("n", "u1"), ("i", "<i4", (3,))])
    assert len(data) == end + n_vert * vdt.itemsize + n_face * fdt.itemsize
    verts = np.frombuffer(data, dtype=vdt, count=n_vert, offset=end)
    faces = np.frombuffer(data, dtype=fdt, count=n_face, offset=end + n_vert * vdt.itemsize)
    return vert_props, verts, faces


def test_write_ply_round_trip(tmp_path):
    v, f, n = bowl_mesh(radius_m=0.05, depth_m=0.03, thickness_m=0.004, segments=16, rings=4)
    path = write_ply(tmp_path / "bowl.ply", v, f, n)
    assert path == tmp_path / "bowl.ply"
    names, verts, faces = _read_ply(path)
    assert names == ["x", "y", "z", "nx", "ny", "nz"]
    np.testing.assert_array_equal(np.stack([verts["x"], verts["y"], verts["z"]], 1), v.astype(np.float32))
    np.testing.assert_array_equal(np.stack([verts["nx"], verts["ny"], verts["nz"]], 1), n.astype(np.float32))
    assert np.all(faces["n"] == 3)
    np.testing.assert_array_equal(faces["i"], f)
    assert list(tmp_path.iterdir()) == [path]  # no temporary file left behind


def test_write_ply_without_normals_and_with_texcoords(tmp_path):
    v = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], dtype=np.int64)
    names, verts, faces = _read_ply(write_ply(tmp_path / "a.ply", v, f))
    assert names == ["x", "y", "z"]
    np.testing.assert_array_equal(np.stack([verts["x"], verts["y"], verts["z"]], 1), v.astype(np.float32))
    np.testing.assert_array_equal(faces["i"], f)
    uv = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [0.5, 0.5]])
    names, verts, _ = _read_ply(write_ply(tmp_path / "b.ply", v, f, texcoords=uv))
    assert names == ["x", "y", "z", "u", "v"]
    np.testing.assert_array_equal(np.stack([verts["u"], verts["v"]], 1), uv.astype(np.float32))
    # the tetrahedron is wound outward
    assert _signed_volume(v, f) == pytest.approx(1.0 / 6.0)


@pytest.mark.parametrize(
    ("change", "name"),
    [
        ({"vertices": np.zeros((4, 2))}, "vertices"),
        ({"vertices": np.array([[0, 0, 0], [1, 0, 0], [0, np.nan, 0], [0, 0, 1.0]])}, "vertices"),
        ({"faces": np.array([[0, 1, 4]])}, "faces"),
        ({"faces": np.array([[0, -1, 2]])}, "faces"),
        ({"faces": np.array([[0.0, 1.0, 2.0]])}, "faces"),
        ({"faces": np.array([0, 1, 2])}, "faces"),
        ({"normals": np.zeros((3, 3))}, "normals"),
        ({"texcoords": np.zeros((4, 3))}, "texcoords"),
    ],
)
def test_write_ply_rejects_bad_input(tmp_path, change, name):
    args = {
        "vertices": np.eye(4, 3),
        "faces": np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]),
    } | change
    with pytest.raises(ParameterError, match=name):
        write_ply(tmp_path / "bad.ply", **args)
    assert list(tmp_path.iterdir()) == []


def test_vertex_normals_of_a_tetrahedron():
    v = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    n = vertex_normals(v, f)
    # the right-angle corner's three faces have equal areas: its normal is -(1, 1, 1)/sqrt(3)
    np.testing.assert_allclose(n[0], -np.ones(3) / math.sqrt(3.0), atol=FLOAT64_FEW_OPS)
    # corner 1 sees faces of area 1/2, 1/2 (normals -z, -y) and sqrt(3)/2 (normal (1,1,1)/sqrt 3)
    expected = np.array([0.5, 0.0, 0.0])
    np.testing.assert_allclose(n[1], expected / np.linalg.norm(expected), atol=FLOAT64_FEW_OPS)
    with pytest.raises(ParameterError, match="vertex 4"):
        vertex_normals(np.vstack([v, [[2.0, 2.0, 2.0]]]), f)
    with pytest.raises(ParameterError, match="faces"):
        vertex_normals(v, f + 1)


def test_assets_does_not_import_mitsuba():
    code = "import sys, simulator.assets; sys.exit(int(any(m in sys.modules for m in ('mitsuba', 'drjit'))))"
    assert subprocess.run([sys.executable, "-c", code], check=False).returncode == 0


# ------------------------------------------------------------------------------------------
# user mesh files: kind, size and content checked before Mitsuba reads them (issue 12)
# ------------------------------------------------------------------------------------------

TRIANGLE_OBJ = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"


def _refusal(path):
    """The message of check_mesh_content's refusal of ``path`` (FileFormatError or ParameterError)."""
    from lfrefract.errors import FileFormatError
    from simulator import assets

    with pytest.raises((FileFormatError, ParameterError)) as err:
        assets.check_mesh_content(path)
    return err.type, str(err.value)


def test_mesh_path_of_the_wrong_kind_or_size_is_refused_from_its_metadata(tmp_path):
    from simulator import assets
    from tests.tolerances import FILE_SIZE_REFUSAL_SECONDS

    folder = tmp_path / "folder.obj"
    folder.mkdir()
    fifo = tmp_path / "pipe.obj"
    os.mkfifo(fifo)
    sparse = tmp_path / "huge.obj"
    with sparse.open("wb") as fh:
        fh.truncate(5 * 2**30)  # 5 GiB, sparse: created instantly, no disk used
    cases = [
        (folder, "is a directory, not a regular file"),
        (fifo, "is a named pipe (FIFO), not a regular file"),
        (sparse, "holds 5368709120 bytes (5120 MiB), more than the 536870912 bytes (512 MiB) accepted"),
        (tmp_path / "missing.obj", "does not exist"),
    ]
    for path, message in cases:
        start = time.perf_counter()
        kind, text = _refusal(path)
        assert time.perf_counter() - start < FILE_SIZE_REFUSAL_SECONDS
        assert kind is ParameterError
        assert f"mesh path {str(path)!r} {message}" == text
    assert assets.MAX_MESH_FILE_BYTES == 512 * 2**20


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"", "the file is empty"),
        (b"hello world\nthis is not a mesh\n", "line 1 ('hello world') is not an OBJ statement"),
        (bytes(range(256)) * 8, "holds the byte 0x00: an OBJ file is ASCII text"),
        (b"# only a comment\n\n", "no vertex ('v') lines"),
        (b"v 0 0 0\nv 1 0 0\nv 0 1 0\n", "no face ('f') lines"),
        (b"v 1 2\nf 1 2 9\n", "line 1 ('v 1 2') does not parse: a vertex ('v') needs 3 numbers"),
        (b"v 0 0 0\nv 1.2.3 0 0\nv 0 1 0\nf 1 2 3\n", "line 2 ('v 1.2.3 0 0') does not parse"),
        (b"v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n", "line 2 ('v nan 0 0') does not parse"),
        (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0\nf 1 2 3\n", "line 4 ('vn 0 0') does not parse"),
        (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0\nf 1 2 3\n", "line 4 ('vt 0') does not parse"),
        (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\n", "line 4 ('f -3 -2 -1') uses negative (relative) vertex"),
        (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n", "line 4 ('f 1 2') does not parse: a face ('f') needs 3"),
        (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x\n", "line 4 ('f 1 2 x') does not parse"),
        (TRIANGLE_OBJ.encode() + b"#" * 1100 + b"\n", "line 5 ('####"),
    ],
    ids=[
        "empty", "garbage", "binary", "comment-only", "no-faces", "short-vertex", "two-points", "nan",
        "short-normal", "short-texcoord", "negative-index", "short-face", "face-letter", "long-line",
    ],
)  # fmt: skip
def test_bad_obj_content_is_named_with_its_file_and_line(tmp_path, content, message):
    from lfrefract.errors import FileFormatError

    path = tmp_path / "thing.obj"
    path.write_bytes(content)
    kind, text = _refusal(path)
    assert kind is FileFormatError
    assert text.startswith(f"{str(path)!r}: ")
    assert message in text


def test_obj_lines_are_counted_across_blocks(tmp_path, monkeypatch):
    from simulator import assets

    monkeypatch.setattr(assets, "_OBJ_BLOCK", 16)  # many blocks, lines cut at their edges
    path = tmp_path / "thing.obj"
    path.write_text(TRIANGLE_OBJ * 5 + "v 1 2 x\n" + TRIANGLE_OBJ)
    assert "line 21 ('v 1 2 x') does not parse" in _refusal(path)[1]
    path.write_text(TRIANGLE_OBJ * 5)  # and a good one passes whatever the block size
    assets.check_mesh_content(path)


def test_good_meshes_pass_the_content_check(tmp_path):
    from simulator import assets

    obj = tmp_path / "good.obj"
    obj.write_text(
        "# a comment\nmtllib thing.mtl\no thing\ng group\ns off\nusemtl stone\n"
        "  v 0 0 0\n\tv 1.5 -2.25e-3 +3.\r\nv .5 5. -.5E+2 0.2 0.3 0.4\nvn 0 0 1\nvt 0 1\n"
        "f 1/1/1 2//1 3/1\nf 1 2 3 1\n"
    )  # indentation, CRLF, exponents, vertex colours, all reference forms, a quad
    assets.check_mesh_content(obj)
    ply = write_ply(tmp_path / "bowl.ply", *bowl_mesh(radius_m=0.05, depth_m=0.03, thickness_m=0.004))
    assets.check_mesh_content(ply)
    ascii_ply = tmp_path / "ascii.ply"
    ascii_ply.write_text(
        "ply\nformat ascii 1.0\ncomment by hand\nelement vertex 3\nproperty float x\nproperty float y\n"
        "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
        "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
    )
    assets.check_mesh_content(ascii_ply)


def _ply_header(*lines: str) -> bytes:
    return ("\n".join(lines) + "\n").encode()


PLY_OK = (
    "ply", "format binary_little_endian 1.0", "element vertex 3", "property float x", "property float y",
    "property float z", "element face 1", "property list uchar int vertex_indices", "end_header",
)  # fmt: skip


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"hello\n", "does not start with the line 'ply': not a PLY file"),
        (_ply_header("ply", "format binary_little_endian 1.0") + b"\0" * 70_000, "no 'end_header' line within"),
        (_ply_header(*PLY_OK), "holds 0 bytes after its header, but its elements need at least 49"),
        (_ply_header(*PLY_OK) + b"\0" * 48, "holds 48 bytes after its header"),
        (_ply_header(*PLY_OK[:3], "property float x", "property float y", *PLY_OK[6:]), "with properties x, y and z"),
        (_ply_header(*PLY_OK[:6], "end_header"), "needs a 'face' element"),
        (_ply_header("ply", "format binary_little_endian 2.0", *PLY_OK[2:]), "header line 2"),
        (_ply_header(*PLY_OK[:3], "property quad x", *PLY_OK[4:]), "header line 4 ('property quad x')"),
        (_ply_header(*PLY_OK[:2], "vertices 3", *PLY_OK[3:]), "not a PLY header statement"),
    ],
    ids=["magic", "no-end", "empty-body", "truncated", "no-z", "no-face", "version", "type", "statement"],
)
def test_bad_ply_headers_are_named_with_their_file(tmp_path, content, message):
    from lfrefract.errors import FileFormatError

    path = tmp_path / "thing.ply"
    path.write_bytes(content)
    kind, text = _refusal(path)
    assert kind is FileFormatError
    assert text.startswith(f"{str(path)!r}: ")
    assert message in text


def test_a_mesh_file_changed_after_passing_is_checked_again(tmp_path):
    from simulator import assets

    path = tmp_path / "thing.obj"
    path.write_text(TRIANGLE_OBJ)
    assets.check_mesh_content(path)
    assets.check_mesh_content(path)  # unchanged: remembered
    path.write_text(TRIANGLE_OBJ + "v 1 2\n")
    assert "line 5 ('v 1 2') does not parse" in _refusal(path)[1]


def test_a_same_size_mesh_copied_in_with_the_same_mtime_is_checked_again(tmp_path):
    """``cp -p`` writes into the same inode and keeps the modification time of its source: a cache keyed on
    size, mtime and inode alone would let a broken mesh of the same size through unchecked."""
    from simulator import assets

    path, broken = tmp_path / "thing.obj", tmp_path / "broken.obj"
    path.write_text(TRIANGLE_OBJ)
    assets.check_mesh_content(path)
    broken.write_text(TRIANGLE_OBJ.replace("v 0 1 0", "v 0 1 x"))
    stat = path.stat()
    assert broken.stat().st_size == stat.st_size
    os.utime(broken, ns=(stat.st_atime_ns, stat.st_mtime_ns))
    time.sleep(0.05)  # past the kernel's coarse clock tick (a few ms) of the file's last change
    subprocess.run(["cp", "-p", str(broken), str(path)], check=True)
    assert (path.stat().st_size, path.stat().st_mtime_ns, path.stat().st_ino) == (
        stat.st_size, stat.st_mtime_ns, stat.st_ino,
    )  # fmt: skip
    assert "line 3 ('v 0 1 x') does not parse" in _refusal(path)[1]
