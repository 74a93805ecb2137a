"""Procedural scene content in plain numpy: textures, calibration boards and triangle meshes.

Everything here is deterministic given its arguments (and ``seed`` where there is one), does not
import Mitsuba or Dr.Jit, and validates its input with :class:`lfrefract._validate.ParameterError`.

Conventions
-----------
Textures
    Arrays of shape ``(H, W, 3)``, float32, linear RGB in [0, 1]. Row 0 is the top of the image
    and column 0 its left edge. A texel ``(row, col)`` covers the continuous pixel coordinates
    ``[col - 0.5, col + 0.5] x [row - 0.5, row + 0.5]``, so its centre is at integer coordinates,
    as in OpenCV.
Board (plane) frame
    Origin at the centre of the whole texture (margin included), +x right (increasing texture
    column), +y down (increasing texture row), metres. A continuous texture pixel coordinate
    ``(u, v)`` maps to ``x = (u + 0.5) * texel_m - width_m / 2`` and
    ``y = (v + 0.5) * texel_m - height_m / 2``.
Mesh (object) frame
    OpenCV-like, metres: origin at the centre of the object's axis-aligned bounding box, +x right,
    +y down (so "up" is -y), +z away from a viewer that looks along +z. Meshes are returned as
    ``(vertices, faces, normals)``: ``vertices`` (V, 3) float64, ``faces`` (F, 3) int32 indices
    into ``vertices``, ``normals`` (V, 3) float64 unit vectors. Faces wind counter-clockwise seen
    from outside: ``cross(v1 - v0, v2 - v0)`` points out of the solid. Normals are smooth per
    vertex: the area-weighted mean of the adjacent face normals. The meshes are closed (every
    undirected edge is shared by exactly two faces) and consistently oriented.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import numpy as np
from scipy import ndimage

from lfrefract._validate import ParameterError, non_negative_float, positive_float, positive_int
from lfrefract.outputs import atomic_file

__all__ = [
    "BLACK",
    "WHITE",
    "bowl_cap_geometry",
    "bowl_mesh",
    "chessboard_inner_corners",
    "chessboard_size_m",
    "chessboard_texture",
    "figurine_mesh",
    "random_texture",
    "vertex_normals",
    "write_ply",
]

#: Value of the black squares of :func:`chessboard_texture` (all three channels).
BLACK = 0.05
#: Value of the white squares and the margin of :func:`chessboard_texture` (all three channels).
WHITE = 0.9

_TEXTURE_LOW = 0.05
_TEXTURE_HIGH = 0.95


# --------------------------------------------------------------------------------------------
# validation helpers
# --------------------------------------------------------------------------------------------


def _seed(name: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ParameterError(f"{name} must be an integer, got {value!r}")
    if value < 0:
        raise ParameterError(f"{name} must be non-negative, got {value!r}")
    return int(value)


def _int_at_least(name: str, value: Any, minimum: int) -> int:
    out = positive_int(name, value)
    if out < minimum:
        raise ParameterError(f"{name} must be at least {minimum}, got {value!r}")
    return out


def _squares(value: Any) -> tuple[int, int]:
    try:
        items = tuple(value)
    except TypeError:
        raise ParameterError(f"squares must be a (columns, rows) pair of integers, got {value!r}") from None
    if len(items) != 2:
        raise ParameterError(f"squares must be a (columns, rows) pair of integers, got {value!r}")
    cols = _int_at_least("squares[0] (columns)", items[0], 2)
    rows = _int_at_least("squares[1] (rows)", items[1], 2)
    return cols, rows


def _finite_array(name: str, value: Any, columns: int) -> np.ndarray:
    arr = np.asarray(value)
    if arr.ndim != 2 or arr.shape[1] != columns:
        raise ParameterError(f"{name} must have shape (N, {columns}), got shape {arr.shape}")
    if not np.issubdtype(arr.dtype, np.number) or np.issubdtype(arr.dtype, np.complexfloating):
        raise ParameterError(f"{name} must hold real numbers, got dtype {arr.dtype}")
    arr = arr.astype(np.float64)
    if not np.all(np.isfinite(arr)):
        raise ParameterError(f"{name} must be finite, got a row {arr[~np.all(np.isfinite(arr), axis=1)][0].tolist()}")
    return arr


def _faces(value: Any, n_vertices: int) -> np.ndarray:
    f = np.asarray(value)
    if f.ndim != 2 or f.shape[1] != 3:
        raise ParameterError(f"faces must have shape (F, 3), got shape {f.shape}")
    if not np.issubdtype(f.dtype, np.integer):
        raise ParameterError(f"faces must hold integers, got dtype {f.dtype}")
    if len(f) == 0:
        raise ParameterError("faces must not be empty, got shape (0, 3)")
    if f.min() < 0 or f.max() >= n_vertices:
        bad = int(f.min()) if f.min() < 0 else int(f.max())
        raise ParameterError(f"faces must index vertices in [0, {n_vertices}), got index {bad}")
    return f.astype(np.int64)


# --------------------------------------------------------------------------------------------
# textures
# --------------------------------------------------------------------------------------------


def random_texture(*, size_px: int, seed: int, octaves: int = 6) -> np.ndarray:
    """A colour noise texture with detail at several scales, for stereo matching.

    The texture is a sum of ``octaves`` band-limited Gaussian noise fields whose feature sizes
    double from one octave to the next (2, 4, 8, ... px), each normalised to unit standard
    deviation so that every scale carries the same energy. Each octave mixes a luminance field
    shared by the three channels with an independent field per channel, so the texture is
    coloured but has strong luminance contrast. Each channel is then contrast-normalised (zero
    mean, unit standard deviation) and mapped smoothly into the value range with
    ``0.5 + 0.45 * tanh(0.6 * z)``, which never clips. The texture is periodic (it tiles
    seamlessly) when ``size_px`` is a multiple of ``2 ** max(0, octaves - 2)``. Cost: about one
    second per megapixel on two cores.

    Parameters
    ----------
    size_px : int
        Width and height of the square texture, in texels. At least ``2 ** octaves``.
    seed : int
        Non-negative seed of the random generator; the same seed gives the same texture.
    octaves : int, optional
        Number of noise scales (default 6). Octave ``k`` (0-based) has features of about
        ``2 ** (k + 1)`` texels (Gaussian standard deviation ``2 ** k`` texels).

    Returns
    -------
    numpy.ndarray
        float32 array of shape ``(size_px, size_px, 3)``, linear RGB in [0.05, 0.95]; row 0 is the
        top of the texture.

    Raises
    ------
    ParameterError
        If ``size_px`` or ``octaves`` is not a positive integer, ``seed`` is not a non-negative
        integer, or ``size_px < 2 ** octaves``.
    """
    size = positive_int("size_px", size_px)
    n_oct = positive_int("octaves", octaves)
    rng = np.random.default_rng(_seed("seed", seed))
    if n_oct > 30 or 2**n_oct > size:
        raise ParameterError(f"size_px must be at least 2 ** octaves (octaves={n_oct}), got {size_px!r}")
    # Octave k has Gaussian sigma 2**k texels and is drawn on a grid of step 2**max(0, k - 1)
    # texels: sigma is 2 grid steps for every octave that is upsampled, so it is well sampled.
    # All grids are periodic over the same extent, a multiple of the coarsest step, so each level
    # is upsampled by 2 exactly (cubic spline, wrapping) and added to the next finer one: no
    # seams, no edge effects. The texture is the top-left size x size window of that field.
    steps = [2 ** max(0, k - 1) for k in range(n_oct)]
    extent = -(-size // steps[-1]) * steps[-1]
    w_lum, w_chroma = math.sqrt(0.6), math.sqrt(0.4)
    total: np.ndarray | None = None
    for k in reversed(range(n_oct)):
        step = steps[k]
        m = extent // step
        if total is not None and total.shape[1] != m:
            total = np.stack([ndimage.zoom(ch, 2, order=3, mode="grid-wrap", grid_mode=True) for ch in total])
        fields = rng.standard_normal((4, m, m), dtype=np.float32)
        smooth = [ndimage.gaussian_filter(field, 2.0**k / step, mode="wrap") for field in fields]
        lum = w_lum * smooth[0] / smooth[0].std()
        band = np.stack([lum + w_chroma * ch / ch.std() for ch in smooth[1:]])
        total = band if total is None else total + band
    assert total is not None
    total = total[:, :size, :size]
    z = (total - total.mean(axis=(1, 2), keepdims=True)) / total.std(axis=(1, 2), keepdims=True)
    mid = 0.5 * (_TEXTURE_LOW + _TEXTURE_HIGH)
    half = 0.5 * (_TEXTURE_HIGH - _TEXTURE_LOW)
    out = (mid + half * np.tanh(0.6 * z)).transpose(1, 2, 0).astype(np.float32)
    return np.clip(out, np.float32(_TEXTURE_LOW), np.float32(_TEXTURE_HIGH))


def _margin_texels(margin_squares: float, texels_per_square: int) -> int:
    margin = margin_squares * texels_per_square
    rounded = round(margin)
    if abs(margin - rounded) > 1e-9 * max(1.0, margin):
        raise ParameterError(
            f"margin_squares * texels_per_square must be a whole number of texels so that square "
            f"edges fall on texel edges, got margin_squares={margin_squares!r} with "
            f"texels_per_square={texels_per_square}"
        )
    return int(rounded)


def chessboard_texture(*, squares: tuple[int, int], texels_per_square: int, margin_squares: float = 1.0) -> np.ndarray:
    """A black/white chessboard with a white margin, as a texture.

    Parameters
    ----------
    squares : tuple of int
        ``(columns, rows)`` of squares, each at least 2. OpenCV's
        ``findChessboardCorners`` needs at least 4 per side (pattern size ``(columns - 1,
        rows - 1)``), and a board with one even and one odd count has no 180-degree ambiguity.
    texels_per_square : int
        Edge length of a square in texels. Square edges fall exactly on texel edges.
    margin_squares : float, optional
        Width of the white margin on every side, in squares (default 1.0; OpenCV's detector
        needs a white border). ``margin_squares * texels_per_square`` must be a whole number.

    Returns
    -------
    numpy.ndarray
        float32 array of shape ``(H, W, 3)`` with ``H = (rows + 2 * margin_squares) *
        texels_per_square`` and ``W = (columns + 2 * margin_squares) * texels_per_square``.
        Black squares are :data:`BLACK` (0.05), white squares and the margin are :data:`WHITE`
        (0.9) in all channels. The top-left square (just inside the margin) is black; the square
        in column ``i``, row ``j`` (0-based) is black when ``i + j`` is even.

    Raises
    ------
    ParameterError
        If a parameter is out of range, or the margin is not a whole number of texels.
    """
    cols, rows = _squares(squares)
    tps = positive_int("texels_per_square", texels_per_square)
    margin = non_negative_float("margin_squares", margin_squares)
    m_tex = _margin_texels(margin, tps)
    height = rows * tps + 2 * m_tex
    width = cols * tps + 2 * m_tex
    r = np.arange(height) - m_tex
    c = np.arange(width) - m_tex
    inside = ((r >= 0) & (r < rows * tps))[:, None] & ((c >= 0) & (c < cols * tps))[None, :]
    parity = ((r // tps)[:, None] + (c // tps)[None, :]) % 2 == 0
    grey = np.where(inside & parity, np.float32(BLACK), np.float32(WHITE)).astype(np.float32)
    return np.repeat(grey[:, :, None], 3, axis=2)


def chessboard_size_m(
    *, squares: tuple[int, int], square_size_m: float, margin_squares: float = 1.0
) -> tuple[float, float]:
    """Physical size of the whole :func:`chessboard_texture`, margin included.

    Parameters
    ----------
    squares : tuple of int
        ``(columns, rows)`` of squares, each at least 2.
    square_size_m : float
        Edge length of one square, metres.
    margin_squares : float, optional
        Margin width on every side, in squares (default 1.0).

    Returns
    -------
    tuple of float
        ``(width_m, height_m)`` = ``((columns + 2 * margin) * s, (rows + 2 * margin) * s)``.
    """
    cols, rows = _squares(squares)
    s = positive_float("square_size_m", square_size_m)
    margin = non_negative_float("margin_squares", margin_squares)
    return (cols + 2.0 * margin) * s, (rows + 2.0 * margin) * s


def chessboard_inner_corners(
    *, squares: tuple[int, int], square_size_m: float, margin_squares: float = 1.0
) -> np.ndarray:
    """Inner-corner positions of :func:`chessboard_texture` in the board's plane frame.

    Parameters
    ----------
    squares : tuple of int
        ``(columns, rows)`` of squares, each at least 2.
    square_size_m : float
        Edge length of one square, metres.
    margin_squares : float, optional
        Margin width on every side, in squares (default 1.0).

    Returns
    -------
    numpy.ndarray
        float64 array of shape ``((columns - 1) * (rows - 1), 2)``: ``(x, y)`` in metres, origin
        at the centre of the whole texture (margin included), +x right (increasing texture
        column), +y down (increasing texture row). Ordered row by row from the top-left corner,
        x varying fastest, as OpenCV's ``findChessboardCorners`` reports them for pattern size
        ``(columns - 1, rows - 1)`` on an upright board.
    """
    cols, rows = _squares(squares)
    s = positive_float("square_size_m", square_size_m)
    margin = non_negative_float("margin_squares", margin_squares)
    width, height = chessboard_size_m(squares=(cols, rows), square_size_m=s, margin_squares=margin)
    x = (margin + np.arange(1, cols)) * s - 0.5 * width
    y = (margin + np.arange(1, rows)) * s - 0.5 * height
    xx, yy = np.meshgrid(x, y, indexing="xy")
    return np.stack([xx.ravel(), yy.ravel()], axis=1)


# --------------------------------------------------------------------------------------------
# meshes
# --------------------------------------------------------------------------------------------


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Smooth per-vertex unit normals: area-weighted sums of the adjacent face normals.

    Parameters
    ----------
    vertices : numpy.ndarray
        (V, 3) positions.
    faces : numpy.ndarray
        (F, 3) vertex indices, wound counter-clockwise seen from the side the normals face.

    Returns
    -------
    numpy.ndarray
        (V, 3) float64 unit vectors.

    Raises
    ------
    ParameterError
        If an array has the wrong shape, type or range, or a vertex belongs to no face or its
        adjacent faces cancel out.
    """
    v = _finite_array("vertices", vertices, 3)
    f = _faces(faces, len(v))
    # The cross product has length twice the triangle area: summing it weights faces by area.
    cross = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    acc = np.zeros_like(v)
    for k in range(3):
        for axis in range(3):
            acc[:, axis] += np.bincount(f[:, k], weights=cross[:, axis], minlength=len(v))
    norm = np.linalg.norm(acc, axis=1)
    if np.any(norm <= 0.0):
        bad = int(np.flatnonzero(norm <= 0.0)[0])
        raise ParameterError(f"vertex {bad} has no well-defined normal (no faces, or faces that cancel)")
    return acc / norm[:, None]


