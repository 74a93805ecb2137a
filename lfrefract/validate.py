"""Validation helpers used at every public boundary.

Every check raises :class:`ParameterError` (a :class:`ValueError`) whose message names
the parameter and the offending value. Nothing is clipped, rounded or otherwise repaired.
Values are shown in messages by :func:`shown`, which keeps them short (a list of a million
numbers, or an integer of a million digits, is abbreviated rather than printed).
"""

from __future__ import annotations

import contextlib
import errno
import math
import os
import reprlib
import stat
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from lfrefract.errors import ParameterError

__all__ = [
    "as_points",
    "as_table",
    "bounded_float",
    "bounded_int",
    "fields_by_flag",
    "file_problem",
    "finite_float",
    "finite_vector",
    "named",
    "non_negative_float",
    "one_of",
    "path_of",
    "positive_float",
    "positive_int",
    "regular_file",
    "reject_unknown_keys",
    "require_keys",
    "shown",
    "text",
]


_SHORT = reprlib.Repr()
_SHORT.maxstring = 80
_SHORT.maxother = 80
_SHORT.maxlong = 40
_SHORT.maxlist = _SHORT.maxtuple = _SHORT.maxdict = _SHORT.maxset = 8
_SHORT.maxlevel = 3


def shown(value: Any) -> str:
    """A short ``repr`` of ``value`` for error messages.

    Strings, sequences and tables are abbreviated with ``...``; an integer too long to print
    (Python refuses to convert integers of more than 4300 digits) is described by its size.
    """
    if isinstance(value, int) and not isinstance(value, bool) and value.bit_length() > 256:
        return f"an integer of {value.bit_length()} bits ({'-' if value < 0 else ''}about 2**{value.bit_length() - 1})"
    if isinstance(value, (float, int, np.number)):
        return repr(value)
    return _SHORT.repr(value)


def finite_float(name: str, value: Any) -> float:
    """Return ``value`` as a float, or raise if it is not a finite real number."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ParameterError(f"{name} must be a real number, got {shown(value)}")
    try:
        out = float(value)
    except OverflowError:  # an int beyond the float range
        raise ParameterError(f"{name} must be finite, got {shown(value)}") from None
    if not math.isfinite(out):
        raise ParameterError(f"{name} must be finite, got {shown(value)}")
    return out


def positive_float(name: str, value: Any) -> float:
    """Return ``value`` as a float, or raise unless it is finite and > 0."""
    out = finite_float(name, value)
    if out <= 0.0:
        raise ParameterError(f"{name} must be positive, got {shown(value)}")
    return out


def non_negative_float(name: str, value: Any) -> float:
    """Return ``value`` as a float, or raise unless it is finite and >= 0."""
    out = finite_float(name, value)
    if out < 0.0:
        raise ParameterError(f"{name} must be non-negative, got {shown(value)}")
    return out


def bounded_float(name: str, value: Any, low: float, high: float, *, low_open: bool = False, unit: str = "") -> float:
    """Return ``value`` as a float, or raise unless it is finite and in ``[low, high]``.

    Parameters
    ----------
    name : str
        The parameter's name in messages.
    value : object
        The value to check.
    low, high : float
        The bounds, both inclusive unless ``low_open``.
    low_open : bool, optional
        Exclude ``low`` itself (``(low, high]``); with ``low = 0`` that is "positive".
    unit : str, optional
        Unit shown after the bounds in messages (``"m"``, ``"deg"``).

    Raises
    ------
    ParameterError
        If ``value`` is not a real number, not finite, or out of range; below a bound of 0 the
        message says "must be positive" (or "non-negative"), otherwise it states the range.
    """
    out = finite_float(name, value)
    below = out <= low if low_open else out < low
    if below and low == 0.0:
        raise ParameterError(f"{name} must be {'positive' if low_open else 'non-negative'}, got {shown(value)}")
    if below or out > high:
        suffix = f" {unit}" if unit else ""
        interval = f"{'(' if low_open else '['}{low:g}, {high:g}]{suffix}"
        raise ParameterError(f"{name} must lie in {interval}, got {shown(value)}")
    return out


def positive_int(name: str, value: Any) -> int:
    """Return ``value`` as an int, or raise unless it is an integer > 0."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ParameterError(f"{name} must be an integer, got {shown(value)}")
    if value <= 0:
        raise ParameterError(f"{name} must be positive, got {shown(value)}")
    return int(value)


