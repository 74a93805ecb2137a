"""Fitting the generic ray model to in-air chessboard light fields, and choosing its capacity.

:class:`~lfrefract.optics.ray_correction.PolynomialCorrection` maps a thin-lens ray ``(a, t)`` to the
camera's ray through ``a + dO`` on z = 0 with slopes ``t + dT``. A board corner ``X`` (camera frame)
seen along it leaves the residual

    ``e = X_xy - (a + dO) - X_z (t + dT)``,

the corner's offset from the ray in the plane z = X_z (metres): the ray reprojection error of
Dansereau et al. (CVPR 2013) measured in the board's depth plane rather than perpendicular to the ray
(the two differ by the ray's cosine, at most 6 % at a slope of 0.35). ``e`` is linear in the model's
coefficients, so one Gauss-Newton step solves for them exactly for given board poses; the poses (six
per capture) are eliminated by their Schur complement, as in bundle adjustment, and the whole is
damped (Levenberg-Marquardt). The coefficients are expressed in a basis without the six directions
that move the camera frame (:func:`lfrefract.optics.ray_correction.frame_directions`), which the poses
would absorb.

Two priors keep the problem determined without choosing the answer: every normalised coefficient has
a weak zero-mean prior of :data:`COEFFICIENT_PRIOR` (the ray moves by at most about the aperture
radius or the field's largest slope), and the slope scale (``dT`` along ``t``, the focal length) has
the prior :data:`~lfrefract.optics.ray_correction.HELD_SLOPE_SCALE_STD` that the file's focal length is
right to 1 %: boards spanning a few degrees cannot tell a focal length from a distance (see
:mod:`lfrefract.calibration.camera`).

The capacity (:data:`~lfrefract.optics.ray_correction.POLYNOMIAL_CAPACITIES`) is chosen by the error
on held-back captures (:func:`choose_capacity`): the captures are split into folds; each fold is fitted
without its captures, then each held-back capture's pose alone is fitted to the fixed model, and its
corners' RMS offset is the held-back error. The smallest capacity whose error lies within one
standard error of the best is kept (the "one standard error" rule of cross-validation).

Frames and units: camera frame (OpenCV axes), metres; slopes dimensionless.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from lfrefract.calibration.uncertainty import clustered_covariance
from lfrefract.errors import CalibrationError
from lfrefract.optics.ray_correction import (
    HELD_SLOPE_SCALE_STD,
    POLYNOMIAL_CAPACITIES,
    Capacity,
    PolynomialCorrection,
    frame_directions,
    polynomial_exponents,
    symmetric_directions,
)

__all__ = ["COEFFICIENT_PRIOR", "CapacityScore", "PolynomialFit", "choose_capacity", "fit_polynomial"]

#: Prior standard deviation of every normalised coefficient (output in units of the aperture radius
#: or the field's largest slope): a ray model that moves rays by more than that is not a camera's.
COEFFICIENT_PRIOR = 1.0
#: Levenberg-Marquardt iterations at most, and the relative decrease of the cost that ends them.
_MAX_ITERATIONS = 60
_TOLERANCE = 1e-10
#: Capacities in a row without improvement after which :func:`choose_capacity` stops.
_PATIENCE = 3
#: Most folds of the held-back captures (fewer with fewer captures: one capture a fold).
MAX_FOLDS = 5

#: One capture's observations: board points (N, 3, board frame, metres), aperture points (N, 2,
#: metres) and thin-lens slopes (N, 2).
Observed = tuple[np.ndarray, np.ndarray, np.ndarray]


@dataclass(frozen=True, eq=False)
class PolynomialFit:
    """One fit of :func:`fit_polynomial`.

    Attributes
    ----------
    correction : PolynomialCorrection
    poses : ndarray, shape (n, 6)
        Each capture's rotation vector (rad) and translation (m), board to camera frame.
    rms_m : float
        RMS corner-to-ray offset (both components), metres.
    per_capture_rms_m : tuple of float
    covariance : ndarray, shape (P, P)
        Covariance of the free coefficients (normalised, in the gauge-free basis ``basis``), marginal
        over the poses, scaled by the residual variance.
    clustered : ndarray, shape (P, P)
        The same with each capture as one sample (sandwich estimate).
    free : ndarray, shape (P,)
        The fitted free coefficients (normalised, in ``basis``).
    basis : ndarray, shape (4 M, P)
        The basis that keeps the frame: normalised coefficients (row-major (M, 4)) are ``basis @ q``.
    """

    correction: PolynomialCorrection
    poses: np.ndarray
    rms_m: float
    per_capture_rms_m: tuple[float, ...]
    covariance: np.ndarray
    clustered: np.ndarray
    free: np.ndarray
    basis: np.ndarray


@dataclass(frozen=True)
class CapacityScore:
    """The held-back error of one capacity (:func:`choose_capacity`).

    Attributes
    ----------
    capacity : Capacity
    held_back_rms_m : float
        RMS offset of the held-back captures' corners from the rays of the model fitted without them.
    standard_error_m : float
        Its standard error over the held-back captures.
    fit_rms_m : float
        The RMS of the fit to every capture.
    """

    capacity: Capacity
    held_back_rms_m: float
    standard_error_m: float
    fit_rms_m: float

    def to_dict(self) -> dict:
        """Plain data: the capacity's fields and the three figures (metres)."""
        return {
            **self.capacity._asdict(),
            "held_back_rms_m": self.held_back_rms_m,
            "standard_error_m": self.standard_error_m,
            "fit_rms_m": self.fit_rms_m,
        }