def _closed_grid_faces(n_rings: int, n_seg: int) -> np.ndarray:
    """Faces of a sphere-like grid: vertex 0 (first pole), rings of ``n_seg``, last vertex (pole).

    Ring ``i`` vertex ``j`` is ``1 + i * n_seg + j``. With ``s`` the ring direction and ``phi``
    the in-ring direction, triangles are wound so their normal is along ``dP/ds x dP/dphi``.
    """
    south = 1 + n_rings * n_seg
    j = np.arange(n_seg)
    jn = (j + 1) % n_seg
    north_fan = np.stack([np.zeros(n_seg, dtype=np.int64), 1 + j, 1 + jn], axis=1)
    last = 1 + (n_rings - 1) * n_seg
    south_fan = np.stack([last + j, np.full(n_seg, south), last + jn], axis=1)
    i = np.arange(n_rings - 1)[:, None]
    a = 1 + i * n_seg + j[None, :]
    b = a + n_seg
    c = 1 + i * n_seg + jn[None, :]
    d = c + n_seg
    quads1 = np.stack([a, b, c], axis=-1).reshape(-1, 3)
    quads2 = np.stack([b, d, c], axis=-1).reshape(-1, 3)
    return np.concatenate([north_fan, quads1, quads2, south_fan]).astype(np.int32)


