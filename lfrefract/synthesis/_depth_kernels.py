"""Numba kernels of the depth-aware synthesis: the plane sweep's photo-consistency and the render at depth.

Everything here works on plain arrays: captured rays in the water (camera frame, metres, from
their point on the port's water-side face), their values, and the output pinhole's intrinsics.
:mod:`lfrefract.synthesis.depth_aware` prepares the inputs and documents the method.

A ray *lands* in output pixel ``p`` at depth ``z`` when the point where it crosses the camera-frame
plane ``Z = z`` projects (pinhole ``K``, centre at the main-lens centre) into ``p``'s square: the
ray then sees the scene point on ``p``'s line of sight at depth ``z`` (within the pixel).

Within a pixel the rays land at different sub-pixel offsets ``(du, dv)`` and so see different
points of the scene's texture even at the true depth. Each pixel therefore fits its rays' values
with a plane in the offsets, ``value = b0 + b1 du + b2 dv`` per channel (least squares, a small
ridge on the slopes): the *residual* variance is the photo-consistency (zero at the true depth for
a texture linear within the pixel, whatever the rays' spread), and ``b0`` is the value at the pixel
centre, unbiased by where in the pixel the rays happen to land.

Rays are split by the quadrant of the main-lens aperture they pass through (``quadrant`` 0-3:
``(x > 0) + 2 (y > 0)``). Each pixel keeps per quadrant the moments of that fit (:data:`N_GEOMETRY`
geometric sums, the sum of squared values, and three sums per channel); a *subset* of quadrants (a
bit mask) adds them. The consistency of a pixel at a depth is the residual variance of the whole
aperture's rays or, occlusion-aware, the least among the whole aperture and its four halves (an
occluder hides part of the aperture from a point; the other half still sees it).
"""

from __future__ import annotations

import numba
import numpy as np

#: Quadrant subsets, as bit masks over the quadrants 0-3 (bit q = quadrant q): the whole aperture,
#: then its halves y <= 0, y > 0, x <= 0, x > 0.
SUBSETS = (0b1111, 0b0011, 0b1100, 0b0101, 0b1010)

#: Geometric moments per quadrant: n, sum du, sum dv, sum du^2, sum du dv, sum dv^2; then the sum
#: of squared values (all channels); then per channel sum v, sum v du, sum v dv.
N_GEOMETRY = 6

#: Ridge on the fitted slopes, as a share of the ray count (offsets span one pixel, so
#: ``sum du^2`` is about n / 12): keeps the fit defined when the rays bunch at one offset.
SLOPE_RIDGE = 1e-3

#: Weight of the per-pixel fit's residual variance added to the comparison's cost: the fit is the
#: sharper test where a pixel's rays come from several microlenses, the comparison where they come
#: from one. Measured on tiny-2x chessboards outside the exact coverage (port 40 mm, 26.8 deg): board
#: pixels more than 5 % off in depth at 0.6 m 39-42 % with weight 1, 24-26 % with 3, 19-20 % with 10;
#: 0 (the comparison alone) 71-73 %.
FIT_WEIGHT = 10.0

#: An aperture half stands in for the whole aperture only where its variance is below this share of
#: the whole's: an occluder makes the whole aperture's rays disagree many times over, while at a mere
#: texture edge a half is only a little more consistent and would shift the edge towards its side.
HALF_RATIO = 0.25


def moments_per_quadrant(channels: int) -> int:
    """Accumulated numbers per quadrant of a pixel for ``channels`` channels."""
    return N_GEOMETRY + 1 + 3 * channels


@numba.njit(cache=True, inline="always")
def _landing(ox, oy, oz, dx, dy, dz, z, fx, cx, cy, width, height):
    """Where the ray crosses the plane Z = z: (flat pixel index, du, dv); index -1 outside (or behind)."""
    t = (z - oz) / dz
    if t <= 0.0:
        return -1, 0.0, 0.0
    u = fx * (ox + t * dx) / z + cx
    v = fx * (oy + t * dy) / z + cy
    iu = int(np.floor(u + 0.5))
    iv = int(np.floor(v + 0.5))
    if iu < 0 or iv < 0 or iu >= width or iv >= height:
        return -1, 0.0, 0.0
    return iv * width + iu, u - iu, v - iv


