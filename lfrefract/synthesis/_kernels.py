"""Numba kernels of the refraction-free synthesis: candidate search and the sparse gather.

Everything here works on plain arrays and scalars in the camera frame (metres) and raw-pixel
coordinates; :mod:`lfrefract.synthesis.warp_map` prepares the inputs and documents the method. The build
kernel is serial and releases the GIL: the caller runs blocks of output pixels on a thread pool.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

#: Distances below this (metres) count as this, so a candidate exactly on the necessary ray gets a
#: finite, dominant weight 1 / D_FLOOR instead of a division by zero.
D_FLOOR_M = 1e-9


class CameraScalars(NamedTuple):
    """The light-field camera as the candidate search sees it (camera frame, metres; raw pixels)."""

    f_m: float  #: main-lens focal length f
    f_prime_m: float  #: main lens to MLA distance f'
    f_mla_m: float  #: microlens focal length (the MLA-sensor gap)
    pixel_pitch_m: float  #: sensor pixel pitch
    cu_px: float  #: column of the optical axis on the sensor (pixel centres at integers)
    cv_px: float  #: row of the optical axis on the sensor
    usable_radius2_m2: float  #: square of the main-lens radius inside which pixels are used
    width_px: int  #: raw image width
    height_px: int  #: raw image height


class Lattice(NamedTuple):
    """The microlens lattice: lens (i, j) is centred at ``off + i a1 + j a2``, image plane, metres."""

    a1x_m: float
    a1y_m: float
    a2x_m: float
    a2y_m: float
    off_x_m: float
    off_y_m: float


class AirFace(NamedTuple):
    """The port's air-side face, ``n . x = d_m`` in the camera frame (unit normal ``n``)."""

    nx: float
    ny: float
    nz: float
    d_m: float


class RayModel(NamedTuple):
    """The camera's departure from its thin-lens rays (:class:`lfrefract.optics.ray_correction.RayCorrection`):
    a thin-lens ray through aperture point ``a`` with slopes ``t`` is the ray of slopes
    ``t' = s t (1 + k1 |t|^2 + k2 |t|^4)`` through ``(m a - d |t'|^2 t', 0)``. The identity
    ``(1, 1, 0, 0, 0)`` leaves every ray, to the last bit, as it is."""

    pupil_scale: float  #: m
    slope_scale: float  #: s
    k1: float
    k2: float
    pupil_drift_m: float  #: d, metres


#: The thin-lens camera's own rays.
THIN_LENS = RayModel(pupil_scale=1.0, slope_scale=1.0, k1=0.0, k2=0.0, pupil_drift_m=0.0)


class SearchQuery(NamedTuple):
    """What the analytic search looks for and where."""

    lens_offsets: np.ndarray  #: (n_off, 2) int64: candidate lenses relative to the nearest lens
    k: int  #: captured rays kept per necessary ray
    window: int  #: half-size of the pixel window searched under each candidate lens
    lam_m_per_rad: float  #: weight of the angle term of D
    sites: np.ndarray  #: (2, 2) bool: raw pixels (u, v) used only where sites[v % 2, u % 2] (CFA colour)


class NecessaryRays(NamedTuple):
    """The necessary air rays of one block of samples (camera frame, metres)."""

    points: np.ndarray  #: (n, 3) point on the air-side face (D is measured from it)
    #: (n, 3) the point at P's depth of the ray's thin-lens twin (or of its parallel through the
    #: nearest usable aperture point, outside the coverage): candidate pixels are predicted from it
    aim_points: np.ndarray
    dirs: np.ndarray  #: (n, 3) unit direction, outwards
    usable: np.ndarray  #: (n,) bool: the ray reached the air side and is searched analytically
    lens0: np.ndarray  #: (n, 2) int64: lattice index of the lens nearest the twin's MLA point


def angle_from_chord(chord):
    """Angle (rad) between unit vectors ``chord`` apart: ``2 arcsin(min(1, chord / 2))``.

    Well conditioned for small angles (unlike ``arccos`` of the dot product). Takes a scalar or
    an array; :func:`angle_from_chord_jit` is the same expression compiled for the kernels (the C
    library's arcsin there, numpy's here: they may differ in the last bit).
    """
    return 2.0 * np.arcsin(np.minimum(1.0, 0.5 * chord))