def _revolve(profile_r: np.ndarray, profile_z: np.ndarray, segments: int) -> tuple[np.ndarray, np.ndarray]:
    """Surface of revolution about the z axis of a profile that starts and ends on the axis."""
    phi = 2.0 * np.pi * np.arange(segments) / segments
    r_in, z_in = profile_r[1:-1], profile_z[1:-1]
    ring = np.stack(
        [
            r_in[:, None] * np.cos(phi)[None, :],
            r_in[:, None] * np.sin(phi)[None, :],
            np.broadcast_to(z_in[:, None], (len(r_in), segments)),
        ],
        axis=-1,
    ).reshape(-1, 3)
    verts = np.concatenate([[[0.0, 0.0, profile_z[0]]], ring, [[0.0, 0.0, profile_z[-1]]]])
    return verts, _closed_grid_faces(len(r_in), segments)


def bowl_cap_geometry(*, radius_m: float, depth_m: float, thickness_m: float) -> dict[str, float]:
    """Exact geometry of the smooth solid that :func:`bowl_mesh` approximates.

    Parameters
    ----------
    radius_m, depth_m, thickness_m : float
        As for :func:`bowl_mesh`, metres, with the same constraints.

    Returns
    -------
    dict
        ``sphere_radius_m`` (radius of the mid-surface sphere), ``half_angle_rad`` (polar angle
        of the rim), ``centre_z_m`` (z of the sphere centre in the bowl's frame) and
        ``volume_m3`` (exact volume of the smooth solid, walls plus rounded rim).
    """
    a = positive_float("radius_m", radius_m)
    h = positive_float("depth_m", depth_m)
    t = positive_float("thickness_m", thickness_m)
    if h > a:
        raise ParameterError(f"depth_m must not exceed radius_m={a!r} (at most a hemisphere), got {depth_m!r}")
    if t >= h:
        raise ParameterError(f"thickness_m must be smaller than depth_m={h!r}, got {thickness_m!r}")
    a_mid, h_mid = a - 0.5 * t, h - t
    rho = (a_mid**2 + h_mid**2) / (2.0 * h_mid)
    theta_c = math.atan2(a_mid, rho - h_mid)
    centre_z = 0.5 * h - rho - 0.5 * t
    shell = 2.0 * math.pi / 3.0 * ((rho + 0.5 * t) ** 3 - (rho - 0.5 * t) ** 3) * (1.0 - math.cos(theta_c))
    # Half-torus rim (Pappus): half-disc area times the path of its centroid.
    centroid_r = rho * math.sin(theta_c) + 2.0 * t / (3.0 * math.pi) * math.cos(theta_c)
    rim = (math.pi * t * t / 8.0) * 2.0 * math.pi * centroid_r
    return {
        "sphere_radius_m": rho,
        "half_angle_rad": theta_c,
        "centre_z_m": centre_z,
        "volume_m3": shell + rim,
    }