@numba.njit(cache=True, inline="always")
def _add(acc, p, q, du, dv, values, i, channels):
    acc[p, q, 0] += 1.0
    acc[p, q, 1] += du
    acc[p, q, 2] += dv
    acc[p, q, 3] += du * du
    acc[p, q, 4] += du * dv
    acc[p, q, 5] += dv * dv
    sq = 0.0
    for c in range(channels):
        val = values[i, c]
        base = N_GEOMETRY + 1 + 3 * c
        acc[p, q, base] += val
        acc[p, q, base + 1] += val * du
        acc[p, q, base + 2] += val * dv
        sq += val * val
    acc[p, q, N_GEOMETRY] += sq


@numba.njit(cache=True)
def _fit(acc, p, mask, channels, centre):
    """Fit the subset ``mask`` of pixel ``p``: (ray count, residual variance per channel); writes
    the fitted values at the pixel centre into ``centre`` (C,). Variance inf if under 4 rays."""
    m = np.zeros(N_GEOMETRY + 1 + 3 * channels)
    for q in range(4):
        if (mask >> q) & 1:
            for j in range(m.shape[0]):
                m[j] += acc[p, q, j]
    n = m[0]
    if n < 4.0:
        return n, np.inf
    ridge = SLOPE_RIDGE * n
    # Normal matrix [[n, sx, sy], [sx, sxx + r, sxy], [sy, sxy, syy + r]], inverted by cofactors.
    a, b, c_, d, e, f = n, m[1], m[2], m[3] + ridge, m[4], m[5] + ridge
    c00 = d * f - e * e
    c01 = c_ * e - b * f
    c02 = b * e - c_ * d
    det = a * c00 + b * c01 + c_ * c02
    if not det > 0.0:
        return n, np.inf
    c11 = a * f - c_ * c_
    c12 = b * c_ - a * e
    c22 = a * d - b * b
    explained = 0.0
    for c in range(channels):
        base = N_GEOMETRY + 1 + 3 * c
        r0, r1, r2 = m[base], m[base + 1], m[base + 2]
        b0 = (c00 * r0 + c01 * r1 + c02 * r2) / det
        b1 = (c01 * r0 + c11 * r1 + c12 * r2) / det
        b2 = (c02 * r0 + c12 * r1 + c22 * r2) / det
        centre[c] = b0
        explained += b0 * r0 + b1 * r1 + b2 * r2
    rss = max(m[N_GEOMETRY] - explained, 0.0)
    return n, rss / ((n - 3.0) * channels)


@numba.njit(cache=True)
def _best_subset(acc, p, channels, min_rays, occlusion_aware, centre):
    """The subset of quadrants of pixel ``p`` with the least residual variance:
    (variance, ray count); its centre values in ``centre``. (inf, 0) if none has ``min_rays``."""
    best = np.inf
    best_score = np.inf
    best_n = 0.0
    trial = np.empty(channels)
    n_subsets = len(SUBSETS) if occlusion_aware else 1
    for s in range(n_subsets):
        n, var = _fit(acc, p, SUBSETS[s], channels, trial)
        score = var if s == 0 else var / HALF_RATIO
        if n < min_rays or not score < best_score:
            continue
        best = var
        best_score = score
        best_n = n
        centre[:] = trial
    return best, best_n


@numba.njit(cache=True, inline="always")
def _bilinear(image, u, v, out):
    """``image`` (H, W, C) at continuous pixel ``(u, v)`` into ``out``; False if a neighbour is NaN or off the image."""
    height, width, channels = image.shape
    u0 = int(np.floor(u))
    v0 = int(np.floor(v))
    if u0 < 0 or v0 < 0 or u0 + 1 >= width or v0 + 1 >= height:
        return False
    fu = u - u0
    fv = v - v0
    for c in range(channels):
        val = (1.0 - fv) * ((1.0 - fu) * image[v0, u0, c] + fu * image[v0, u0 + 1, c]) + fv * (
            (1.0 - fu) * image[v0 + 1, u0, c] + fu * image[v0 + 1, u0 + 1, c]
        )
        if not np.isfinite(val):
            return False
        out[c] = val
    return True


