"""How well a calibration knows what it reports: covariances beyond pixel noise.

A least-squares fit's covariance from its Jacobian, ``(J^T J)^-1 sigma^2``, counts every corner as an
independent observation with the same noise. Board captures break that twice: the corners of one
capture share their errors (the board's pose, what the model leaves of the lens), and a fit that
builds on an earlier calibration inherits that calibration's errors. This module gives the pieces the
calibrations combine:

- :func:`clustered_covariance`: the "sandwich" estimate with each capture as one sample;
- :func:`larger_covariance`: of two covariances, the larger in every direction;
- :func:`spread_factors`: a covariance as a few directions ``f_j`` with ``C ~ sum_j f_j f_j^T``, so a
  later fit can propagate it by re-fitting along each (:func:`propagated_covariance`).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import numpy as np

__all__ = [
    "clustered_covariance",
    "fit_covariances",
    "larger_covariance",
    "propagated_covariance",
    "propagated_shifts",
    "spread_factors",
]

#: Most directions :func:`spread_factors` keeps, and the smallest variance kept, relative to the largest.
MAX_SPREAD_DIRECTIONS = 40
SPREAD_RELATIVE_FLOOR = 1e-6


def clustered_covariance(bread: np.ndarray, scores: Sequence[np.ndarray]) -> np.ndarray:
    """The capture-clustered ("sandwich") covariance ``B (n / (n - 1) sum_k s_k s_k^T) B``.

    Parameters
    ----------
    bread : ndarray, shape (P, P)
        ``(J^T J)^-1`` of the fit (without the residual variance).
    scores : sequence of ndarray, shape (P,)
        Each capture's score ``J_k^T r_k`` at the solution.
    """
    stacked = np.stack([np.asarray(s, dtype=float) for s in scores])
    n = len(stacked)
    meat = stacked.T @ stacked * (n / max(1, n - 1))
    out = bread @ meat @ bread
    return (out + out.T) / 2.0


def fit_covariances(
    jac: np.ndarray, residuals: np.ndarray, bread: np.ndarray, sigma2: float, bounds: Sequence[int] | np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """A least-squares fit's two covariances of its parameters: the Jacobian's, ``bread * sigma2``
    (every residual independent, of variance ``sigma2``), and the one clustered by capture
    (:func:`clustered_covariance`; each capture's residuals ``bounds[k]:bounds[k + 1]`` one sample: a
    capture's corners share errors a model cannot follow). Callers state the larger of the two
    (:func:`larger_covariance`) of the parameters they report.

    Parameters
    ----------
    jac : ndarray, shape (M, P)
        The Jacobian at the solution.
    residuals : ndarray, shape (M,)
        The residuals there.
    bread : ndarray, shape (P, P)
        ``(J^T J)^-1``.
    sigma2 : float
        The residuals' variance.
    bounds : sequence of int, or ndarray of int
        Where each cluster's rows start, and the last's end (``K + 1`` numbers for ``K`` clusters).

    Examples
    --------
    >>> import numpy as np
    >>> jac, r = np.ones((4, 1)), np.array([1.0, 1.0, -1.0, -1.0])
    >>> pixel, by_capture = fit_covariances(jac, r, np.array([[0.25]]), 1.0, [0, 2, 4])
    >>> float(pixel[0, 0]), float(by_capture[0, 0])  # two captures that each err one way: 2 x 4 / 16
    (0.25, 1.0)
    """
    scores = [jac[a:b].T @ residuals[a:b] for a, b in itertools.pairwise(bounds)]
    return bread * sigma2, clustered_covariance(bread, scores)


def larger_covariance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The covariance that is the larger of ``a`` and ``b`` in every direction (a positive definite):
    ``a^(1/2) U max(L, 1) U^T a^(1/2)`` with ``U L U^T`` the eigen-decomposition of
    ``a^(-1/2) b a^(-1/2)``."""
    values, vectors = np.linalg.eigh((a + a.T) / 2.0)
    values = np.maximum(values, values.max(initial=0.0) * 1e-15 + 1e-300)
    root = vectors * np.sqrt(values) @ vectors.T
    inverse_root = vectors / np.sqrt(values) @ vectors.T
    ratio_values, ratio_vectors = np.linalg.eigh(inverse_root @ ((b + b.T) / 2.0) @ inverse_root)
    middle = ratio_vectors * np.maximum(ratio_values, 1.0) @ ratio_vectors.T
    out = root @ middle @ root
    return (out + out.T) / 2.0


def spread_factors(covariance: np.ndarray, *, max_directions: int = MAX_SPREAD_DIRECTIONS) -> np.ndarray:
    """Directions ``f_j`` (rows, (k, P)) with ``covariance ~ sum_j f_j f_j^T``: its largest principal
    axes, each scaled by its standard deviation, down to :data:`SPREAD_RELATIVE_FLOOR` of the largest
    variance and at most ``max_directions`` (the variance left out is reported by nothing: keep it small)."""
    values, vectors = np.linalg.eigh((covariance + covariance.T) / 2.0)
    order = np.argsort(values)[::-1]
    values, vectors = values[order], vectors[:, order]
    keep = values > SPREAD_RELATIVE_FLOOR * max(float(values[0]), 1e-300)
    keep[max_directions:] = False
    return (vectors[:, keep] * np.sqrt(values[keep])).T


def propagated_shifts(bread_jt: np.ndarray, residual_changes: Sequence[np.ndarray]) -> np.ndarray:
    """A fit's first-order change ``-(J^T J)^-1 J^T dr_j`` for each direction ``f_j`` of an input's
    uncertainty, ``dr_j`` its residuals' change when the input moves by ``f_j``.

    Parameters
    ----------
    bread_jt : ndarray, shape (P, R)
        ``(J^T J)^-1 J^T`` of the fit.
    residual_changes : sequence of ndarray, shape (R,)

    Returns
    -------
    ndarray, shape (k, P)
        One row per direction (k = 0: shape (0, P)).
    """
    return np.array([-(bread_jt @ change) for change in residual_changes]).reshape(-1, bread_jt.shape[0])


def propagated_covariance(bread_jt: np.ndarray, residual_changes: Sequence[np.ndarray]) -> np.ndarray:
    """The covariance a fit inherits from an input known to ``sum_j f_j f_j^T``: the outer products
    of its :func:`propagated_shifts` summed, shape (P, P)."""
    shifts = propagated_shifts(bread_jt, residual_changes)
    return shifts.T @ shifts