def sensor_to_plane_scale(z_m, f_m, f_prime_m, f_mla_m):
    """How far the chief ray of a pixel moves on the plane ``z = z_m`` per unit sensor offset.

    A pixel ``s`` (image plane, relative to its microlens centre) sends its ray through the
    microlens centre with slope ``-s / f_mla``; through the thin main lens it meets the plane
    ``z_m`` in front of it (metres, camera frame) displaced by ``beta * s`` with
    ``beta = f' / f_mla + z (1 / f_mla - f' / (f_mla f))``, i.e.
    ``beta = (z f' / f_mla) (1 / z + 1 / f' - 1 / f)``: zero where the plane is conjugate to the
    MLA through the main lens (thin-lens equation ``1 / z + 1 / f' = 1 / f``), where every pixel of
    a microlens sees the same point. Scalars or arrays; :func:`sensor_to_plane_scale_jit` is the
    compiled twin for the kernels.
    """
    return f_prime_m / f_mla_m + z_m * (1.0 / f_mla_m - f_prime_m / (f_mla_m * f_m))


angle_from_chord_jit = numba.njit(cache=True, inline="always")(angle_from_chord)
sensor_to_plane_scale_jit = numba.njit(cache=True, inline="always")(sensor_to_plane_scale)


@numba.njit(cache=True, inline="always")
def _model_slopes(dx, dy, model):
    """The camera's slopes of thin-lens slopes ``(dx, dy)`` (:class:`RayModel`), and the shift
    ``d |t'|^2 t'`` of its ray's crossing of z = 0 from the scaled aperture point."""
    r2 = dx * dx + dy * dy
    scale = model.slope_scale * (1.0 + model.k1 * r2 + model.k2 * r2 * r2)
    mx, my = scale * dx, scale * dy
    drift = model.pupil_drift_m * (mx * mx + my * my)
    return mx, my, drift * mx, drift * my


@numba.njit(cache=True, inline="always")
def _better(d_a, i_a, d_b, i_b):
    """Total order of candidates: smaller D first, ties broken by the smaller raw index, so the
    selection does not depend on the order candidates are visited in."""
    return d_a < d_b or (d_a == d_b and i_a < i_b)


@numba.njit(cache=True, nogil=True)
def _select_best(dist, index, n, k):
    """Reorder ``dist[:n]``, ``index[:n]`` in place so that the first ``min(n, k)`` are the best
    under :func:`_better` (in no particular order); quickselect."""
    lo, hi = 0, n - 1
    while lo < hi:
        mid = (lo + hi) // 2
        pd, pi = dist[mid], index[mid]
        i, j = lo, hi
        while i <= j:
            while _better(dist[i], index[i], pd, pi):
                i += 1
            while _better(pd, pi, dist[j], index[j]):
                j -= 1
            if i <= j:
                dist[i], dist[j] = dist[j], dist[i]
                index[i], index[j] = index[j], index[i]
                i += 1
                j -= 1
        # Now [lo, j] <= pivot <= [i, hi]; keep narrowing the side that holds position k - 1.
        if k - 1 <= j:
            hi = j
        elif k - 1 >= i:
            lo = i
        else:
            break


@numba.njit(cache=True, nogil=True)
def _sort_row(index, weight, first, stop):
    """Insertion-sort entries ``first:stop`` by raw index (rows are short)."""
    for r in range(first + 1, stop):
        idx, w = index[r], weight[r]
        j = r
        while j > first and index[j - 1] > idx:
            index[j] = index[j - 1]
            weight[j] = weight[j - 1]
            j -= 1
        index[j] = idx
        weight[j] = w