@functools.cache
def free_basis(capacity: Capacity) -> np.ndarray:
    """The free coefficients' basis of a capacity, (4 M, P) with orthonormal columns (normalised
    coefficients, row-major (M, 4)): the symmetric terms (:func:`symmetric_directions`) or every
    monomial's, less the frame's directions (:func:`frame_directions`)."""
    degree, aperture_degree, symmetric = capacity
    fixed = frame_directions(polynomial_exponents(degree, aperture_degree))  # orthonormal rows
    if symmetric:
        table = symmetric_directions(degree, aperture_degree)
        table = table - (table @ fixed.T) @ fixed
        _, singular, vt = np.linalg.svd(table, full_matrices=False)
        basis = vt[singular > 1e-9 * singular.max()].T
    else:
        _, singular, vt = np.linalg.svd(fixed)
        basis = vt[int(np.sum(singular > 1e-9)) :].T
    basis.setflags(write=False)
    return basis


def _left_jacobian(rotvec: np.ndarray) -> np.ndarray:
    """SO(3)'s left Jacobian at each rotation vector (n, 3) -> (n, 3, 3): d exp(w) / dw = [.]x J_l(w)."""
    theta = np.linalg.norm(rotvec, axis=1)
    skew = _skew(rotvec)
    small = theta < 1e-6
    th = np.where(small, 1.0, theta)
    a = np.where(small, 0.5 - theta**2 / 24.0, (1.0 - np.cos(th)) / th**2)
    b = np.where(small, 1.0 / 6.0 - theta**2 / 120.0, (th - np.sin(th)) / th**3)
    return np.eye(3) + a[:, None, None] * skew + b[:, None, None] * skew @ skew