def bounded_int(name: str, value: Any, low: int, high: int) -> int:
    """Return ``value`` as an int, or raise unless it is an integer in ``[low, high]``.

    Below ``low = 1`` the message says "must be positive"; above ``high`` it says "must be at
    most ``high``"; otherwise it states the range.
    """
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ParameterError(f"{name} must be an integer, got {shown(value)}")
    if value < low and low == 1:
        raise ParameterError(f"{name} must be positive, got {shown(value)}")
    if value > high and value >= low:
        raise ParameterError(f"{name} must be at most {high}, got {shown(value)}")
    if value < low:
        raise ParameterError(f"{name} must lie in [{low}, {high}], got {shown(value)}")
    return int(value)


def one_of(name: str, value: Any, allowed: Sequence[str]) -> str:
    """Return ``value`` if it is one of the strings ``allowed``, else raise."""
    if not isinstance(value, str) or value not in allowed:
        kind = "" if isinstance(value, str) else "a string, "
        raise ParameterError(f"{name} must be {kind}one of {list(allowed)}, got {shown(value)}")
    return str(value)


def text(name: str, value: Any) -> str:
    """Return ``value`` if it is a string, else raise (a list or number is not silently printed)."""
    if not isinstance(value, str):
        raise ParameterError(f"{name} must be a string, got {shown(value)}")
    return value


def as_table(name: str, value: Any) -> dict:
    """Return ``value`` if it is a table (a dict with string keys, as TOML and JSON give), else raise."""
    if not isinstance(value, Mapping):
        raise ParameterError(f"{name} must be a table, got {shown(value)}")
    bad = [k for k in value if not isinstance(k, str)]
    if bad:
        raise ParameterError(f"{name} must have string keys, got {shown(bad[0])}")
    return dict(value)


def finite_vector(name: str, value: Any, length: int) -> tuple[float, ...]:
    """Return ``value`` as a tuple of ``length`` finite floats, or raise.

    A string, a table or a set is refused (``tuple("abc")`` would otherwise be three letters).
    """
    if isinstance(value, (str, bytes, bytearray, Mapping, set, frozenset)):
        raise ParameterError(f"{name} must be a sequence of {length} numbers, got {shown(value)}")
    try:
        items = tuple(value)
    except TypeError:
        raise ParameterError(f"{name} must be a sequence of {length} numbers, got {shown(value)}") from None
    if len(items) != length:
        raise ParameterError(f"{name} must have {length} entries, got {shown(value)}")
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


def _keys(data: dict) -> list[str]:
    return sorted(str(k) for k in data)


def reject_unknown_keys(where: str, data: dict, allowed: set[str] | frozenset[str]) -> None:
    """Raise if ``data`` has keys outside ``allowed`` (or is not a table); ``where`` names it."""
    if not isinstance(data, Mapping):
        raise ParameterError(f"{where} must be a table, got {shown(data)}")
    unknown = sorted(str(k) for k in data if k not in allowed)
    if unknown:
        raise ParameterError(f"unknown key(s) in {where}: {unknown}; allowed: {sorted(allowed)}")


def require_keys(where: str, data: dict, required: set[str] | frozenset[str]) -> None:
    """Raise if ``data`` lacks any of ``required`` (or is not a table); ``where`` names it."""
    if not isinstance(data, Mapping):
        raise ParameterError(f"{where} must be a table, got {shown(data)}")
    missing = sorted(set(required) - set(_keys(data)))
    if missing:
        raise ParameterError(f"missing key(s) in {where}: {missing}")


