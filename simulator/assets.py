"""Procedural scene content in plain numpy: textures, calibration boards and triangle meshes.

Everything here is deterministic given its arguments (and ``seed`` where there is one), does not
import Mitsuba or Dr.Jit, and validates its input with :class:`lfrefract.validate.ParameterError`.

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

import functools
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy import ndimage

from lfrefract.errors import FileFormatError, ParameterError
from lfrefract.formats.outputs import atomic_file
from lfrefract.validate import non_negative_float, positive_float, positive_int, regular_file, shown
from simulator import seeds

__all__ = [
    "BLACK",
    "MAX_MESH_FILE_BYTES",
    "TEXTURE_OCTAVES",
    "WHITE",
    "ChessboardLayout",
    "bowl_cap_geometry",
    "bowl_mesh",
    "check_mesh_content",
    "check_mesh_file",
    "chessboard_inner_corners",
    "chessboard_size_m",
    "chessboard_texture",
    "chessboard_texture_shape",
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

#: Default number of noise scales of :func:`random_texture` (features of 2 to 64 texels); a
#: texture needs at least ``2 ** TEXTURE_OCTAVES`` texels a side.
TEXTURE_OCTAVES = 6


# --------------------------------------------------------------------------------------------
# validation helpers
# --------------------------------------------------------------------------------------------


def _int_at_least(name: str, value: Any, minimum: int) -> int:
    out = positive_int(name, value)
    if out < minimum:
        raise ParameterError(f"{name} must be at least {minimum}, got {value!r}")
    return out


def _squares(value: Any) -> tuple[int, int]:
    """``(columns, rows)``, two integers of at least 2 (the one check of a chessboard's squares)."""
    if isinstance(value, (str, bytes, dict)) or not hasattr(value, "__len__") or len(value) != 2:
        raise ParameterError(f"squares must be (columns, rows), a list of 2 integers, got {shown(value)}")
    items = tuple(value)
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


def random_texture(*, size_px: int, seed: int, octaves: int = TEXTURE_OCTAVES) -> np.ndarray:
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
        Seed of the random generator, an integer in [0, 2**31) (:func:`simulator.seeds.seed`); the
        same seed gives the same texture.
    octaves : int, optional
        Number of noise scales (default :data:`TEXTURE_OCTAVES`, 6). Octave ``k`` (0-based) has features of about
        ``2 ** (k + 1)`` texels (Gaussian standard deviation ``2 ** k`` texels).

    Returns
    -------
    numpy.ndarray
        float32 array of shape ``(size_px, size_px, 3)``, linear RGB in [0.05, 0.95]; row 0 is the
        top of the texture.

    Raises
    ------
    ParameterError
        If ``size_px`` or ``octaves`` is not a positive integer, ``seed`` is not an integer in
        [0, 2**31), or ``size_px < 2 ** octaves``.
    """
    size = positive_int("size_px", size_px)
    n_oct = positive_int("octaves", octaves)
    rng = np.random.default_rng(seeds.seed("seed", seed))
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
    if not math.isfinite(margin):
        raise ParameterError(
            f"margin_squares * texels_per_square must be finite, got margin_squares={margin_squares!r} with "
            f"texels_per_square={texels_per_square}"
        )
    rounded = round(margin)
    if abs(margin - rounded) > 1e-9 * max(1.0, margin):
        raise ParameterError(
            f"margin_squares * texels_per_square must be a whole number of texels so that square "
            f"edges fall on texel edges, got margin_squares={margin_squares!r} with "
            f"texels_per_square={texels_per_square}"
        )
    return int(rounded)


@dataclass(frozen=True, kw_only=True)
class ChessboardLayout:
    """A chessboard's squares and margin, checked once (on construction).

    Parameters
    ----------
    squares : tuple of int
        ``(columns, rows)`` of squares, each at least 2. OpenCV's ``findChessboardCorners`` needs
        at least 4 per side (pattern size ``(columns - 1, rows - 1)``), and a board with one even
        and one odd count has no 180-degree ambiguity.
    margin_squares : float, optional
        Width of the white margin on every side, in squares (default 1.0; OpenCV's detector
        needs a white border), at least 0.

    Raises
    ------
    ParameterError
        If ``squares`` is not a pair of integers of at least 2 or the margin is negative or not
        finite; the message names the key and the value.
    """

    squares: tuple[int, int]
    margin_squares: float = 1.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "squares", _squares(self.squares))
        object.__setattr__(self, "margin_squares", non_negative_float("margin_squares", self.margin_squares))

    def texture_shape(self, texels_per_square: int) -> tuple[int, int]:
        """``(H, W)`` of :meth:`texture` at ``texels_per_square``, without building it.

        Raises
        ------
        ParameterError
            If ``texels_per_square`` is not a positive integer or the margin is not a whole
            number of texels at it.
        """
        cols, rows = self.squares
        tps = positive_int("texels_per_square", texels_per_square)
        m_tex = _margin_texels(self.margin_squares, tps)
        return rows * tps + 2 * m_tex, cols * tps + 2 * m_tex

    def texture(self, texels_per_square: int) -> np.ndarray:
        """The board as a texture (see :func:`chessboard_texture`), float32 (H, W, 3)."""
        height, width = self.texture_shape(texels_per_square)
        cols, rows = self.squares
        tps = int(texels_per_square)
        m_tex = (width - cols * tps) // 2
        r = np.arange(height) - m_tex
        c = np.arange(width) - m_tex
        inside = ((r >= 0) & (r < rows * tps))[:, None] & ((c >= 0) & (c < cols * tps))[None, :]
        parity = ((r // tps)[:, None] + (c // tps)[None, :]) % 2 == 0
        grey = np.where(inside & parity, np.float32(BLACK), np.float32(WHITE)).astype(np.float32)
        return np.repeat(grey[:, :, None], 3, axis=2)

    def size_m(self, square_size_m: float) -> tuple[float, float]:
        """``(width_m, height_m)`` of the whole board, margin included, for squares of
        ``square_size_m`` metres (positive)."""
        cols, rows = self.squares
        s = positive_float("square_size_m", square_size_m)
        return (cols + 2.0 * self.margin_squares) * s, (rows + 2.0 * self.margin_squares) * s

    def inner_corners_m(self, square_size_m: float) -> np.ndarray:
        """Inner-corner positions (N, 2), metres, in the board's plane frame (see
        :func:`chessboard_inner_corners`)."""
        cols, rows = self.squares
        width, height = self.size_m(square_size_m)
        s, margin = float(square_size_m), self.margin_squares
        x = (margin + np.arange(1, cols)) * s - 0.5 * width
        y = (margin + np.arange(1, rows)) * s - 0.5 * height
        xx, yy = np.meshgrid(x, y, indexing="xy")
        return np.stack([xx.ravel(), yy.ravel()], axis=1)


def chessboard_texture(*, squares: tuple[int, int], texels_per_square: int, margin_squares: float = 1.0) -> np.ndarray:
    """A black/white chessboard with a white margin, as a texture.

    Parameters
    ----------
    squares : tuple of int
        ``(columns, rows)`` of squares, each at least 2 (:class:`ChessboardLayout`).
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
    return ChessboardLayout(squares=squares, margin_squares=margin_squares).texture(texels_per_square)