def _skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrices of vectors (n, 3) -> (n, 3, 3)."""
    out = np.zeros((len(v), 3, 3))
    out[:, 0, 1], out[:, 0, 2], out[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    out[:, 1, 0], out[:, 2, 0], out[:, 2, 1] = v[:, 2], -v[:, 1], v[:, 0]
    return out


class _Problem:
    """The least-squares problem of one capacity on a set of captures (see the module docstring)."""

    def __init__(
        self,
        observed: Sequence[Observed],
        capacity: Capacity,
        aperture_norm_m: float,
        slope_norm: float,
    ) -> None:
        degree, aperture_degree, symmetric = capacity
        self.exponents = polynomial_exponents(degree, aperture_degree)
        self.degree, self.aperture_degree, self.symmetric = degree, aperture_degree, symmetric
        self.norms = np.array([aperture_norm_m, aperture_norm_m, slope_norm, slope_norm])
        self.template = PolynomialCorrection(
            degree=degree,
            aperture_degree=aperture_degree,
            aperture_norm_m=aperture_norm_m,
            slope_norm=slope_norm,
            coefficients=np.zeros((len(self.exponents), 4)),
        )
        self.basis = free_basis(Capacity(degree, aperture_degree, symmetric))
        self.observed = list(observed)
        self.points = [p for p, _, _ in self.observed]
        self.a = [a for _, a, _ in self.observed]
        self.t = [t for _, _, t in self.observed]
        self.phi = [self.template.monomials(a, t) for _, a, t in self.observed]
        # Each free coefficient's effect on dO_x, dO_y, dT_x, dT_y at each observation: (4, n, P), fixed.
        columns = self.basis.reshape(len(self.exponents), 4, -1)
        self.effects = [np.stack([phi @ columns[:, c, :] * self.norms[c] for c in range(4)]) for phi in self.phi]
        # The slope scale: the normalised coefficients of dT_x along t_x and dT_y along t_y, averaged.
        index = {tuple(int(v) for v in e): m for m, e in enumerate(self.exponents)}
        scale_row = np.zeros((len(self.exponents), 4))
        scale_row[index[(0, 0, 1, 0)], 2] = 0.5
        scale_row[index[(0, 0, 0, 1)], 3] = 0.5
        self.scale_row = scale_row.ravel() @ self.basis  # (P,): the slope scale - 1 of q

    @property
    def n_free(self) -> int:
        return self.basis.shape[1]

    def correction(self, q: np.ndarray) -> PolynomialCorrection:
        coefficients = (self.basis @ q).reshape(-1, 4) * self.norms
        return PolynomialCorrection(
            degree=self.degree,
            aperture_degree=self.aperture_degree,
            aperture_norm_m=self.template.aperture_norm_m,
            slope_norm=self.template.slope_norm,
            coefficients=coefficients,
            symmetric=self.symmetric,
        )

    def _delta(self, k: int, q: np.ndarray) -> np.ndarray:
        """Capture ``k``'s ``(dO_x, dO_y, dT_x, dT_y)`` at the free coefficients ``q``: (N_k, 4)."""
        return np.einsum("cnp,p->nc", self.effects[k], q)

    def residuals(self, q: np.ndarray, poses: np.ndarray) -> list[np.ndarray]:
        """Each capture's residuals (N_k, 2), metres."""
        out = []
        for k in range(len(self.observed)):
            delta = self._delta(k, q)
            corners = Rotation.from_rotvec(poses[k, :3]).apply(self.points[k]) + poses[k, 3:]
            out.append(corners[:, :2] - (self.a[k] + delta[:, :2]) - corners[:, 2:3] * (self.t[k] + delta[:, 2:]))
        return out

    def summed(self, q: np.ndarray, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[tuple[np.ndarray, ...]]]:
        """The Gauss-Newton blocks of the residuals ``r`` and their Jacobians ``J_q`` (free coefficients)
        and ``J_p`` (each capture's pose): ``J_q^T J_q`` (P, P) and ``J_q^T r`` (P,) summed over
        captures, and per capture ``(J_p^T J_p, J_q^T J_p, J_p^T r, J_q^T r)``.

        A residual's x component moves with the free coefficients as ``-(dO_x' + X_z dT_x')``, the
        primes their effects (:attr:`effects`, fixed by the observations), so ``J_q`` is formed from
        them and the corners' depths. The pose's rotation is differentiated through SO(3)'s left
        Jacobian, exactly at any rotation.
        """
        hqq_total = np.zeros((self.n_free, self.n_free))
        gq_total = np.zeros(self.n_free)
        per_capture: list[tuple[np.ndarray, ...]] = []
        for k, effects in enumerate(self.effects):
            delta = self._delta(k, q)
            slopes = self.t[k] + delta[:, 2:]
            rotated = Rotation.from_rotvec(poses[k, :3]).apply(self.points[k])
            corners = rotated + poses[k, 3:]
            z = corners[:, 2]
            r = corners[:, :2] - (self.a[k] + delta[:, :2]) - z[:, None] * slopes  # (n, 2)
            jq = -np.stack([effects[0] + z[:, None] * effects[2], effects[1] + z[:, None] * effects[3]], axis=1)
            jq = jq.reshape(-1, self.n_free)  # rows x0, y0, x1, ...
            de_dx = np.zeros((len(z), 2, 3))  # d e / d X
            de_dx[:, 0, 0] = de_dx[:, 1, 1] = 1.0
            de_dx[:, :, 2] = -slopes
            dx_dw = -_skew(rotated) @ _left_jacobian(poses[k : k + 1, :3])[0]  # X = exp(w) P + T
            jp = np.concatenate([de_dx @ dx_dw, de_dx], axis=2).reshape(-1, 6)
            flat = r.ravel()
            gq = jq.T @ flat
            hqq_total += jq.T @ jq
            gq_total += gq
            per_capture.append((jp.T @ jp, jq.T @ jp, jp.T @ flat, gq))
        return hqq_total, gq_total, per_capture


def _prior(problem: _Problem, noise_m: float) -> np.ndarray:
    """The zero-mean prior's information matrix (P, P), in units of the corners' noise ``noise_m``."""
    info = np.eye(problem.n_free) * (noise_m / COEFFICIENT_PRIOR) ** 2
    return info + np.outer(problem.scale_row, problem.scale_row) * (noise_m / HELD_SLOPE_SCALE_STD) ** 2