@numba.njit(cache=True, nogil=True)
def select_candidates(rays, query, camera, lattice, face, model, sel_index, sel_dist):
    """For every necessary ray (sample): the k captured rays of smallest D among the candidates of
    the analytic search, under the total order of :func:`_better`.

    Parameters
    ----------
    rays : NecessaryRays
        The samples; those not ``usable`` are skipped (their rows stay empty).
    query : SearchQuery
    camera : CameraScalars
    lattice : Lattice
    face : AirFace
    model : RayModel
        The captured rays are the thin-lens rays of the pixels searched, mapped by it
        (:data:`THIN_LENS`: as they are). Which pixels are searched is predicted on the thin-lens
        model, so ``rays`` must hold the thin-lens twins of the necessary rays in ``aim_points``
        and ``lens0`` (``points`` and ``dirs``, from which D is measured, are the rays themselves).
    sel_index : ndarray of int64, shape (n_samples, k)
        Filled: raw flat indices of the k best, -1 where fewer.
    sel_dist : ndarray of float64, shape (n_samples, k)
        Filled: their D, metres (inf where -1).
    """
    points, aim_points, dirs, usable, lens0 = rays.points, rays.aim_points, rays.dirs, rays.usable, rays.lens0
    lens_offsets, k, window, lam = query.lens_offsets, query.k, query.window, query.lam_m_per_rad
    sites = query.sites
    f, f_prime, f_mla, pitch = camera.f_m, camera.f_prime_m, camera.f_mla_m, camera.pixel_pitch_m
    cu, cv, r_ok2 = camera.cu_px, camera.cv_px, camera.usable_radius2_m2
    width, height = camera.width_px, camera.height_px
    a1x, a1y, a2x, a2y = lattice.a1x_m, lattice.a1y_m, lattice.a2x_m, lattice.a2y_m
    off_x, off_y = lattice.off_x_m, lattice.off_y_m
    nx, ny, nz, plane_d = face.nx, face.ny, face.nz, face.d_m
    n_samples = usable.shape[0]
    n_off = lens_offsets.shape[0]
    g = 1.0 + f_prime / f_mla
    # A captured ray leaves its pixel with slope sin = (xi - c) / f_mla towards lens centre c, meets
    # the main lens at h = c + sin f' and leaves it with slope sin - h / f = sin (1 - f'/f) - c / f:
    # under one lens the direction changes by `spread` per unit of sin (0 when the MLA sits in the
    # focal plane: then all rays of a lens are parallel and share one angle to the necessary ray).
    spread = 1.0 - f_prime / f
    step = pitch * f_prime / f_mla  # main-lens distance between neighbouring pixels' rays
    inv_step = 1.0 / step
    slope_step = pitch / f_mla  # slope change between neighbouring pixels under one lens
    side = 2 * window + 1
    cand_d = np.empty(n_off * side * side, dtype=np.float64)
    cand_i = np.empty(n_off * side * side, dtype=np.int64)
    sel_index[:] = -1
    sel_dist[:] = np.inf
    for s in range(n_samples):
        if not usable[s]:
            continue
        px, py, pz = points[s, 0], points[s, 1], points[s, 2]
        qx, qy = aim_points[s, 0], aim_points[s, 1]
        rx, ry, rz = dirs[s, 0], dirs[s, 1], dirs[s, 2]
        beta = sensor_to_plane_scale_jit(pz, f, f_prime, f_mla)
        n_cand = 0
        for o in range(n_off):
            ci = lens0[s, 0] + lens_offsets[o, 0]
            cj = lens0[s, 1] + lens_offsets[o, 1]
            c_xi = off_x + a1x * ci + a2x * cj
            c_eta = off_y + a1y * ci + a2y * cj
            cx, cy = -c_xi, -c_eta  # camera frame
            # Predicted sensor point: the pixel of this lens whose chief ray passes P (plane z = P_z).
            ax = cx * g + pz * (cx / f_mla - cx * g / f)
            ay = cy * g + pz * (cy / f_mla - cy * g / f)
            sx, sy = (ax - qx) / beta, (ay - qy) / beta
            u0 = int(np.floor(-sx / pitch + cu + 0.5))
            v0 = int(np.floor(-sy / pitch + cv + 0.5))
            # Main-lens point of pixel (u, v)'s ray: h = h0 + step * (u - u0, v - v0).
            sin0_x = ((u0 - cu) * pitch - c_xi) / f_mla
            sin0_y = ((v0 - cv) * pitch - c_eta) / f_mla
            h0x = cx + sin0_x * f_prime
            h0y = cy + sin0_y * f_prime
            # Direction (dx, dy, 1) of pixel (u0, v0)'s ray in front of the main lens; with
            # spread == 0 it is every pixel's of this lens, and so are its angle to the
            # necessary ray and 1 / (n . d) for the face intersection.
            dx0 = sin0_x * spread - cx / f
            dy0 = sin0_y * spread - cy / f
            # With spread == 0 the camera's slopes (a function of the thin-lens slopes) and the
            # shift of its rays' crossings are the lens's too.
            mdx0, mdy0, shift_x0, shift_y0 = _model_slopes(dx0, dy0, model)
            lens_angle = 0.0
            lens_inv_denom = 0.0
            if spread == 0.0:
                denom = nx * mdx0 + ny * mdy0 + nz
                if denom <= 0.0:
                    continue
                lens_inv_denom = 1.0 / denom
                if lam != 0.0:
                    norm = np.sqrt(mdx0 * mdx0 + mdy0 * mdy0 + 1.0)
                    ex, ey, ez = mdx0 / norm - rx, mdy0 / norm - ry, 1.0 / norm - rz
                    lens_angle = angle_from_chord_jit(np.sqrt(ex * ex + ey * ey + ez * ez))
            for dv in range(-window, window + 1):
                v = v0 + dv
                if v < 0 or v >= height:
                    continue
                hy = h0y + dv * step
                half2 = r_ok2 - hy * hy
                if half2 < 0.0:
                    continue
                # Columns whose main-lens point can lie inside the usable aperture (one pixel
                # of slack each side; the exact test below decides).
                half = np.sqrt(half2)
                du_lo = max(-window, int(np.floor((-half - h0x) * inv_step)) - 1)
                du_hi = min(window, int(np.ceil((half - h0x) * inv_step)) + 1)
                for du in range(du_lo, du_hi + 1):
                    u = u0 + du
                    if u < 0 or u >= width or not sites[v & 1, u & 1]:
                        continue
                    hx = h0x + du * step
                    # Inside the (shrunk) aperture means inside this lens's micro-image disc,
                    # which lies inside the lens's own cell (the camera's f-numbers are
                    # validated to match), so the pixel belongs to this lens.
                    if hx * hx + hy * hy > r_ok2:
                        continue
                    if spread == 0.0:
                        dx, dy, inv_denom = mdx0, mdy0, lens_inv_denom
                        shift_x, shift_y = shift_x0, shift_y0
                    else:
                        dx, dy, shift_x, shift_y = _model_slopes(
                            dx0 + du * slope_step * spread, dy0 + dv * slope_step * spread, model
                        )
                        denom = nx * dx + ny * dy + nz
                        if denom <= 0.0:
                            continue
                        inv_denom = 1.0 / denom
                    # The camera's ray crosses z = 0 at (ox, oy) and meets the face t later.
                    ox = model.pupil_scale * hx - shift_x
                    oy = model.pupil_scale * hy - shift_y
                    t = (plane_d - (nx * ox + ny * oy)) * inv_denom
                    ex = ox + t * dx - px
                    ey = oy + t * dy - py
                    ez = t - pz
                    dist = np.sqrt(ex * ex + ey * ey + ez * ez)
                    if lam != 0.0:
                        if spread == 0.0:
                            dist += lam * lens_angle
                        else:
                            norm = np.sqrt(dx * dx + dy * dy + 1.0)
                            ex, ey, ez = dx / norm - rx, dy / norm - ry, 1.0 / norm - rz
                            dist += lam * angle_from_chord_jit(np.sqrt(ex * ex + ey * ey + ez * ez))
                    cand_d[n_cand] = dist
                    cand_i[n_cand] = v * width + u
                    n_cand += 1
        if n_cand == 0:
            continue
        _select_best(cand_d, cand_i, n_cand, k)
        for j in range(min(n_cand, k)):
            sel_index[s, j] = cand_i[j]
            sel_dist[s, j] = cand_d[j]


