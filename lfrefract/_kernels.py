"""Numba kernels of the refraction-free synthesis: candidate search and the sparse gather.

Everything here works on plain arrays and scalars in the camera frame (metres) and raw-pixel
coordinates; :mod:`lfrefract.synthesis` prepares the inputs and documents the method.
"""

from __future__ import annotations

import numba
import numpy as np

#: Distances below this (metres) count as this, so a candidate exactly on the necessary ray gets a
#: finite, dominant weight 1 / D_FLOOR instead of a division by zero.
D_FLOOR_M = 1e-9


@numba.njit(cache=True, parallel=True)
def build_rows(
    points,  # (n_samples, 3) necessary air ray: point on the air-side face (D is measured from it)
    aim_points,  # (n_samples, 3) point the candidate pixels are predicted from (= points when covered)
    dirs,  # (n_samples, 3) necessary air ray: unit direction, outwards
    usable,  # (n_samples,) bool: the necessary ray reached the air side
    lens0,  # (n_samples, 2) int64: lattice index of the lens nearest the ray's MLA hit
    lens_offsets,  # (n_off, 2) int64: candidate lenses relative to lens0
    samples_per_pixel,
    k,
    window,
    lam,
    cam,  # float64 (f, f', f_mla, pixel pitch, cu, cv, usable aperture radius^2), see synthesis
    lattice,  # float64 (a1x, a1y, a2x, a2y, off_x, off_y): lens (i, j) at off + i a1 + j a2 (image plane)
    normal,  # (3,) port normal
    plane_d,  # air-side face offset
    width,
    height,
    out_index,  # (n_pixels, samples_per_pixel * k) int32, filled
    out_weight,  # (n_pixels, samples_per_pixel * k) float32, filled
    out_count,  # (n_pixels,) int32, filled
):
    """For every output pixel: per sub-sample the k candidates of smallest D, weights 1/D
    (normalised per sub-sample), averaged over sub-samples and merged by raw pixel."""
    f, f_prime, f_mla, pitch, cu, cv, r_ok2 = cam[0], cam[1], cam[2], cam[3], cam[4], cam[5], cam[6]
    a1x, a1y, a2x, a2y, off_x, off_y = lattice[0], lattice[1], lattice[2], lattice[3], lattice[4], lattice[5]
    nx, ny, nz = normal[0], normal[1], normal[2]
    n_pixels = out_count.shape[0]
    n_off = lens_offsets.shape[0]
    g = 1.0 + f_prime / f_mla
    for p in numba.prange(n_pixels):
        idx_buf = np.empty(samples_per_pixel * k, dtype=np.int64)
        w_buf = np.empty(samples_per_pixel * k, dtype=np.float64)
        best_d = np.empty(k, dtype=np.float64)
        best_i = np.empty(k, dtype=np.int64)
        n_buf = 0
        n_used_samples = 0
        for q in range(samples_per_pixel):
            s = p * samples_per_pixel + q
            if not usable[s]:
                continue
            px, py, pz = points[s, 0], points[s, 1], points[s, 2]
            qx, qy = aim_points[s, 0], aim_points[s, 1]
            rx, ry, rz = dirs[s, 0], dirs[s, 1], dirs[s, 2]
            beta = f_prime / f_mla + pz * (1.0 / f_mla - f_prime / (f_mla * f))
            for j in range(k):
                best_d[j] = np.inf
                best_i[j] = -1
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
                for dv in range(-window, window + 1):
                    v = v0 + dv
                    if v < 0 or v >= height:
                        continue
                    for du in range(-window, window + 1):
                        u = u0 + du
                        if u < 0 or u >= width:
                            continue
                        xi = (u - cu) * pitch
                        eta = (v - cv) * pitch
                        sin_x = (xi - c_xi) / f_mla  # slope behind the main lens, camera frame
                        sin_y = (eta - c_eta) / f_mla
                        hx = cx + sin_x * f_prime
                        hy = cy + sin_y * f_prime
                        # Inside the (shrunk) aperture means inside this lens's micro-image disc,
                        # which lies inside the lens's own cell (the camera's f-numbers are
                        # validated to match), so the pixel belongs to this lens.
                        if hx * hx + hy * hy > r_ok2:
                            continue
                        dx = sin_x - hx / f
                        dy = sin_y - hy / f
                        norm = np.sqrt(dx * dx + dy * dy + 1.0)
                        dx, dy, dz = dx / norm, dy / norm, 1.0 / norm
                        denom = nx * dx + ny * dy + nz * dz
                        if denom <= 0.0:
                            continue
                        t = (plane_d - (nx * hx + ny * hy)) / denom
                        ex = hx + t * dx - px
                        ey = hy + t * dy - py
                        ez = t * dz - pz
                        dist = np.sqrt(ex * ex + ey * ey + ez * ez)
                        if lam != 0.0:
                            cos_a = min(1.0, max(-1.0, dx * rx + dy * ry + dz * rz))
                            dist += lam * np.arccos(cos_a)
                        if dist < best_d[k - 1]:
                            j = k - 1
                            while j > 0 and best_d[j - 1] > dist:
                                best_d[j] = best_d[j - 1]
                                best_i[j] = best_i[j - 1]
                                j -= 1
                            best_d[j] = dist
                            best_i[j] = v * width + u
            total = 0.0
            for j in range(k):
                if best_i[j] >= 0:
                    total += 1.0 / max(best_d[j], D_FLOOR_M)
            if total == 0.0:
                continue
            n_used_samples += 1
            for j in range(k):
                if best_i[j] >= 0:
                    idx_buf[n_buf] = best_i[j]
                    w_buf[n_buf] = (1.0 / max(best_d[j], D_FLOOR_M)) / total
                    n_buf += 1
        if n_buf == 0:
            out_count[p] = 0
            continue
        order = np.argsort(idx_buf[:n_buf], kind="mergesort")
        m = 0
        last = -1
        for r in range(n_buf):
            idx = idx_buf[order[r]]
            w = w_buf[order[r]] / n_used_samples
            if idx == last:
                out_weight[p, m - 1] += w
            else:
                out_index[p, m] = idx
                out_weight[p, m] = w
                last = idx
                m += 1
        out_count[p] = m


@numba.njit(cache=True, parallel=True)
def gather(indptr, indices, weights, gain, raw_flat, out):
    """``out[p, c] = gain[p] * sum_j weights[j] * raw_flat[indices[j], c]`` over row p's entries."""
    n_channels = raw_flat.shape[1]
    for p in numba.prange(out.shape[0]):
        acc = np.zeros(n_channels, dtype=np.float32)
        for j in range(indptr[p], indptr[p + 1]):
            w = weights[j]
            row = indices[j]
            for c in range(n_channels):
                acc[c] += w * raw_flat[row, c]
        for c in range(n_channels):
            out[p, c] = acc[c] * gain[p]
