"""Flat ports as one line of text: the layout of Refractive COLMAP and calibmar (``FLATPORT``)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from lfrefract.errors import FileFormatError, ParameterError
from lfrefract.formats.jsonio import write_text_atomically
from lfrefract.optics.port import FlatPort
from lfrefract.validate import file_problem

#: Largest flat-port file read, bytes: the format is one line of eight numbers and a comment.
MAX_FLAT_PORT_BYTES = 65536

#: Field order of a flat port in Refractive COLMAP and calibmar (``FLATPORT`` parameters).
FLAT_PORT_FIELDS = ("Nx", "Ny", "Nz", "int_dist", "int_thick", "na", "ng", "nw")

__all__ = ["FLAT_PORT_FIELDS", "MAX_FLAT_PORT_BYTES", "read_flat_port", "write_flat_port"]


def write_flat_port(path: str | os.PathLike, port: FlatPort) -> Path:
    """Write a port in the flat-port layout of Refractive COLMAP / calibmar, atomically.

    One comment line naming the fields, then ``Nx Ny Nz int_dist int_thick na ng nw``: the unit
    normal (camera frame, into the water), the distance of the air-side face from the camera
    centre and the glass thickness (metres), and the refractive indices of air, glass and water.
    """
    if not isinstance(port, FlatPort):
        raise ParameterError(f"port must be a FlatPort, got {port!r}")
    values = [*port.normal, port.distance_m, port.thickness_m, port.n_air, port.n_glass, port.n_water]
    text = "# " + " ".join(FLAT_PORT_FIELDS) + "\n" + " ".join(repr(float(v)) for v in values) + "\n"
    return write_text_atomically(Path(path), text)


def read_flat_port(path: str | os.PathLike) -> FlatPort:
    """Read a port written by :func:`write_flat_port` (or any file with that one line).

    Raises
    ------
    FileFormatError
        If the file is missing, larger than a port file can be (:data:`MAX_FLAT_PORT_BYTES`), not
        UTF-8 text, not one line of the eight fields, or its values are not a valid port (the
        normal not a unit vector, a value outside :class:`FlatPort`'s ranges).
    """
    path = Path(path)
    if (problem := file_problem(path)) is not None:
        raise FileFormatError(problem)
    if path.stat().st_size > MAX_FLAT_PORT_BYTES:
        raise FileFormatError(
            f"{str(path)!r} is {path.stat().st_size} bytes: not a flat port (at most {MAX_FLAT_PORT_BYTES} bytes)"
        )
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as exc:
        raise FileFormatError(f"{str(path)!r} is not UTF-8 text (byte {exc.start}): not a flat port") from None
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    try:
        values = [float(v) for v in lines[0].split()] if len(lines) == 1 else []
    except ValueError:
        values = []
    if len(values) != len(FLAT_PORT_FIELDS):
        raise FileFormatError(f"{str(path)!r} is not a flat port ({' '.join(FLAT_PORT_FIELDS)} on one line)")
    nx, ny, nz, distance, thickness, n_air, n_glass, n_water = values
    if abs(np.hypot(np.hypot(nx, ny), nz) - 1.0) > 1e-6:
        raise FileFormatError(f"{str(path)!r}: the normal ({nx!r}, {ny!r}, {nz!r}) is not a unit vector")
    try:
        return FlatPort.from_normal(
            np.array([nx, ny, nz]),
            distance_m=distance,
            thickness_m=thickness,
            n_air=n_air,
            n_glass=n_glass,
            n_water=n_water,
        )
    except ParameterError as exc:
        raise FileFormatError(f"{str(path)!r} is not a valid port: {exc}") from None