def _solve(
    problem: _Problem, q: np.ndarray, poses: np.ndarray, noise_m: float, *, fix_model: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """Levenberg-Marquardt with the poses eliminated (Schur complement). ``fix_model``: only poses.
    Returns the free coefficients and the poses."""
    prior_info = _prior(problem, noise_m)

    def cost(q_: np.ndarray, poses_: np.ndarray) -> float:
        r = sum(float(np.sum(e * e)) for e in problem.residuals(q_, poses_))
        return r + (0.0 if fix_model else float(q_ @ prior_info @ q_))

    current = cost(q, poses)
    damping = 1e-3
    for _ in range(_MAX_ITERATIONS):
        hqq, gq, captures = problem.summed(q, poses)
        hqq, gq = (0.0 * hqq, 0.0 * gq) if fix_model else (hqq + prior_info, gq + prior_info @ q)
        blocks = [c[:3] for c in captures]
        improved = False
        for _ in range(12):
            schur, rhs, inverses = hqq + damping * np.diag(np.diag(hqq) + 1e-30), gq.copy(), []
            for hpp, hqp, gp in blocks:
                inv = np.linalg.inv(hpp + damping * np.diag(np.diag(hpp)))
                inverses.append(inv)
                if not fix_model:
                    schur -= hqp @ inv @ hqp.T
                    rhs -= hqp @ inv @ gp
            dq = np.zeros(problem.n_free) if fix_model else -np.linalg.solve(schur, rhs)
            dposes = np.stack([-inv @ (gp + hqp.T @ dq) for inv, (hpp, hqp, gp) in zip(inverses, blocks, strict=True)])
            trial_q, trial_poses = q + dq, poses + dposes
            trial = cost(trial_q, trial_poses)
            if trial < current:
                improved = True
                decrease = (current - trial) / max(current, 1e-300)
                q, poses, current = trial_q, trial_poses, trial
                damping = max(damping / 5.0, 1e-12)
                break
            damping *= 10.0
        if not improved or decrease < _TOLERANCE:
            break
    return q, poses


def fit_polynomial(
    observed: Sequence[Observed],
    *,
    capacity: Capacity | tuple[int, int],
    aperture_norm_m: float,
    slope_norm: float,
    poses: np.ndarray,
    noise_m: float,
    start: np.ndarray | None = None,
) -> PolynomialFit:
    """Fit a :class:`PolynomialCorrection` of the given capacity and one pose per capture.

    Parameters
    ----------
    observed : sequence of (ndarray, ndarray, ndarray)
        Per capture: board points (N, 3, board frame, metres), the thin-lens rays' aperture points
        (N, 2, metres) and slopes (N, 2) along which each was seen.
    capacity : Capacity or (int, int)
        The capacity (a pair: a generic one of that degree and aperture degree).
    aperture_norm_m, slope_norm : float
        The model's scales ``R`` and ``T``.
    poses : ndarray, shape (n, 6)
        Starting poses (rotation vector, translation), e.g. the thin-lens model's own.
    noise_m : float
        The corners' offset noise the priors are weighed against (metres; e.g. a first fit's RMS).
    start : ndarray, optional
        Starting free coefficients (default zero: the thin lens).
    """
    problem = _Problem(observed, Capacity(*capacity), aperture_norm_m, slope_norm)
    q0 = np.zeros(problem.n_free) if start is None else start
    q, fitted = _solve(problem, q0, np.array(poses, dtype=float), noise_m)
    return _result(problem, q, fitted, noise_m)


def _result(problem: _Problem, q: np.ndarray, poses: np.ndarray, noise_m: float) -> PolynomialFit:
    residuals = problem.residuals(q, poses)
    prior_info = _prior(problem, noise_m)
    n_rows = sum(r.size for r in residuals)
    total = float(sum(np.sum(r * r) for r in residuals))
    hqq, _, captures = problem.summed(q, poses)
    hqq = hqq + prior_info
    scores = []
    for hpp, hqp, gp, gq_k in captures:
        hqq -= hqp @ np.linalg.solve(hpp, hqp.T)
        # The capture's score on q with its pose optimal (its pose score is ~zero there).
        scores.append(gq_k - hqp @ np.linalg.solve(hpp, gp))
    dof = max(1, n_rows - problem.n_free - 6 * len(residuals))
    bread = np.linalg.inv(hqq)
    bread = (bread + bread.T) / 2.0
    return PolynomialFit(
        correction=problem.correction(q),
        poses=poses,
        rms_m=math.sqrt(total / (n_rows / 2)),
        per_capture_rms_m=tuple(math.sqrt(float(np.sum(r * r)) / len(r)) for r in residuals),
        covariance=bread * (total / dof),
        clustered=clustered_covariance(bread, scores),
        free=q,
        basis=problem.basis,
    )


def held_back_rms(
    correction: PolynomialCorrection | Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]],
    observed: Observed,
    pose: np.ndarray,
) -> tuple[float, int]:
    """RMS offset (metres) of one capture's corners from a fixed model's rays, its pose fitted
    alone (from ``pose``), and the number of corners."""
    fixed = correction.origins_and_slopes if isinstance(correction, PolynomialCorrection) else correction
    # The fixed model's rays as the observations of a zero model: only the pose moves.
    problem = _Problem([(observed[0], *fixed(observed[1], observed[2]))], Capacity(1, 0), 1.0, 1.0)
    q = np.zeros(problem.n_free)
    _, fitted = _solve(problem, q, np.array([pose], dtype=float), 1.0, fix_model=True)
    residual = problem.residuals(q, fitted)[0]
    return math.sqrt(float(np.sum(residual * residual)) / len(residual)), len(residual)


