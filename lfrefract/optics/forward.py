"""Forward projection through a flat port: the air-side ray from a centre of projection to a point in the water.

:meth:`FlatPort.trace_from_air` goes from a ray in the air to the water; this module goes the
other way round for a *point*: given a centre of projection ``C`` in the air (camera frame,
camera side of the port) and a point ``X`` in the water, it finds the unit direction ``r`` such
that the ray ``C + lambda r``, refracted by the port (air -> glass -> water, or air -> water for
``t = 0``), passes through ``X``. That is how a point is imaged by a pinhole behind the port:
``K (r / r_z)`` is its pixel.

Reduction to one dimension
--------------------------
Snell's law keeps every refracted ray in the plane of incidence, the plane spanned by the port
normal ``n`` and ``X - C``, and conserves ``p = n_i sin(theta_i)`` across the faces. In that plane
let ``a = d - n . C`` (gap from ``C`` to the air-side face, > 0), ``t`` the glass thickness,
``w = n . X - (d + t)`` (depth of ``X`` beyond the water-side face) and ``rho`` the distance of
``X`` from the normal line through ``C``. The ray reaches ``X`` iff the lateral distances it
covers in the media add up to ``rho``::

    F(p) = a tan(theta_air) + t tan(theta_glass) + w tan(theta_water) - rho = 0.

Each term grows with ``p`` and diverges as ``p`` approaches the smallest index ``n_min`` of the
media the ray crosses (a medium of positive thickness), so the root is unique and exists for
every ``X`` beyond the water-side face, whatever the indices: total internal reflection only
removes rays that could not have reached ``X`` anyway. The unknown used is
``s = tan(theta_min)``, the tangent of the ray's angle in that slowest-turning medium, in
``[0, inf)``; then ``p = n_min s / sqrt(1 + s^2)`` and, for every medium,
``tan(theta_i) = n_min s / sqrt(n_i^2 + (n_i^2 - n_min^2) s^2)``, free of cancellation even at
grazing angles (``p`` itself loses the angle's precision there). In ``s`` the terms of the
slowest media are linear and the others concave, so ``F`` is concave and increasing with
``F(0) = -rho``: Newton's method from the left never overshoots the root and converges
monotonically (quadratically near it). The bracket ``[rho / sum(h_i n_min / n_i), rho / H]``
(``h_i`` the media's thicknesses, ``H`` the total thickness of those with ``n_i = n_min``) holds
the root; a step that leaves it is replaced by bisection, so the iteration cannot diverge
(:func:`forward_project`).

For a single interface (``t = 0``) :func:`forward_project_quartic` solves the same problem in
closed form, as the quartic in the lateral position of the hit on the interface of Agrawal,
Ramalingam, Taguchi and Chari, "A theory of multi-layer flat refractive geometry", CVPR 2012.
It is a check of the iteration, not a faster path (its roots are eigenvalues of 4 x 4 matrices).

Points that cannot be seen get NaN rows: points on the camera side of the water-side face (in the
air or inside the glass), and points whose ray would meet a face at a cosine below
:data:`~lfrefract.optics.port.GRAZING_COS_MIN`, which :meth:`FlatPort.trace_from_air` treats as
missing it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lfrefract.errors import ParameterError
from lfrefract.optics.pinhole import PinholeCamera
from lfrefract.optics.port import GRAZING_COS_MIN, FlatPort
from lfrefract.validate import as_points, bounded_int, positive_float

__all__ = [
    "DEFAULT_MAX_ITERATIONS",
    "DEFAULT_TOLERANCE_M",
    "ForwardProjection",
    "forward_project",
    "forward_project_quartic",
    "project_through_port",
]

#: Default convergence threshold of :func:`forward_project`, metres: the largest accepted
#: lateral distance between ``X`` and the refracted ray where it crosses ``X``'s plane parallel to
#: the port. Double-precision round-off of the residual is a few 1e-16 m per metre of distance, so
#: this is reached for any geometry within the port's ranges short of grazing incidence.
DEFAULT_TOLERANCE_M = 1e-12

#: Default cap on the iterations of :func:`forward_project`. Newton's method converges in under ten
#: steps (quadratically, from the left); with bisection as the safeguard, 100 halvings would shrink
#: any bracket below double precision.
DEFAULT_MAX_ITERATIONS = 100


@dataclass(frozen=True)
class ForwardProjection:
    """Air-side rays from centres of projection to points in the water, camera frame, metres.

    Attributes
    ----------
    directions_cam : ndarray, shape (N, 3)
        Unit direction of the air-side ray leaving each centre, NaN where the point is not visible.
    entry_points_cam : ndarray, shape (N, 3)
        Where the ray meets the air-side face (``n . X = d``), NaN where not visible.
    exit_points_cam : ndarray, shape (N, 3)
        Where the refracted ray leaves the water-side face (``n . X = d + t``; equal to
        ``entry_points_cam`` for ``t = 0``), NaN where not visible.
    visible : ndarray of bool, shape (N,)
        The point lies beyond the water-side face and its ray meets every face at a cosine of at
        least :data:`~lfrefract.optics.port.GRAZING_COS_MIN`.
    residual_m : ndarray, shape (N,)
        The solver's final lateral residual ``|F|`` (see the module docstring), metres; NaN where
        not visible.
    iterations : int
        Iterations the solver ran (the slowest point's).
    """

    directions_cam: np.ndarray
    entry_points_cam: np.ndarray
    exit_points_cam: np.ndarray
    visible: np.ndarray
    residual_m: np.ndarray
    iterations: int


def _checked(port: FlatPort, centres_cam: np.ndarray, points_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``centres_cam`` broadcast to (N, 3) and ``points_cam`` (N, 3), validated."""
    if not isinstance(port, FlatPort):
        raise ParameterError(f"port must be a FlatPort, got {port!r}")
    x = as_points("points_cam", points_cam, 3)
    c = as_points("centres_cam", centres_cam, 3)
    if c.shape[0] == 1:
        c = np.broadcast_to(c, x.shape)
    elif c.shape != x.shape:
        raise ParameterError(
            f"centres_cam must have shape (3,) or the shape of points_cam {x.shape}, got {np.shape(centres_cam)}"
        )
    gap = port.distance_m - c @ port.normal
    if np.any(gap <= 0.0):
        bad = c[np.argmin(gap)]
        raise ParameterError(
            f"centres_cam must lie on the camera side of the port's air-side face (n . C < d = {port.distance_m!r} m), "
            f"got a centre {bad.tolist()} at n . C = {float(bad @ port.normal)!r} m"
        )
    return c, x


def _media(port: FlatPort, gap_air: np.ndarray, depth_water: np.ndarray) -> list[tuple[np.ndarray | float, float]]:
    """``(thickness, index)`` of each medium the ray crosses, from the camera outwards."""
    media: list[tuple[np.ndarray | float, float]] = [(gap_air, port.n_air)]
    if port.thickness_m > 0.0:
        media.append((port.thickness_m, port.n_glass))
    media.append((depth_water, port.n_water))
    return media


def _tangent(s: np.ndarray, n_i: float, n_min: float) -> np.ndarray:
    """``tan(theta_i)`` in a medium of index ``n_i`` for ``s = tan(theta)`` in one of index ``n_min``."""
    if n_i == n_min:
        return s
    return n_min * s / np.sqrt(n_i * n_i + (n_i * n_i - n_min * n_min) * s * s)


def forward_project(
    port: FlatPort,
    centres_cam: np.ndarray,
    points_cam: np.ndarray,
    *,
    tolerance_m: float = DEFAULT_TOLERANCE_M,
    max_iterations: int = DEFAULT_MAX_ITERATIONS,
) -> ForwardProjection:
    """Air-side rays from centres of projection through the port to points in the water.

    Solves the 1-D equation of the module docstring for all points at once by a safeguarded Newton
    iteration (Newton steps inside a bracket of the root, bisection when a step leaves it).

    Parameters
    ----------
    port : FlatPort
    centres_cam : array_like, shape (3,) or (N, 3)
        Centres of projection, camera frame, metres, on the camera side of the air-side face
        (``n . C < d``): one for all points or one per point.
    points_cam : array_like, shape (N, 3)
        Points, camera frame, metres.
    tolerance_m : float
        Convergence threshold on the lateral residual, metres, > 0 (see :data:`DEFAULT_TOLERANCE_M`).
        A point whose residual cannot fall below it (its root is pinned to the last bit of ``s``)
        stops there.
    max_iterations : int
        Cap on the iterations, 1 to 10000.

    Returns
    -------
    ForwardProjection
        Unit air-side directions (N, 3) and the face points; NaN rows where the point is not
        visible (on the camera side of the water-side face, or a ray too close to grazing).

    Raises
    ------
    ParameterError
        If ``port`` is not a FlatPort, an array has the wrong shape or a non-finite value, a
        centre is not on the camera side of the air-side face, or an option is out of range.
    """
    c, x = _checked(port, centres_cam, points_cam)
    tol = positive_float("tolerance_m", tolerance_m)
    max_iter = bounded_int("max_iterations", max_iterations, 1, 10_000)
    n = port.normal
    count = x.shape[0]
    gap_air = port.distance_m - c @ n
    rel = x - c
    along = rel @ n
    depth_water = along - gap_air - port.thickness_m
    lateral_vec = rel - along[:, None] * n
    rho = np.linalg.norm(lateral_vec, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        e = np.where(rho[:, None] > 0.0, lateral_vec / rho[:, None], 0.0)
    beyond = depth_water > 0.0
    media = _media(port, gap_air, np.where(beyond, depth_water, 1.0))
    n_min = min(index for _, index in media)
    slowest = sum((h for h, index in media if index == n_min), np.zeros(count))
    slope_at_zero = sum((h * (n_min / index) for h, index in media), np.zeros(count))

    def residual(s: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        value = -rho[rows]
        slope = np.zeros_like(s)
        for h, index in media:
            hh = h[rows] if isinstance(h, np.ndarray) else h
            value = value + hh * _tangent(s, index, n_min)
            q = index * index + (index * index - n_min * n_min) * s * s
            slope = slope + hh * n_min * index * index / (q * np.sqrt(q))
        return value, slope

    lo = rho / slope_at_zero  # F(lo) <= 0: the first Newton step from s = 0
    hi = rho / slowest  # F(hi) >= 0: the slowest media's linear terms alone reach rho there
    s = lo.copy()
    final = np.full(count, np.nan)
    active = np.flatnonzero(beyond)
    iterations = 0
    while active.size and iterations < max_iter:
        iterations += 1
        sa = s[active]
        value, slope = residual(sa, active)
        done = np.abs(value) <= tol
        final[active] = np.abs(value)
        below = value < 0.0
        lo[active] = np.where(below, np.maximum(lo[active], sa), lo[active])
        hi[active] = np.where(below, hi[active], np.minimum(hi[active], sa))
        step = sa - value / slope
        la, ha = lo[active], hi[active]
        outside = ~((step >= la) & (step <= ha))
        step = np.where(outside, 0.5 * (la + ha), step)
        # No representable progress left: the root is pinned to the last bit of s.
        stuck = np.abs(step - sa) <= 4.0 * np.finfo(np.float64).eps * np.maximum(sa, np.finfo(np.float64).tiny)
        s[active] = np.where(done, sa, step)
        active = active[~(done | stuck)]
    if active.size:  # hit the cap: report the residual of the final s
        final[active] = np.abs(residual(s[active], active)[0])

    tan = [_tangent(s, index, n_min) for _, index in media]
    cos_air = 1.0 / np.sqrt(1.0 + tan[0] * tan[0])
    visible = beyond & (cos_air >= GRAZING_COS_MIN) & np.isfinite(final)
    if port.thickness_m > 0.0:
        visible &= 1.0 / np.sqrt(1.0 + tan[1] * tan[1]) >= GRAZING_COS_MIN
    directions = cos_air[:, None] * n + (tan[0] * cos_air)[:, None] * e
    entry = c + gap_air[:, None] * n + (gap_air * tan[0])[:, None] * e
    exit_ = entry + port.thickness_m * (n + tan[1][:, None] * e) if port.thickness_m > 0.0 else entry.copy()
    for arr in (directions, entry, exit_):
        arr[~visible] = np.nan
    final[~visible] = np.nan
    return ForwardProjection(
        directions_cam=directions,
        entry_points_cam=entry,
        exit_points_cam=exit_,
        visible=visible,
        residual_m=final,
        iterations=iterations,
    )


def forward_project_quartic(port: FlatPort, centres_cam: np.ndarray, points_cam: np.ndarray) -> np.ndarray:
    """Air-side directions for a single interface (``t = 0``) from Agrawal et al.'s quartic (CVPR 2012).

    In the plane of incidence, with ``a``, ``w`` and ``rho`` as in the module docstring and ``x``
    the lateral position of the hit on the interface, Snell's law
    ``n_air x / sqrt(x^2 + a^2) = n_water (rho - x) / sqrt((rho - x)^2 + w^2)``, squared, is the quartic
    ``(n_air^2 - n_water^2) x^2 (rho - x)^2 + n_air^2 w^2 x^2 - n_water^2 a^2 (rho - x)^2 = 0``. Its roots
    are the eigenvalues of the companion matrices (vectorised over points); the answer is the real
    root in ``[0, rho]`` that satisfies the unsquared equation best. Meant as an independent check of
    :func:`forward_project`; it does not apply the grazing limit.

    Parameters
    ----------
    port : FlatPort
        A port with ``thickness_m == 0``.
    centres_cam : array_like, shape (3,) or (N, 3)
        Centres of projection, camera frame, metres, on the camera side of the interface.
    points_cam : array_like, shape (N, 3)
        Points, camera frame, metres.

    Returns
    -------
    ndarray, shape (N, 3)
        Unit air-side directions; NaN rows for points not beyond the interface.

    Raises
    ------
    ParameterError
        As :func:`forward_project`, and for a port with glass (``thickness_m > 0``).
    """
    c, x = _checked(port, centres_cam, points_cam)
    if port.thickness_m != 0.0:
        raise ParameterError(
            f"forward_project_quartic solves a single interface only (port.thickness_m = 0), got {port.thickness_m!r}"
        )
    n = port.normal
    a = port.distance_m - c @ n
    rel = x - c
    along = rel @ n
    w = along - a
    lateral_vec = rel - along[:, None] * n
    rho = np.linalg.norm(lateral_vec, axis=1)
    beyond = w > 0.0
    out = np.full(x.shape, np.nan)
    if port.n_air == port.n_water:  # no refraction: the straight line
        out[beyond] = rel[beyond] / np.linalg.norm(rel[beyond], axis=1, keepdims=True)
        return out
    rows = np.flatnonzero(beyond & (rho > 0.0))
    on_normal = beyond & (rho == 0.0)
    out[on_normal] = n
    if rows.size == 0:
        return out
    # Lengths in units of the row's scale, so the coefficients are of order one.
    scale = (a + w + rho)[rows]
    aa, ww, rr = a[rows] / scale, w[rows] / scale, rho[rows] / scale
    na2, nw2 = port.n_air**2, port.n_water**2
    lead = na2 - nw2
    # lead x^4 - 2 r lead x^3 + (r^2 lead + na2 w^2 - nw2 a^2) x^2 + 2 r nw2 a^2 x - nw2 a^2 r^2
    coeffs = (
        np.stack(
            [
                -2.0 * rr * lead,
                rr * rr * lead + na2 * ww * ww - nw2 * aa * aa,
                2.0 * rr * nw2 * aa * aa,
                -nw2 * aa * aa * rr * rr,
            ],
            axis=1,
        )
        / lead
    )
    companion = np.zeros((rows.size, 4, 4))
    companion[:, 0, :] = -coeffs
    companion[:, 1, 0] = companion[:, 2, 1] = companion[:, 3, 2] = 1.0
    roots = np.linalg.eigvals(companion)  # (M, 4) complex
    real = roots.real
    plausible = (np.abs(roots.imag) <= 1e-9) & (real >= -1e-12) & (real <= rr[:, None] + 1e-12)
    xs = np.clip(real, 0.0, rr[:, None])
    snell = port.n_air * xs / np.hypot(xs, aa[:, None]) - port.n_water * (rr[:, None] - xs) / np.hypot(
        rr[:, None] - xs, ww[:, None]
    )
    misfit = np.where(plausible, np.abs(snell), np.inf)
    best = xs[np.arange(rows.size), np.argmin(misfit, axis=1)]
    ray = aa[:, None] * n + best[:, None] * (lateral_vec[rows] / rho[rows, None])
    out[rows] = ray / np.linalg.norm(ray, axis=1, keepdims=True)
    return out


def project_through_port(
    port: FlatPort | None, pinhole: PinholeCamera, centres_cam: np.ndarray, points_cam: np.ndarray
) -> np.ndarray:
    """Pixels of points seen by pinholes behind the port: ``K (r / r_z)`` of the forward-projected ray ``r``.

    Each pinhole has ``pinhole``'s intrinsics and the camera frame's orientation, its centre at
    ``centres_cam``; its pixel ``p`` looks along ``K^-1 p`` (the sub-aperture views of
    :mod:`lfrefract.synthesis.views`).

    Parameters
    ----------
    port : FlatPort or None
        None: no port, straight rays (``K (X - C)`` normalised).
    pinhole : PinholeCamera
    centres_cam : array_like, shape (3,) or (N, 3)
        Centres of projection, camera frame, metres.
    points_cam : array_like, shape (N, 3)
        Points, camera frame, metres.

    Returns
    -------
    ndarray, shape (N, 2)
        Pixels ``(u, v)``; NaN where the point is not visible (:func:`forward_project`) or its ray
        does not point forward (``r_z <= 0``).

    Raises
    ------
    ParameterError
        As :func:`forward_project`; for ``port=None`` the centres need only be finite.
    """
    if not isinstance(pinhole, PinholeCamera):
        raise ParameterError(f"pinhole must be a PinholeCamera, got {pinhole!r}")
    if port is None:
        x = as_points("points_cam", points_cam, 3)
        c = as_points("centres_cam", centres_cam, 3)
        if c.shape[0] != 1 and c.shape != x.shape:
            raise ParameterError(
                f"centres_cam must have shape (3,) or the shape of points_cam {x.shape}, got {np.shape(centres_cam)}"
            )
        rays = x - c
    else:
        rays = forward_project(port, centres_cam, points_cam).directions_cam
    with np.errstate(invalid="ignore", divide="ignore"):
        uv = pinhole.focal_px * rays[:, :2] / rays[:, 2:3] + np.array([pinhole.cx_px, pinhole.cy_px])
    uv[~(rays[:, 2] > 0.0)] = np.nan
    return uv