def bowl_mesh(
    *, radius_m: float, depth_m: float, thickness_m: float, segments: int = 96, rings: int = 32
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A closed, thin-walled spherical bowl with a rounded rim, opening towards the viewer.

    The wall is a spherical cap (the mid-surface) thickened by ``thickness_m / 2`` on each side;
    a half-torus of diameter ``thickness_m`` rounds the rim and joins the outer and inner
    surfaces smoothly, so the mesh is a single closed surface. The dimensions are those of the
    solid: its outer radius at the rim is ``radius_m`` and its extent along z is ``depth_m``.

    Parameters
    ----------
    radius_m : float
        Outer radius of the bowl (half its width), metres.
    depth_m : float
        Outer depth from the rim plane to the outside of the bottom, metres; at most
        ``radius_m`` (at most a hemisphere).
    thickness_m : float
        Wall thickness, metres; smaller than ``depth_m``.
    segments : int, optional
        Vertices around the axis (default 96, at least 8).
    rings : int, optional
        Vertex rings on each of the outer and inner walls from the bottom to the rim (default
        32, at least 2). The rim half-circle has ``max(4, rings // 2)`` segments.

    Returns
    -------
    vertices : numpy.ndarray
        (V, 3) float64, metres, in the bowl's frame: origin at the centre of its bounding box,
        the axis along z, the opening facing the viewer (-z) with the rim's extreme in the plane
        ``z = -depth_m / 2`` and the outside of the bottom at ``z = +depth_m / 2``; +y down.
        The bounding box is ``[-radius_m, radius_m]`` in x and y (up to the polygonal
        approximation of the circles) and ``[-depth_m / 2, depth_m / 2]`` in z.
    faces : numpy.ndarray
        (F, 3) int32, counter-clockwise seen from outside the solid.
    normals : numpy.ndarray
        (V, 3) float64 smooth unit normals pointing out of the solid.

    Raises
    ------
    ParameterError
        If a size is not positive, ``depth_m > radius_m``, ``thickness_m >= depth_m``, or
        ``segments``/``rings`` are too small.
    """
    geo = bowl_cap_geometry(radius_m=radius_m, depth_m=depth_m, thickness_m=thickness_m)
    n_seg = _int_at_least("segments", segments, 8)
    n_rings = _int_at_least("rings", rings, 2)
    t = float(thickness_m)
    rho, theta_c, cz = geo["sphere_radius_m"], geo["half_angle_rad"], geo["centre_z_m"]

    # Profile in the (r, z) half-plane: outer apex -> outer wall -> rim -> inner wall -> inner apex.
    th = theta_c * np.arange(n_rings + 1) / n_rings
    r_out, z_out = (rho + 0.5 * t) * np.sin(th), cz + (rho + 0.5 * t) * np.cos(th)
    n_rim = max(4, n_rings // 2)
    psi = np.pi * np.arange(n_rim + 1) / n_rim
    # Move the nearest rim samples onto the rim's widest point (psi = pi/2 - theta_c) and its
    # point nearest the viewer (psi = pi - theta_c) so the bounding box is exact; an extreme
    # nearer to an end of the half-circle than to an interior sample is left to that end.
    for extreme in (0.5 * np.pi - theta_c, np.pi - theta_c):
        k = int(np.argmin(np.abs(psi - extreme)))
        if 0 < k < n_rim:
            psi[k] = extreme
    psi = psi[1:-1]
    u = np.array([math.sin(theta_c), math.cos(theta_c)])  # radial direction at the rim
    tau = np.array([math.cos(theta_c), -math.sin(theta_c)])  # direction of increasing polar angle
    mid = np.array([0.0, cz]) + rho * u
    rim = mid[None, :] + 0.5 * t * (np.cos(psi)[:, None] * u[None, :] + np.sin(psi)[:, None] * tau[None, :])
    th_in = th[::-1]
    r_in, z_in = (rho - 0.5 * t) * np.sin(th_in), cz + (rho - 0.5 * t) * np.cos(th_in)
    profile_r = np.concatenate([r_out, rim[:, 0], r_in])
    profile_z = np.concatenate([z_out, rim[:, 1], z_in])
    profile_r[0] = profile_r[-1] = 0.0
    verts, faces = _revolve(profile_r, profile_z, n_seg)
    return verts, faces, vertex_normals(verts, faces)


# Figurine components in body units (y down, -z towards the viewer): axis-aligned ellipsoids
# (centre, semi-axes). The first one contains the origin, which makes the shape star-shaped.
_FIGURINE_PARTS: tuple[tuple[tuple[float, float, float], tuple[float, float, float]], ...] = (
    ((0.0, 0.0, 0.0), (0.75, 0.95, 0.65)),  # body
    ((0.0, -1.25, -0.05), (0.56, 0.52, 0.52)),  # head
    ((-0.38, -1.72, 0.02), (0.2, 0.24, 0.14)),  # left ear
    ((0.38, -1.72, 0.02), (0.2, 0.24, 0.14)),  # right ear
    ((0.0, -1.12, -0.52), (0.24, 0.18, 0.2)),  # snout
    ((-0.8, -0.2, -0.15), (0.36, 0.2, 0.2)),  # left arm
    ((0.8, -0.2, -0.15), (0.36, 0.2, 0.2)),  # right arm
    ((-0.42, 0.9, -0.15), (0.26, 0.18, 0.34)),  # left foot
    ((0.42, 0.9, -0.15), (0.26, 0.18, 0.34)),  # right foot
    ((0.0, 0.45, 0.66), (0.16, 0.16, 0.18)),  # tail
)
_FIGURINE_BLEND = 10.0  # sharpness of the smooth maximum, per body unit


def _ray_ellipsoid_far(d: np.ndarray, centre: np.ndarray, semi: np.ndarray) -> np.ndarray:
    """Far intersection distance of rays from the origin along unit ``d`` with an ellipsoid.

    Where a ray misses, the square root of the negative discriminant continues with a negative
    sign, which keeps the radial function continuous and falls off steeply past the silhouette.
    """
    ds = d / semi
    cs = centre / semi
    a = np.einsum("ij,ij->i", ds, ds)
    b = ds @ cs
    disc = b * b - a * (cs @ cs - 1.0)
    return (b + np.sign(disc) * np.sqrt(np.abs(disc))) / a


def figurine_mesh(*, height_m: float, seed: int = 0, resolution: int = 64) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A closed, organic, figurine-like shape: a small creature with head, ears, arms and feet.

    The surface is star-shaped about the centre of the body: along every direction ``d`` its
    distance from that centre is a smooth maximum (log-sum-exp) of the far intersection
    distances of the ray with ten ellipsoids (body, head, ears, snout, arms, feet, tail), which
    blends the parts smoothly, times ``1 + b(d)`` where ``b`` is a sum of seeded low-frequency
    bumps. The seed also jitters the parts' positions and sizes. A radial graph over the sphere
    cannot self-intersect, so the mesh (a UV-sphere grid with single-vertex poles) is closed and
    consistently oriented. The result is scaled so that its height is exactly ``height_m``.

    Parameters
    ----------
    height_m : float
        Height of the figurine (its extent along y), metres.
    seed : int, optional
        Non-negative seed of the shape variations (default 0).
    resolution : int, optional
        Number of latitude bands of the sphere grid (default 64, at least 40: coarser grids
        cannot resolve the ears, and their smooth normals turn against some faces); there are
        ``2 * resolution`` vertices around each ring and ``(resolution - 1) * 2 * resolution + 2``
        vertices in all.

    Returns
    -------
    vertices : numpy.ndarray
        (V, 3) float64, metres, in the figurine's frame: origin at the centre of its bounding
        box, head up (towards -y), face towards the viewer (-z), its left/right along x. The
        extent along y is ``height_m``.
    faces : numpy.ndarray
        (F, 3) int32, counter-clockwise seen from outside.
    normals : numpy.ndarray
        (V, 3) float64 smooth unit normals pointing outward.

    Raises
    ------
    ParameterError
        If ``height_m`` is not positive, ``seed`` is negative or ``resolution < 40``.
    """
    height = positive_float("height_m", height_m)
    rng = np.random.default_rng(_seed("seed", seed))
    n_lat = _int_at_least("resolution", resolution, 40)
    n_lon = 2 * n_lat

    # Directions on the UV sphere; its pole axis is -y (the north pole is straight up).
    theta = np.pi * np.arange(1, n_lat) / n_lat
    phi = 2.0 * np.pi * np.arange(n_lon) / n_lon
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    sx, sy, sz = (st * np.cos(phi)).ravel(), (st * np.sin(phi)).ravel(), np.repeat(ct.ravel(), n_lon)
    d_std = np.concatenate([[[0.0, 0.0, 1.0]], np.stack([sx, sy, sz], axis=1), [[0.0, 0.0, -1.0]]])
    # (x, y, z)_standard -> (x, -z, y): a proper rotation, so the winding stays outward.
    d = np.stack([d_std[:, 0], -d_std[:, 2], d_std[:, 1]], axis=1)

    dists = []
    for k, (centre, semi) in enumerate(_FIGURINE_PARTS):
        c = np.asarray(centre, dtype=np.float64)
        s = np.asarray(semi, dtype=np.float64)
        if k > 0:  # the body stays centred on the origin
            c = c + rng.uniform(-0.05, 0.05, size=3)
        s = s * rng.uniform(0.9, 1.1, size=3)
        dists.append(_ray_ellipsoid_far(d, c, s))
    dist = np.stack(dists)
    top = dist.max(axis=0)
    r = top + np.log(np.exp(_FIGURINE_BLEND * (dist - top)).sum(axis=0)) / _FIGURINE_BLEND

    n_bumps = 8
    axes = rng.standard_normal((n_bumps, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    amp = rng.uniform(-0.035, 0.035, size=n_bumps)
    kappa = rng.uniform(2.0, 6.0, size=n_bumps)
    bumps = (amp[None, :] * np.exp(kappa[None, :] * (d @ axes.T - 1.0))).sum(axis=1)
    verts = d * (r * (1.0 + bumps))[:, None]

    lo, hi = verts.min(axis=0), verts.max(axis=0)
    verts = (verts - 0.5 * (lo + hi)) * (height / (hi[1] - lo[1]))
    faces = _closed_grid_faces(n_lat - 1, n_lon)
    return verts, faces, vertex_normals(verts, faces)


# --------------------------------------------------------------------------------------------
# PLY
# --------------------------------------------------------------------------------------------


def write_ply(
    path: str | os.PathLike[str],
    vertices: np.ndarray,
    faces: np.ndarray,
    normals: np.ndarray | None = None,
    *,
    texcoords: np.ndarray | None = None,
) -> Path:
    """Write a triangle mesh as a binary little-endian PLY file (readable by Mitsuba's ``ply``).

    The header declares ``element vertex V`` with ``float x, y, z``, then ``float nx, ny, nz``
    when ``normals`` is given and ``float u, v`` when ``texcoords`` is given, and
    ``element face F`` with ``property list uchar int vertex_indices``. Values are written as
    float32 and int32. The file is written to a temporary file beside ``path`` and renamed, so
    no half-written file is left behind.

    Parameters
    ----------
    path : str or os.PathLike
        Destination; its directory must exist. An existing file is replaced.
    vertices : numpy.ndarray
        (V, 3) finite positions.
    faces : numpy.ndarray
        (F, 3) integer vertex indices in ``[0, V)``.
    normals : numpy.ndarray, optional
        (V, 3) finite per-vertex normals.
    texcoords : numpy.ndarray, optional
        (V, 2) finite per-vertex texture coordinates ``(u, v)``.

    Returns
    -------
    pathlib.Path
        The path written.

    Raises
    ------
    ParameterError
        If an array has the wrong shape or type, holds non-finite values or out-of-range
        indices, or the mesh is empty.
    """
    v = _finite_array("vertices", vertices, 3)
    if len(v) == 0:
        raise ParameterError("vertices must not be empty, got shape (0, 3)")
    f = _faces(faces, len(v))
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    columns = [v]
    if normals is not None:
        n = _finite_array("normals", normals, 3)
        if len(n) != len(v):
            raise ParameterError(f"normals must have one row per vertex ({len(v)}), got {len(n)}")
        fields += [("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4")]
        columns.append(n)
    if texcoords is not None:
        uv = _finite_array("texcoords", texcoords, 2)
        if len(uv) != len(v):
            raise ParameterError(f"texcoords must have one row per vertex ({len(v)}), got {len(uv)}")
        fields += [("u", "<f4"), ("v", "<f4")]
        columns.append(uv)
    vert_rec = np.empty(len(v), dtype=np.dtype(fields))
    flat = np.concatenate(columns, axis=1)
    for k, (name, _) in enumerate(fields):
        vert_rec[name] = flat[:, k]
    face_rec = np.empty(len(f), dtype=np.dtype([("n", "u1"), ("i", "<i4", (3,))]))
    face_rec["n"] = 3
    face_rec["i"] = f
    header = ["ply", "format binary_little_endian 1.0", "comment written by simulator.assets"]
    header.append(f"element vertex {len(v)}")
    header += [f"property float {name}" for name, _ in fields]
    header += [f"element face {len(f)}", "property list uchar int vertex_indices", "end_header"]

    out = Path(path)
    with atomic_file(out) as tmp, tmp.open("wb") as fh:
        fh.write(("\n".join(header) + "\n").encode("ascii"))
        fh.write(vert_rec.tobytes())
        fh.write(face_rec.tobytes())
    return out