@numba.njit(cache=True, nogil=True)
def merge_rows(sel_index, sel_dist, samples_per_pixel, out_index, out_weight, out_count):
    """Rows of the warp map from each sample's selected captured rays.

    Per sample the selected rays get weights 1/D (D floored at D_FLOOR_M) normalised to 1; the
    samples of a pixel that found any ray are averaged, entries of the same raw pixel merged, and
    the row ordered by raw index. ``sel_index`` (n_samples, k) holds -1 in unused slots.
    ``out_index`` / ``out_weight`` (n_pixels * samples_per_pixel * k,) receive the rows back to
    back, ``out_count`` (n_pixels,) their lengths; returns the number of entries written.
    """
    k = sel_index.shape[1]
    n_pixels = out_count.shape[0]
    cand_rows = np.empty(samples_per_pixel * k, dtype=np.int64)
    w_buf = np.empty(samples_per_pixel * k, dtype=np.float64)
    table_size = 1 << int(np.ceil(np.log2(2 * samples_per_pixel * k)))  # at most half full
    table_mask = table_size - 1
    table_key = np.full(table_size, -1, dtype=np.int64)
    table_slot = np.empty(table_size, dtype=np.int64)
    pos = 0
    for p in range(n_pixels):
        n_buf = 0
        n_used_samples = 0
        for q in range(samples_per_pixel):
            s = p * samples_per_pixel + q
            total = 0.0
            for j in range(k):
                if sel_index[s, j] >= 0:
                    total += 1.0 / max(sel_dist[s, j], D_FLOOR_M)
            if total == 0.0:
                continue
            n_used_samples += 1
            for j in range(k):
                if sel_index[s, j] >= 0:
                    cand_rows[n_buf] = sel_index[s, j]
                    w_buf[n_buf] = (1.0 / max(sel_dist[s, j], D_FLOOR_M)) / total
                    n_buf += 1
        # Merge the sub-samples' entries by raw pixel (open addressing on the raw index), then
        # order the row by raw index for the gather's memory access.
        m = 0
        for r in range(n_buf):
            idx = cand_rows[r]
            w = w_buf[r] / n_used_samples
            h = (idx * 2654435761) & table_mask
            while table_key[h] != -1 and table_key[h] != idx:
                h = (h + 1) & table_mask
            if table_key[h] == idx:
                out_weight[pos + table_slot[h]] += w
            else:
                table_key[h] = idx
                table_slot[h] = m
                out_index[pos + m] = idx
                out_weight[pos + m] = w
                m += 1
        for r in range(n_buf):  # clear the table for the next pixel
            h = (cand_rows[r] * 2654435761) & table_mask
            while table_key[h] != -1:
                table_key[h] = -1
                h = (h + 1) & table_mask
        _sort_row(out_index, out_weight, pos, pos + m)
        out_count[p] = m
        pos += m
    return pos