def chessboard_texture_shape(
    *, squares: tuple[int, int], texels_per_square: int, margin_squares: float = 1.0
) -> tuple[int, int]:
    """``(H, W)`` of :func:`chessboard_texture`, without building it, with the same checks.

    Returns
    -------
    tuple of int
        ``(H, W)`` = ``((rows + 2 * margin_squares) * texels_per_square,
        (columns + 2 * margin_squares) * texels_per_square)``.

    Raises
    ------
    ParameterError
        As :func:`chessboard_texture`.
    """
    return ChessboardLayout(squares=squares, margin_squares=margin_squares).texture_shape(texels_per_square)


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
    return ChessboardLayout(squares=squares, margin_squares=margin_squares).size_m(square_size_m)


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
    return ChessboardLayout(squares=squares, margin_squares=margin_squares).inner_corners_m(square_size_m)


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
        Seed of the shape variations, an integer in [0, 2**31) (:func:`simulator.seeds.seed`;
        default 0).
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
        If ``height_m`` is not positive, ``seed`` is not a seed (:func:`simulator.seeds.seed`) or ``resolution < 40``.
    """
    height = positive_float("height_m", height_m)
    rng = np.random.default_rng(seeds.seed("seed", seed))
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
# user mesh files (OBJ, PLY): cheap checks before Mitsuba reads them
# --------------------------------------------------------------------------------------------

#: Largest user mesh file, bytes (512 MiB). An OBJ spends about 30 bytes on a vertex line and 20
#: on a face line, so 512 MiB is some 10 million triangles, far more detail than a preset
#: camera resolves (the Illum's refraction-free image has 0.23 Mpx); Mitsuba needs several
#: times the file's size in memory to load it and about a minute per GiB. A larger file is a
#: mistake (a sparse or wrong file), refused from its size alone before anything reads it.
MAX_MESH_FILE_BYTES = 512 * 2**20

#: Longest OBJ line: Mitsuba's OBJ reader copies each line into a 1025-byte buffer.
_OBJ_MAX_LINE = 1023
#: OBJ content is checked in blocks of this many bytes (bounded memory whatever the file).
_OBJ_BLOCK = 8 * 2**20
#: A PLY header must end within this many bytes.
_PLY_MAX_HEADER = 64 * 2**10
_PLY_TYPES = {
    "char": 1, "uchar": 1, "int8": 1, "uint8": 1,
    "short": 2, "ushort": 2, "int16": 2, "uint16": 2, "half": 2,
    "int": 4, "uint": 4, "int32": 4, "uint32": 4, "float": 4, "float32": 4,
    "long": 8, "ulong": 8, "double": 8, "float64": 8,
}  # fmt: skip


def check_mesh_file(path: str | os.PathLike[str]) -> int:
    """Size of a user mesh file, checked from its metadata alone: a regular file of at most
    :data:`MAX_MESH_FILE_BYTES`.

    Raises
    ------
    ParameterError
        If ``path`` does not exist, is not a regular file (a directory, a FIFO: the message says
        which) or is larger than :data:`MAX_MESH_FILE_BYTES`; the message names the path.
    """
    return regular_file("mesh path", path, max_bytes=MAX_MESH_FILE_BYTES)


def check_mesh_content(path: str | os.PathLike[str]) -> None:
    """Check that a user mesh file (``.obj`` or ``.ply``) holds a triangle mesh Mitsuba can read.

    Cheap checks, so that a wrong file gets a message naming the file and the problem rather
    than Mitsuba's internal one (an empty or garbage OBJ gives "Storing new normals in a Mesh
    that didn't have normals at construction time"). First :func:`check_mesh_file` (kind, size).

    OBJ (ASCII text, read in blocks, vectorised: about 0.3 s per 10 MiB on two busy cores, half
    the time Mitsuba takes to load it; a file that passed is not read again while unchanged):
    every line is blank, a ``#`` comment, or a statement Mitsuba reads (``v``, ``vn``, ``vt``,
    ``f``) or skips (``o``, ``g``, ``s``, ``l``, ``p``, ``mg``, ``vp``, ``usemtl``, ``mtllib``);
    no line is longer than 1023 characters (Mitsuba's limit); ``v`` and ``vn`` lines hold at
    least 3 numbers and ``vt`` lines at least 2, each a decimal number (``[+-]digits[.digits]
    [e[+-]digits]``; no ``nan``, ``inf`` or hexadecimal); ``f`` lines hold at least 3 vertex
    references of unsigned indices (``i``, ``i/j``, ``i//k``, ``i/j/k``: Mitsuba does not read
    negative, relative, indices); and there is at least one ``v`` and one ``f`` line. The range
    of each index is left to Mitsuba, whose message names it.

    PLY (the header only, and the file's size): ``ply`` then ``format ascii|binary_little_endian|
    binary_big_endian 1.0``, ``element``, ``property`` (of a known type), ``comment`` and
    ``obj_info`` lines up to ``end_header`` within 64 KiB; a ``vertex`` element of at least one
    vertex with ``x``, ``y`` and ``z``; a ``face`` element of at least one face with a list
    property ``vertex_indices`` (or ``vertex_index``). A binary file must be at least as long as
    its elements with triangular faces (Mitsuba reads triangles only).

    Parameters
    ----------
    path : path-like
        The mesh file; its suffix (``.obj`` or ``.ply``, any case) selects the format.

    Raises
    ------
    ParameterError
        From :func:`check_mesh_file`, or for a suffix other than ``.obj`` and ``.ply``.
    FileFormatError
        If the content is not what the format needs; the message starts with the quoted path
        and says what is wrong (and, for an OBJ, on which line).
    """
    p = Path(path)
    size = check_mesh_file(p)
    suffix = p.suffix.lower()
    if suffix not in (".obj", ".ply"):
        raise ParameterError(f"mesh path must end in .obj or .ply, got {str(p)!r}")
    if size == 0:
        raise FileFormatError(f"{str(p)!r}: the file is empty")
    st = p.stat()
    _check_content(str(p), suffix, size, (st.st_dev, st.st_ino, st.st_mtime_ns, st.st_ctime_ns))


@functools.lru_cache(maxsize=32)
def _check_content(path: str, suffix: str, size: int, stat_key: tuple[int, ...]) -> None:
    """The content check, remembered while the file is unchanged (same size, device, inode, modification
    and status change time: ``cp -p`` keeps the inode and mtime, but the kernel sets ctime on every
    write): a job loads a mesh into several scenes (raw, ideal). Refusals are not cached."""
    if suffix == ".obj":
        _check_obj(Path(path))
    else:
        _check_ply(Path(path), size)


def _check_obj(path: Path) -> None:
    counts = {"v": 0, "f": 0}
    line0 = 0  # lines before the current block
    carry = b""
    with path.open("rb") as fh:
        while True:
            block = fh.read(_OBJ_BLOCK)
            data = carry + block
            if not block:
                if data:
                    _check_obj_lines(path, data + b"\n", line0, counts)
                break
            cut = data.rfind(b"\n") + 1
            if cut == 0:
                _obj_error(path, line0 + 1, data[:40], f"is longer than {_OBJ_MAX_LINE} characters (Mitsuba's limit)")
            line0 += _check_obj_lines(path, data[:cut], line0, counts)
            carry = data[cut:]
    if counts["v"] == 0:
        raise FileFormatError(f"{str(path)!r}: no vertex ('v') lines: not an OBJ mesh")
    if counts["f"] == 0:
        raise FileFormatError(f"{str(path)!r}: no face ('f') lines: Mitsuba renders triangles, not points")


def _obj_error(path: Path, line: int, text: bytes, problem: str) -> None:
    shown = text.decode("ascii", errors="backslashreplace").rstrip("\r\n")
    if len(shown) > 60:
        shown = shown[:60] + "..."
    raise FileFormatError(f"{str(path)!r}: line {line} ({shown!r}) {problem}")


# Byte classes of OBJ text (bytes.translate maps a block to them at C speed); 0: not text.
_DIGIT, _SIGN, _POINT, _MARK, _BLANK, _NEWLINE, _SLASH, _OTHER = range(1, 9)


def _obj_classes() -> bytes:
    table = bytearray(256)
    for byte in range(0x20, 0x7F):
        table[byte] = _OTHER
    for chars, code in (
        (b"0123456789", _DIGIT),
        (b"+-", _SIGN),
        (b".", _POINT),
        (b"eE", _MARK),
        (b" \t\r", _BLANK),
        (b"\n", _NEWLINE),
        (b"/", _SLASH),
    ):
        for byte in chars:
            table[byte] = code
    return bytes(table)


_OBJ_CLASSES = _obj_classes()
_OBJ_NAMES = (b"o", b"g", b"s", b"l", b"p", b"mg", b"vp", b"usemtl", b"mtllib")


def _check_obj_lines(path: Path, data: bytes, line0: int, counts: dict[str, int]) -> int:
    """Check the complete lines ``data`` (ending in a newline) that follow line ``line0``;
    add their ``v`` and ``f`` statements to ``counts``; return their number.

    Vectorised over the block: the bytes are mapped to classes, the lines found from the
    newlines, and every check is either a reduction per line or a look at the few positions of
    signs, points and exponent marks."""
    n = len(data)
    c = np.frombuffer(bytearray(data.translate(_OBJ_CLASSES) + b"\n\n\n".translate(_OBJ_CLASSES)), dtype=np.uint8)
    a = np.frombuffer(data + b"\n\n\n", dtype=np.uint8)  # padded: keywords are read 2 bytes ahead
    ends = np.flatnonzero(c[:n] == _NEWLINE)
    starts = np.concatenate(([0], ends[:-1] + 1))

    def line_of(pos: np.ndarray) -> np.ndarray:
        return np.searchsorted(ends, pos)

    def fail(i: int, problem: str) -> None:
        _obj_error(path, line0 + int(i) + 1, data[starts[i] : ends[i]], problem)

    if (c[:n] == 0).any():
        pos = int(np.argmax(c[:n] == 0))
        fail(line_of(pos), f"holds the byte 0x{data[pos]:02x}: an OBJ file is ASCII text")
    long_lines = np.flatnonzero(ends - starts > _OBJ_MAX_LINE)
    if len(long_lines):
        fail(long_lines[0], f"is longer than {_OBJ_MAX_LINE} characters (Mitsuba's limit)")
    # First non-blank character of every line (Mitsuba skips spaces, tabs and carriage returns).
    k = starts.copy()
    indented = np.flatnonzero(c[k] == _BLANK)
    while len(indented):
        k[indented] += 1
        indented = indented[c[k[indented]] == _BLANK]
    c0, c1 = a[k], a[k + 1]
    after1, after2 = c[k + 1] == _BLANK, c[k + 2] == _BLANK  # a space, a tab (or a carriage return)
    empty = (k >= ends) | (c0 == ord("#"))
    is_v = (c0 == ord("v")) & after1
    is_vn = (c0 == ord("v")) & (c1 == ord("n")) & after2
    is_vt = (c0 == ord("v")) & (c1 == ord("t")) & after2
    is_f = (c0 == ord("f")) & after1
    numeric = is_v | is_vn | is_vt
    for i in np.flatnonzero(~(empty | numeric | is_f)):
        word = data[k[i] : ends[i]].split(None, 1)[0] if k[i] < ends[i] else b""
        if word not in _OBJ_NAMES:
            fail(i, "is not an OBJ statement that Mitsuba reads (v, vn, vt, f) or skips (o, g, s, usemtl, ...)")
    # Blank out the keywords, so that what is left of a statement line is its arguments.
    c[k[numeric | is_f]] = _BLANK
    c[k[is_vn | is_vt] + 1] = _BLANK
    b = c[:n]
    blank = (b == _BLANK) | (b == _NEWLINE)
    starts_token = np.empty(n, dtype=bool)
    starts_token[0] = not blank[0]
    np.greater(blank[:-1], blank[1:], out=starts_token[1:])  # blank, then not blank
    tokens = np.add.reduceat(starts_token, starts, dtype=np.int32)
    # A numeric argument holds digits, signs, points and exponent marks; a face index digits and slashes.
    not_number = np.logical_or.reduceat((b - np.uint8(1)) > np.uint8(_NEWLINE - 1), starts)
    not_face = np.logical_or.reduceat(~(blank | (b == _DIGIT) | (b == _SLASH)), starts)
    token_first = np.flatnonzero(starts_token)
    bad_face_start = token_first[c[token_first] != _DIGIT]  # a reference starts with its vertex index
    not_face[line_of(bad_face_start)] = True
    misplaced = _misplaced_in_number(c, b, token_first)
    not_number[line_of(misplaced)] = True
    for mask, need, what in (
        (is_v, 3, "a vertex ('v') needs 3 numbers"),
        (is_vn, 3, "a normal ('vn') needs 3 numbers"),
        (is_vt, 2, "a texture coordinate ('vt') needs 2 numbers"),
    ):
        wrong = mask & (not_number | (tokens < need))
        if wrong.any():
            fail(np.argmax(wrong), f"does not parse: {what}, and nothing else")
    wrong = is_f & (not_face | (tokens < 3))
    if wrong.any():
        i = int(np.argmax(wrong))
        negative = b"-" in data[k[i] : ends[i]]
        fail(
            i,
            "uses negative (relative) vertex indices, which Mitsuba does not read"
            if negative
            else "does not parse: a face ('f') needs 3 or more vertex references of unsigned indices "
            "(i, i/j, i//k, i/j/k)",
        )
    counts["v"] += int(is_v.sum())
    counts["f"] += int(is_f.sum())
    return len(ends)


def _misplaced_in_number(c: np.ndarray, b: np.ndarray, token_first: np.ndarray) -> np.ndarray:
    """Positions of the bytes that break the syntax of a decimal number
    (``[+-]digits[.digits][(e|E)[+-]digits]``, either side of the point may be empty but not
    both) within their blank-separated token: a sign elsewhere than first or after the exponent
    mark, or not followed by the mantissa; a lone point; a mark without a mantissa before it or
    an exponent after it; a second point, a point in the exponent, a second mark.

    ``c`` holds the byte classes of the block (padded by 3 bytes past ``b``, its first ``n``);
    ``token_first`` the positions where tokens start. Positions in lines that are not numeric
    statements are harmless: only the lines' verdicts for numeric statements are used."""
    bad = []
    signs = np.flatnonzero(b == _SIGN)
    before = c[signs - 1]  # at position 0, the padding's newline
    ok_before = (before == _BLANK) | (before == _NEWLINE) | (before == _MARK)
    after = c[signs + 1]
    bad.append(signs[~ok_before | ~((after == _DIGIT) | (after == _POINT))])
    points = np.flatnonzero(b == _POINT)
    bad.append(points[(c[points - 1] != _DIGIT) & (c[points + 1] != _DIGIT)])
    marks = np.flatnonzero(b == _MARK)
    before, after, after2 = c[marks - 1], c[marks + 1], c[marks + 2]
    ok = ((before == _DIGIT) | (before == _POINT)) & ((after == _DIGIT) | ((after == _SIGN) & (after2 == _DIGIT)))
    bad.append(marks[~ok])
    # Within one token, a point may follow neither a point nor a mark, and a mark no mark.
    both = np.concatenate((points, marks))
    order = np.argsort(both, kind="stable")
    pos = both[order]
    is_mark = order >= len(points)
    token = np.searchsorted(token_first, pos, side="right")
    again = (token[1:] == token[:-1]) & (~is_mark[1:] | is_mark[:-1])
    bad.append(pos[1:][again])
    return np.concatenate(bad)


def _check_ply(path: Path, size: int) -> None:
    with path.open("rb") as fh:
        head = fh.read(_PLY_MAX_HEADER)

    def fail(problem: str) -> None:
        raise FileFormatError(f"{str(path)!r}: {problem}")

    first = head.split(b"\n", 1)[0].rstrip(b"\r")
    if first != b"ply":
        fail("does not start with the line 'ply': not a PLY file")
    end = -1
    for marker in (b"\nend_header\n", b"\nend_header\r\n"):
        at = head.find(marker)
        if at >= 0 and (end < 0 or at < end):
            end, header_bytes = at, at + len(marker)
    if end < 0:
        fail(f"no 'end_header' line within the first {_PLY_MAX_HEADER // 1024} KiB: not a PLY header")
    try:
        lines = head[:end].decode("ascii").splitlines()
    except UnicodeDecodeError:
        fail("the header is not ASCII text")
    fmt = None
    elements: list[dict] = []
    for number, line in enumerate(lines[1:], start=2):
        words = line.split()
        where = f"header line {number} ({line[:60]!r})"
        if not words or words[0] in ("comment", "obj_info"):
            continue
        if words[0] == "format":
            if fmt is not None or len(words) != 3 or words[2] != "1.0":
                fail(f"{where}: needs one 'format <ascii|binary_little_endian|binary_big_endian> 1.0' line")
            if words[1] not in ("ascii", "binary_little_endian", "binary_big_endian"):
                fail(f"{where}: unknown format {words[1]!r}")
            fmt = words[1]
        elif words[0] == "element":
            if len(words) != 3 or not words[2].isdigit():
                fail(f"{where}: needs 'element <name> <count>' with a non-negative integer count")
            elements.append({"name": words[1], "count": int(words[2]), "bytes": 0, "props": {}})
        elif words[0] == "property":
            if not elements:
                fail(f"{where}: a property before any element")
            types = words[2:4] if words[1:2] == ["list"] else words[1:2]
            if len(words) != (5 if words[1:2] == ["list"] else 3) or any(t not in _PLY_TYPES for t in types):
                fail(
                    f"{where}: needs 'property <type> <name>' or 'property list <type> <type> <name>' "
                    f"of the types {sorted(_PLY_TYPES)}"
                )
            el = elements[-1]
            el["props"][words[-1]] = types
            # A list is read as a triangle: its count and 3 indices.
            el["bytes"] += _PLY_TYPES[types[0]] + (3 * _PLY_TYPES[types[1]] if len(types) == 2 else 0)
        else:
            fail(f"{where}: not a PLY header statement (format, element, property, comment)")
    if fmt is None:
        fail("no 'format' line in the header")
    by_name = {el["name"]: el for el in elements}
    vertex, face = by_name.get("vertex"), by_name.get("face")
    if vertex is None or vertex["count"] == 0 or not {"x", "y", "z"} <= set(vertex["props"]):
        fail("needs a 'vertex' element of at least one vertex with properties x, y and z")
    lists = [name for name, types in (face or {"props": {}})["props"].items() if len(types) == 2]
    if face is None or face["count"] == 0 or not {"vertex_indices", "vertex_index"} & set(lists):
        fail("needs a 'face' element of at least one face with a list property 'vertex_indices'")
    if fmt != "ascii":
        need = sum(el["count"] * el["bytes"] for el in elements)
        have = size - header_bytes
        if have < need:
            fail(
                f"holds {have} bytes after its header, but its elements need at least {need} "
                "(with triangular faces): the file is truncated"
            )


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