def problem_size(fit: PolynomialFit) -> int:
    """The number of free coefficients of a fit."""
    return int(fit.basis.shape[1])


def choose_capacity(
    observed: Sequence[Observed],
    *,
    aperture_norm_m: float,
    slope_norm: float,
    poses: np.ndarray,
    noise_m: float,
    capacities: Sequence[Capacity | tuple[int, int]] = POLYNOMIAL_CAPACITIES,
    progress: Callable[[str], None] | None = None,
) -> tuple[PolynomialFit, tuple[CapacityScore, ...]]:
    """The capacity with the smallest error on held-back captures (one standard error rule), fitted
    to every capture, and every capacity's score (see the module docstring).

    Stops going up the ladder once :data:`_PATIENCE` capacities in a row have not improved on the
    best (terms of even degree, which a centred lens lacks, can make one capacity worse than the one
    below while the next odd one is better).

    Raises
    ------
    CalibrationError
        With fewer than 3 captures (no capture can be held back).
    """
    observed = list(observed)
    n = len(observed)
    if n < 3:
        raise CalibrationError(f"choosing the ray model's capacity needs at least 3 captures, got {n}")
    folds = np.arange(n) % min(MAX_FOLDS, n)
    scores: list[CapacityScore] = []
    fits: list[PolynomialFit] = []
    worse_in_a_row = 0
    for given in capacities:
        capacity = Capacity(*given)
        full = fit_polynomial(
            observed,
            capacity=capacity,
            aperture_norm_m=aperture_norm_m,
            slope_norm=slope_norm,
            poses=poses,
            noise_m=noise_m,
        )
        errors, counts = [], []
        for fold in np.unique(folds):
            keep = np.flatnonzero(folds != fold)
            part = fit_polynomial(
                [observed[k] for k in keep],
                capacity=capacity,
                aperture_norm_m=aperture_norm_m,
                slope_norm=slope_norm,
                poses=full.poses[keep],
                noise_m=noise_m,
                start=full.free,
            )
            for k in np.flatnonzero(folds == fold):
                rms, count = held_back_rms(part.correction, observed[k], full.poses[k])
                errors.append(rms)
                counts.append(count)
        err, cnt = np.array(errors), np.array(counts)
        mean_sq = float(np.sum(err**2 * cnt) / np.sum(cnt))
        # Standard error of the pooled RMS over captures (delta method on the mean square).
        se = math.sqrt(float(np.var(err**2, ddof=1)) / n) / (2.0 * math.sqrt(mean_sq)) if n > 1 else 0.0
        score = CapacityScore(
            capacity=capacity,
            held_back_rms_m=math.sqrt(mean_sq),
            standard_error_m=se,
            fit_rms_m=full.rms_m,
        )
        scores.append(score)
        fits.append(full)
        if progress is not None:
            progress(
                f"ray model {full.correction.name} ({problem_size(full)} free): held-back "
                f"{score.held_back_rms_m * 1e6:.2f} um "
                f"(+- {se * 1e6:.2f}), fit {full.rms_m * 1e6:.2f} um"
            )
        best = min(s.held_back_rms_m for s in scores)
        worse_in_a_row = worse_in_a_row + 1 if score.held_back_rms_m > best else 0
        if worse_in_a_row >= _PATIENCE:
            break
    best_index = int(np.argmin([s.held_back_rms_m for s in scores]))
    bar = scores[best_index].held_back_rms_m + scores[best_index].standard_error_m
    chosen = next(i for i, s in enumerate(scores) if s.held_back_rms_m <= bar)
    return fits[chosen], tuple(scores)
