"""Validation helpers used at every public boundary.

Every check raises :class:`ParameterError` (a :class:`ValueError`) whose message names
the parameter and the offending value. Nothing is clipped, rounded or otherwise repaired.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = [
    "ParameterError",
    "as_points",
    "finite_float",
    "finite_vector",
    "non_negative_float",
    "one_of",
    "positive_float",
    "positive_int",
    "reject_unknown_keys",
    "require_keys",
]


class ParameterError(ValueError):
    """A parameter has an impossible, non-finite or unknown value."""


def finite_float(name: str, value: Any) -> float:
    """Return ``value`` as a float, or raise if it is not a finite real number."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ParameterError(f"{name} must be a real number, got {value!r}")
    out = float(value)
    if not math.isfinite(out):
        raise ParameterError(f"{name} must be finite, got {value!r}")
    return out


def positive_float(name: str, value: Any) -> float:
    """Return ``value`` as a float, or raise unless it is finite and > 0."""
    out = finite_float(name, value)
    if out <= 0.0:
        raise ParameterError(f"{name} must be positive, got {value!r}")
    return out


def non_negative_float(name: str, value: Any) -> float:
    """Return ``value`` as a float, or raise unless it is finite and >= 0."""
    out = finite_float(name, value)
    if out < 0.0:
        raise ParameterError(f"{name} must be non-negative, got {value!r}")
    return out


def positive_int(name: str, value: Any) -> int:
    """Return ``value`` as an int, or raise unless it is an integer > 0."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ParameterError(f"{name} must be an integer, got {value!r}")
    if value <= 0:
        raise ParameterError(f"{name} must be positive, got {value!r}")
    return int(value)


def one_of(name: str, value: Any, allowed: Sequence[str]) -> str:
    """Return ``value`` if it is one of ``allowed``, else raise."""
    if value not in allowed:
        raise ParameterError(f"{name} must be one of {list(allowed)}, got {value!r}")
    return str(value)


def finite_vector(name: str, value: Any, length: int) -> tuple[float, ...]:
    """Return ``value`` as a tuple of ``length`` finite floats, or raise."""
    try:
        items = tuple(value)
    except TypeError:
        raise ParameterError(f"{name} must be a sequence of {length} numbers, got {value!r}") from None
    if len(items) != length:
        raise ParameterError(f"{name} must have {length} entries, got {value!r}")
    return tuple(finite_float(f"{name}[{i}]", v) for i, v in enumerate(items))


def as_points(name: str, value: Any, dim: int) -> np.ndarray:
    """Return ``value`` as a float64 array of shape (N, dim) with finite entries, or raise.

    A single point of shape (dim,) is accepted and returned as shape (1, dim).
    """
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 1 and arr.shape[0] == dim:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != dim:
        raise ParameterError(f"{name} must have shape (N, {dim}), got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        bad = arr[~np.all(np.isfinite(arr), axis=1)][0]
        raise ParameterError(f"{name} must be finite, got a row {bad.tolist()}")
    return arr


def reject_unknown_keys(where: str, data: dict, allowed: set[str] | frozenset[str]) -> None:
    """Raise if ``data`` has keys outside ``allowed``; ``where`` names the table or object."""
    unknown = sorted(set(data) - set(allowed))
    if unknown:
        raise ParameterError(f"unknown key(s) in {where}: {unknown}; allowed: {sorted(allowed)}")


def require_keys(where: str, data: dict, required: set[str] | frozenset[str]) -> None:
    """Raise if ``data`` lacks any of ``required``; ``where`` names the table or object."""
    missing = sorted(set(required) - set(data))
    if missing:
        raise ParameterError(f"missing key(s) in {where}: {missing}")