@numba.njit(cache=True, parallel=True)
def sweep_cost(origins, directions, values, quadrant, depths_m, fx, cx, cy, width, height, min_rays, occlusion_aware):
    """Photo-consistency of every output pixel at every depth plane ("refocus and compare").

    Per plane: the *refocused image* is each pixel's fitted centre value over all the rays that
    land in it (the plane fit of the module docstring, every quadrant together); then every ray is
    compared with the refocused image interpolated (bilinearly) at its exact landing point, and the
    cost of a pixel is the mean squared difference per channel of its rays, of the best subset of
    quadrants, plus :data:`FIT_WEIGHT` times the residual variance of the pixel's own plane fit. At
    the true depth each ray agrees with the sharp image of the plane; at another it sees a point
    shifted by its aperture position's parallax, which the blurred refocused image does not hold.
    (The per-pixel fit alone can absorb that parallax where the rays of a pixel come from a single
    microlens, whose landing offset grows with its aperture position: the comparison with the image
    made from all rays cannot.)

    Parameters
    ----------
    origins, directions : float32 (N, 3)
        Captured rays in the water, camera frame (directions with dz > 0).
    values : float32 (N, C)
        What each ray recorded (radiance in the water).
    quadrant : int8 (N,)
        Aperture quadrant of each ray.
    depths_m : float64 (D,)
        The planes' camera-frame z.
    fx, cx, cy : float
        Output pinhole intrinsics (square pixels).
    width, height : int
        Output size.
    min_rays : int
        Fewest rays a subset needs.
    occlusion_aware : bool
        Least cost over the whole aperture and its halves (else the whole aperture only).

    Returns
    -------
    cost : float32 (D, height, width)
        Mean squared difference per channel of the best subset; NaN where no subset has ``min_rays``.
    """
    n_rays = origins.shape[0]
    channels = values.shape[1]
    n_pix = width * height
    n_subsets = len(SUBSETS) if occlusion_aware else 1
    cost = np.empty((depths_m.shape[0], height, width), dtype=np.float32)
    for k in numba.prange(depths_m.shape[0]):
        z = depths_m[k]
        acc = np.zeros((n_pix, 1, N_GEOMETRY + 1 + 3 * channels))
        for i in range(n_rays):
            p, du, dv = _landing(
                origins[i, 0], origins[i, 1], origins[i, 2], directions[i, 0], directions[i, 1], directions[i, 2],
                z, fx, cx, cy, width, height,
            )  # fmt: skip
            if p >= 0:
                _add(acc, p, 0, du, dv, values, i, channels)
        refocused = np.full((height, width, channels), np.nan)
        fit_var = np.zeros(n_pix)
        centre = np.empty(channels)
        for p in range(n_pix):
            _, var = _fit(acc, p, 1, channels, centre)
            if np.isfinite(var):
                refocused[p // width, p % width, :] = centre
                fit_var[p] = var
        residual = np.zeros((n_pix, 4, 2))
        predicted = np.empty(channels)
        for i in range(n_rays):
            p, du, dv = _landing(
                origins[i, 0], origins[i, 1], origins[i, 2], directions[i, 0], directions[i, 1], directions[i, 2],
                z, fx, cx, cy, width, height,
            )  # fmt: skip
            if p < 0 or not _bilinear(refocused, p % width + du, p // width + dv, predicted):
                continue
            sq = 0.0
            for c in range(channels):
                sq += (values[i, c] - predicted[c]) ** 2
            q = quadrant[i]
            residual[p, q, 0] += 1.0
            residual[p, q, 1] += sq
        for p in range(n_pix):
            best = np.inf
            best_score = np.inf
            for s in range(n_subsets):
                mask = SUBSETS[s]
                n = 0.0
                total = 0.0
                for q in range(4):
                    if (mask >> q) & 1:
                        n += residual[p, q, 0]
                        total += residual[p, q, 1]
                if n < min_rays or n == 0:
                    continue
                score = total / (n * channels) if s == 0 else total / (n * channels * HALF_RATIO)
                if score < best_score:
                    best_score = score
                    best = total / (n * channels)
            cost[k, p // width, p % width] = best + FIT_WEIGHT * fit_var[p] if np.isfinite(best) else np.nan
    return cost


@numba.njit(cache=True, parallel=True)
def render_at_depth(
    origins,
    directions,
    values,
    quadrant,
    depths_m,
    depth_map,
    plane_of,
    fx,
    cx,
    cy,
    min_rays,
    occlusion_aware,
    n_chunks,
):
    """The value at each output pixel's centre, fitted to the consistent rays that land in it at its depth.

    A ray belongs to the first pixel, from near to far, at whose depth it lands in that pixel: for
    each pair of neighbouring planes the ray's landing pixels on both are the candidates, and a
    candidate whose depth lies between those planes takes the ray if the ray lands in it at
    exactly that depth.

    Parameters
    ----------
    origins, directions, values, quadrant, depths_m, fx, cx, cy, min_rays, occlusion_aware
        As :func:`sweep_cost`.
    depth_map : float64 (height, width)
        Camera-frame z of each pixel's surface; NaN for none.
    plane_of : int64 (height, width)
        Index of the plane interval ``[depths_m[j], depths_m[j + 1]]`` holding the pixel's depth;
        -1 for none.
    n_chunks : int
        Blocks of rays, each with its own accumulators (one per thread: :func:`numba.get_num_threads`).

    Returns
    -------
    image : float32 (height, width, C)
        The best subset's fitted value at the pixel centre (NaN where no subset has ``min_rays``).
    used : int32 (height, width)
        Rays in that subset (0 where none).
    """
    height, width = depth_map.shape
    n_rays = origins.shape[0]
    channels = values.shape[1]
    n_pix = width * height
    n_planes = depths_m.shape[0]
    acc = np.zeros((n_chunks, n_pix, 4, N_GEOMETRY + 1 + 3 * channels))
    bounds = np.linspace(0, n_rays, n_chunks + 1).astype(np.int64)
    for chunk in numba.prange(n_chunks):
        for i in range(bounds[chunk], bounds[chunk + 1]):
            ox, oy, oz = origins[i, 0], origins[i, 1], origins[i, 2]
            dx, dy, dz = directions[i, 0], directions[i, 1], directions[i, 2]
            previous, _, _ = _landing(ox, oy, oz, dx, dy, dz, depths_m[0], fx, cx, cy, width, height)
            for j in range(n_planes - 1):
                following, _, _ = _landing(ox, oy, oz, dx, dy, dz, depths_m[j + 1], fx, cx, cy, width, height)
                hit = -1
                du = dv = 0.0
                for candidate in (previous, following):
                    if candidate < 0 or hit >= 0:
                        continue
                    cv, cu = candidate // width, candidate % width
                    if plane_of[cv, cu] != j:
                        continue
                    p, du, dv = _landing(ox, oy, oz, dx, dy, dz, depth_map[cv, cu], fx, cx, cy, width, height)
                    if p == candidate:
                        hit = candidate
                previous = following
                if hit >= 0:
                    _add(acc[chunk], hit, quadrant[i], du, dv, values, i, channels)
                    break
    total = acc[0]
    for chunk in range(1, n_chunks):
        total += acc[chunk]
    image = np.full((height, width, channels), np.nan, dtype=np.float32)
    used = np.zeros((height, width), dtype=np.int32)
    for p in numba.prange(n_pix):
        centre = np.empty(channels)
        var, n = _best_subset(total, p, channels, min_rays, occlusion_aware, centre)
        if not np.isfinite(var):
            continue
        for c in range(channels):
            image[p // width, p % width, c] = centre[c]
        used[p // width, p % width] = int(n)
    return image, used