@numba.njit(cache=True, parallel=True)
def gather(chunks, indptr, indices, weights, gain, raw_flat, out):
    """``out[p, c] = gain[p] * sum_j weights[j] * raw_flat[indices[j], c]`` over row p's entries.

    ``chunks`` (n + 1,) bounds blocks of rows with about equal numbers of entries, one task each
    (rows differ a lot in length: empty outside the coverage). Within a row two accumulators take
    alternate entries, which halves the dependency chain of the additions.
    """
    n_channels = raw_flat.shape[1]
    for c in numba.prange(chunks.shape[0] - 1):
        for p in range(chunks[c], chunks[c + 1]):
            first, stop = indptr[p], indptr[p + 1]
            if n_channels == 3:  # the common case, without a per-pixel accumulator array
                a0 = a1 = a2 = b0 = b1 = b2 = np.float32(0.0)
                j = first
                while j + 1 < stop:
                    w, r = weights[j], indices[j]
                    v, q = weights[j + 1], indices[j + 1]
                    a0 += w * raw_flat[r, 0]
                    a1 += w * raw_flat[r, 1]
                    a2 += w * raw_flat[r, 2]
                    b0 += v * raw_flat[q, 0]
                    b1 += v * raw_flat[q, 1]
                    b2 += v * raw_flat[q, 2]
                    j += 2
                if j < stop:
                    w, r = weights[j], indices[j]
                    a0 += w * raw_flat[r, 0]
                    a1 += w * raw_flat[r, 1]
                    a2 += w * raw_flat[r, 2]
                out[p, 0] = (a0 + b0) * gain[p]
                out[p, 1] = (a1 + b1) * gain[p]
                out[p, 2] = (a2 + b2) * gain[p]
            else:
                for ch in range(n_channels):
                    acc = np.float32(0.0)
                    for j in range(first, stop):
                        acc += weights[j] * raw_flat[indices[j], ch]
                    out[p, ch] = acc * gain[p]