_KINDS = (
    (stat.S_ISDIR, "a directory"),
    (stat.S_ISFIFO, "a named pipe (FIFO)"),
    (stat.S_ISSOCK, "a socket"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
)


def file_problem(path: str | os.PathLike[str]) -> str | None:
    """What stops ``path`` from being read as a file, for a message; None if it is a regular file.

    ``Path.is_file()`` answers False alike for a missing path, a folder, a symbolic link loop and a
    link to nothing; a reader that says "no such file" for all of them sends the user looking for
    the wrong mistake. Symbolic links are followed.

    Returns
    -------
    str or None
        ``"no such file: 'x'"``, ``"'x' is a symbolic link loop ..."``, ``"'x' is a symbolic link
        to nothing ..."``, ``"'x' is a directory, not a regular file"`` (or another kind), the system's
        reason it cannot be examined, or None.

    Examples
    --------
    >>> file_problem("/nonexistent/raw.exr")
    "no such file: '/nonexistent/raw.exr'"
    >>> file_problem("/")
    "'/' is a directory, not a regular file"
    """
    p = str(path)
    try:
        st = os.stat(p)
    except FileNotFoundError:
        if os.path.islink(p):
            return f"{p!r} is a symbolic link to nothing ({os.readlink(p)!r})"
        return f"no such file: {p!r}"
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            return f"{p!r} is a symbolic link loop (it never reaches a file): point it at a file"
        return f"{p!r} cannot be examined: {exc.strerror or exc}"
    for test, kind in _KINDS:
        if test(st.st_mode):
            return f"{p!r} is {kind}, not a regular file"
    return None if stat.S_ISREG(st.st_mode) else f"{p!r} is not a regular file"


def regular_file(name: str, path: str | os.PathLike[str], *, max_bytes: int) -> int:
    """The size in bytes of the regular file at ``path``, or raise before anything reads it.

    The kind is checked first (a FIFO would block a reader forever, a directory is not "missing"),
    then the size, from the file's metadata only: a huge (even sparse) file is refused at once.

    Parameters
    ----------
    name : str
        What the file is, for messages (``"mesh path"``, ``"scene file"``).
    path : path-like
        The file; symbolic links are followed.
    max_bytes : int
        Largest size accepted.

    Raises
    ------
    ParameterError
        If the path holds a NUL character, does not exist, is not a regular file (the message
        says what it is), cannot be examined (the system's reason), or is larger than
        ``max_bytes``; the message names the path.
    """
    p = str(path)
    if "\0" in p:
        raise ParameterError(f"{name} {shown(p)} contains a NUL character")
    try:
        st = os.stat(p)
    except FileNotFoundError:
        raise ParameterError(f"{name} {p!r} does not exist") from None
    except OSError as exc:
        raise ParameterError(f"{name} {p!r} cannot be examined: {exc.strerror or exc}") from None
    for test, kind in _KINDS:
        if test(st.st_mode):
            raise ParameterError(f"{name} {p!r} is {kind}, not a regular file")
    if not stat.S_ISREG(st.st_mode):
        raise ParameterError(f"{name} {p!r} is not a regular file")
    if st.st_size > max_bytes:
        raise ParameterError(
            f"{name} {p!r} holds {st.st_size} bytes ({st.st_size / 2**20:.0f} MiB), more than the "
            f"{max_bytes} bytes ({max_bytes / 2**20:.0f} MiB) accepted"
        )
    return int(st.st_size)


def path_of(name: str, value: Any) -> Path:
    """``value`` (a string or path) as a :class:`pathlib.Path`, or raise for anything else."""
    if isinstance(value, os.PathLike):
        value = os.fspath(value)
    return Path(text(name, value))


@contextlib.contextmanager
def named(what: str) -> Iterator[None]:
    """Prefix ``what`` to every :class:`ParameterError` the block raises (of the same class).

    A library check names its field (``render.spp must be positive``); a command line wraps it in
    what the user gave: the option as typed (``--spp``) or the file the value came from.

    Examples
    --------
    >>> with named("--k"):
    ...     positive_int("k", 0)
    Traceback (most recent call last):
    lfrefract.errors.ParameterError: --k: k must be positive, got 0
    """
    try:
        yield
    except ParameterError as exc:
        raise type(exc)(f"{what}: {exc}") from None


def fields_by_flag(check: Callable[..., object], given: Mapping[str, Mapping[str, Any]]) -> dict[str, Any]:
    """The fields set by command-line flags, each flag's fields checked alone by ``check(**fields)``
    (the others at their defaults) so that an invalid value's error starts with its flag.

    Parameters
    ----------
    check : callable
        Builds the options' frozen dataclass from some of its fields (``SynthesisOptions``,
        ``RenderSettings``, ...), raising :class:`ParameterError` for an invalid one.
    given : mapping
        Flag, as the user types it -> the fields it sets; a field whose value is None (an option
        not given) is left out.

    Returns
    -------
    dict
        Every field given, to build the options with.

    Raises
    ------
    ParameterError
        ``"--flag: <the check's message>"`` for the first invalid flag.
    """
    values: dict[str, Any] = {}
    for flag, fields in given.items():
        present = {key: value for key, value in fields.items() if value is not None}
        if present:
            with named(flag):
                check(**present)
            values.update(present)
    return values
