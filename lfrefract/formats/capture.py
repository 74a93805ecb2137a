"""A capture: a raw lenslet image and the parameters it was taken with, read and checked in one place.

A capture folder holds ``raw.exr`` (the raw lenslet image, float, (H, W) or (H, W, 3)) and its
sidecar ``meta.json`` (:func:`lfrefract.formats.jsonio.write_json`) beside it; the core reads these keys of the
sidecar, and ignores the others:

* ``camera`` (required unless a camera is given): a table, :meth:`LightFieldCamera.from_dict`;
* ``port`` (optional, may be null): a table, :meth:`FlatPort.from_dict`;
* ``ideal`` (optional, may be null): the refraction-free image geometry, a table,
  :meth:`PinholeCamera.from_dict` (default :func:`virtual_camera_for` of the camera);
* ``pose`` (optional, may be null): the camera's pose in the world, a table, :meth:`Pose.from_dict`.

A bare raw image (no ``meta.json`` beside it) is a capture too when its camera (and, for a
refraction-free image, its port) is given: a preset name or a camera file, TOML or JSON
(:func:`camera_model_from_option`), and a port file, TOML, JSON or the flat-port text
(:func:`port_from_file`; both formats: :mod:`lfrefract.formats.paramfile`).
A given camera or port replaces the sidecar's.

Raw values that are NaN, infinite or negative record no radiance. :func:`read_capture` refuses a
raw image holding any (``nonfinite="refuse"``, the default), with their count, or, with
``nonfinite="mask"``, marks their pixels as unrecorded (:attr:`Capture.recorded`): the commands
then give them no weight (:func:`mask_warp_map`; ``recorded`` of :mod:`lfrefract.synthesis.views`) and
report how many were masked.

Every problem is a :class:`lfrefract.errors.FileFormatError` naming the file and the key (a missing
key, a value of the wrong type or an impossible value), never a KeyError or a traceback.

:func:`write_capture` is the one writer of capture folders (``lfsim render`` writes its renders
with it): ``raw.exr``, ``meta.json`` with ``kind``, ``files`` (role -> file name of every image
it wrote), ``camera``, ``pose``, ``port`` and ``ideal`` (null when not given) followed by the
caller's own keys, and, for a capture with ground truth (:class:`CaptureTruth`), ``ideal.exr``,
``depth.exr`` and ``lenses.npz``. :func:`read_capture` reads such a folder (or its raw image);
:func:`read_ground_truth` its ground truth.
"""

from __future__ import annotations

import dataclasses
import os
import zipfile
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from lfrefract.calibration.camera import CAMERA_CALIBRATION_KIND
from lfrefract.errors import FileFormatError, ParameterError
from lfrefract.formats.exr import read_exr, write_exr
from lfrefract.formats.jsonio import read_json, write_json
from lfrefract.formats.lytro import colour_from_metadata
from lfrefract.formats.mosaic import cfa_channels
from lfrefract.formats.outputs import atomic_file, staged_directory
from lfrefract.formats.paramfile import (
    camera_from_json,
    check_kind,
    read_camera_file,
    read_parameter_json,
    read_port_file,
)
from lfrefract.formats.whites import (
    MAX_WHITE_SHIFT_PX,
    DevelopedCapture,
    FlatField,
    WhiteImage,
    develop,
    existing_path,
    find_white_images,
    is_lytro_file,
    lens_steps,
    micro_image_shift_px,
    read_lytro_file,
    same_file,
)
from lfrefract.optics.camera import LightFieldCamera
from lfrefract.optics.camera_model import BOARD_COLOURS, CameraModel
from lfrefract.optics.lens import LensPrescription
from lfrefract.optics.pinhole import PinholeCamera, virtual_camera_for
from lfrefract.optics.port import FlatPort
from lfrefract.optics.pose import Pose
from lfrefract.optics.presets import PRESETS, camera_preset
from lfrefract.optics.ray_correction import Correction, CorrectionEstimate, RayCorrection, correction_from_dict
from lfrefract.optics.real_lens import RealLensCamera, TracedLens
from lfrefract.synthesis.depth_aware import DepthAwareResult, DepthAwareSynthesis, SearchImage
from lfrefract.validate import file_problem, one_of, shown

__all__ = [
    "CAPTURE_KIND",
    "DEPTH_NAME",
    "IDEAL_NAME",
    "LENSES_NAME",
    "MAX_RAW_VALUE",
    "NONFINITE_POLICIES",
    "RAW_NAME",
    "SIDECAR_NAME",
    "Capture",
    "CaptureParameters",
    "CaptureSidecar",
    "CaptureTruth",
    "UnrecordedValues",
    "WhiteChoice",
    "apply_depth_aware",
    "camera_model_from_option",
    "capture_parameters",
    "check_lens_modelled",
    "check_port_ray_model",
    "mask_warp_map",
    "mla_from_file",
    "port_from_file",
    "read_capture",
    "read_ground_truth",
    "read_lytro_capture",
    "read_sidecar",
    "recorded_main_lens",
    "recorded_prescription",
    "white_for",
    "write_capture",
    "write_capture_files",
]

#: Name of a capture's sidecar, beside its raw image.
SIDECAR_NAME = "meta.json"

#: Name of a capture folder's raw lenslet image (EXR role ``"raw"``).
RAW_NAME = "raw.exr"

#: Name of a rendered capture's ideal refraction-free image (EXR role ``"ideal"``; ground truth).
IDEAL_NAME = "ideal.exr"

#: Name of a rendered capture's depth map along the ideal image's rays (EXR role ``"depth"``; ground truth).
DEPTH_NAME = "depth.exr"

#: Name of a rendered capture's microlens ground truth (NumPy ``.npz``: ``lens_index``, ``lens_centre_m``,
#: ``micro_image_centre_px``).
LENSES_NAME = "lenses.npz"

#: Kind of a capture folder written by :func:`write_capture` unless the caller names another
#: (``lfsim render`` writes ``"lfsim.render"``).
CAPTURE_KIND = "lfrefract.capture"

#: Keys of a capture's sidecar that :func:`write_capture` writes itself (``metadata`` may not hold them).
_SIDECAR_KEYS = ("kind", "files", "camera", "pose", "port", "ideal")

#: What :func:`read_capture` does with NaN, infinite and negative raw values.
NONFINITE_POLICIES = ("refuse", "mask")
#: Largest raw value taken (any unit of radiance). The steps after reading scale raw values in float32
#: (the port's radiometric gain, the weighted sums of the synthesis, the depth search's gain): a finite
#: 3e38 overflowed to infinity there. 1e30 leaves them a factor 1e8 below float32's 3.4e38, far
#: beyond any image's range.
MAX_RAW_VALUE = 1e30


def _table(path: Path, data: dict, key: str, *, required: bool, nullable: bool) -> dict | None:
    """``data[key]`` if it is a table; None if it is absent and not ``required``, or null and ``nullable``."""
    if key not in data:
        if required:
            raise FileFormatError(f"{str(path)!r} has no key {key!r}")
        return None
    value = data[key]
    if value is None and nullable:
        return None
    if not isinstance(value, dict):
        raise FileFormatError(f"{str(path)!r}: key {key!r} must be a table (a JSON object), got {value!r}")
    return value


def _parse(path: Path, key: str, value: dict, parser):
    """``parser(value)``, its ParameterError a FileFormatError naming the file and key."""
    try:
        return parser(value)
    except ParameterError as exc:
        raise FileFormatError(f"{str(path)!r}: key {key!r}: {exc}") from None


@dataclass(frozen=True, kw_only=True, eq=False)
class CaptureSidecar:
    """The parameters a capture's sidecar (``meta.json``) gives, checked (:func:`read_sidecar`).

    Attributes
    ----------
    path : Path
        The sidecar file.
    data : dict
        Its whole content, as read (not to be modified).
    camera : LightFieldCamera or None
        None only when the sidecar has no ``camera`` and none was required.
    port : FlatPort or None
    ideal : PinholeCamera or None
    pose : Pose or None
    """

    path: Path
    data: dict
    camera: LightFieldCamera | None
    port: FlatPort | None
    ideal: PinholeCamera | None
    pose: Pose | None


def read_sidecar(path: str | os.PathLike, *, camera_required: bool = True) -> CaptureSidecar:
    """Read and check a capture's sidecar: every key the core uses, with its type and values.

    Parameters
    ----------
    path : path-like
        A ``meta.json`` (schema version 1).
    camera_required : bool
        Whether a missing ``camera`` is an error (it is not when the caller gives the camera).

    Returns
    -------
    CaptureSidecar

    Raises
    ------
    FileFormatError
        If the file is missing, not UTF-8 JSON of this schema, lacks ``camera`` (when required), or
        a key the core reads (``camera``, ``port``, ``ideal``, ``pose``) is not a table or holds an
        invalid value; or if it holds a table of a camera or ray model that its ``kind`` does not
        hold (:func:`lfrefract.formats.paramfile.check_kind`: a ``correction`` is not read from a
        sidecar): the message names the file and the key.
    """
    path = Path(path)
    data = read_json(path)
    check_kind(path, data)  # a camera or ray model table the sidecar's kind does not hold: refused
    camera_data = _table(path, data, "camera", required=camera_required, nullable=False)
    port_data = _table(path, data, "port", required=False, nullable=True)
    ideal_data = _table(path, data, "ideal", required=False, nullable=True)
    pose_data = _table(path, data, "pose", required=False, nullable=True)
    return CaptureSidecar(
        path=path,
        data=data,
        camera=None if camera_data is None else _parse(path, "camera", camera_data, LightFieldCamera.from_dict),
        port=None if port_data is None else _parse(path, "port", port_data, FlatPort.from_dict),
        ideal=None if ideal_data is None else _parse(path, "ideal", ideal_data, PinholeCamera.from_dict),
        pose=None if pose_data is None else _parse(path, "pose", pose_data, Pose.from_dict),
    )


@dataclass(frozen=True, kw_only=True)
class UnrecordedValues:
    """Counts of the raw values that record no radiance, and of the pixels holding any.

    Attributes
    ----------
    nan, posinf, neginf, negative : int
        Values that are NaN, +inf, -inf, and finite and below zero.
    pixels : int
        Pixels with at least one such value (in any channel).
    """

    nan: int = 0
    posinf: int = 0
    neginf: int = 0
    negative: int = 0
    pixels: int = 0

    @classmethod
    def of(cls, raw: np.ndarray) -> UnrecordedValues:
        """Count them in ``raw`` ((H, W) or (H, W, C) float), and the pixels that hold any."""
        if raw.size == 0:
            return cls()
        low, high = raw.min(), raw.max()  # NaN if any value is NaN
        if np.isfinite(low) and np.isfinite(high) and low >= 0:  # the common case, without masks (Illum: 0.5 GB)
            return cls()
        nan = np.isnan(raw)
        posinf = np.isposinf(raw)
        neginf = np.isneginf(raw)
        negative = raw < 0  # False for NaN, True for -inf
        bad = nan | posinf | negative
        return cls(
            nan=int(nan.sum()),
            posinf=int(posinf.sum()),
            neginf=int(neginf.sum()),
            negative=int(negative.sum()) - int(neginf.sum()),
            pixels=int((bad.any(axis=2) if bad.ndim == 3 else bad).sum()),
        )

    @property
    def values(self) -> int:
        """All unrecorded values."""
        return self.nan + self.posinf + self.neginf + self.negative

    def describe(self) -> str:
        """E.g. ``"1234 NaN, 5 +inf and 17 negative pixel values (in 1240 pixels)"``."""
        parts = [
            f"{n} {what}"
            for n, what in (
                (self.nan, "NaN"),
                (self.posinf, "+inf"),
                (self.neginf, "-inf"),
                (self.negative, "negative"),
            )
            if n
        ]
        listed = ", ".join(parts[:-1]) + f" and {parts[-1]}" if len(parts) > 1 else (parts[0] if parts else "no bad")
        return f"{listed} pixel values (in {self.pixels} pixels)"

    def to_dict(self) -> dict:
        """Plain data for sidecars."""
        return {**dataclasses.asdict(self), "values": self.values}


@dataclass(frozen=True, kw_only=True, eq=False)
class Capture:
    """A raw lenslet image with the parameters it was taken with, checked (:func:`read_capture`).

    Parameters
    ----------
    raw_path : Path
        The raw image file (named in every message).
    raw : ndarray, float32, shape (H, W) or (H, W, C)
        The raw image as read, made read-only. Unrecorded values (see ``nonfinite``) are kept as
        they are: use :attr:`recorded`.
    camera : LightFieldCamera or None
        The camera; its sensor must be (W, H). None only for commands that need none.
    port : FlatPort or None
    ideal : PinholeCamera or None
        The refraction-free image geometry the sidecar gives (:attr:`output` has the default).
    pose : Pose or None
    sidecar_path : Path or None
        The sidecar read, if any.
    sidecar : dict or None
        Its content, as read (not to be modified).
    camera_source : str
        Where the camera comes from, for messages (the sidecar, a file, a preset).
    nonfinite : {"refuse", "mask"}
        What to do with NaN, infinite and negative raw values.
    developed : DevelopedCapture or None
        For a Lytro capture: the developed mosaic (:func:`lfrefract.formats.whites.develop`), whose
        per-pixel ``values`` a colour-by-colour synthesis gathers from; ``raw`` is its demosaiced
        ``image``.

    Attributes
    ----------
    unrecorded : UnrecordedValues
        Their counts.
    recorded : ndarray of bool, shape (H, W), or None
        With ``nonfinite="mask"`` and any unrecorded value: False at the pixels holding one.
        None when every pixel is recorded.

    Raises
    ------
    FileFormatError
        If the raw image does not match the camera's sensor, or holds unrecorded values and
        ``nonfinite`` is ``"refuse"`` (the message gives their counts).
    ParameterError
        If a value has the wrong type.
    """

    raw_path: Path
    raw: np.ndarray
    camera: LightFieldCamera | None
    port: FlatPort | None = None
    ideal: PinholeCamera | None = None
    pose: Pose | None = None
    sidecar_path: Path | None = None
    sidecar: dict | None = None
    camera_source: str = "the camera given"
    nonfinite: str = "refuse"
    developed: DevelopedCapture | None = None
    unrecorded: UnrecordedValues = field(init=False)
    recorded: np.ndarray | None = field(init=False)

    def __post_init__(self) -> None:
        one_of("nonfinite", self.nonfinite, NONFINITE_POLICIES)
        for name, value, kind in (
            ("camera", self.camera, LightFieldCamera),
            ("port", self.port, FlatPort),
            ("ideal", self.ideal, PinholeCamera),
            ("pose", self.pose, Pose),
        ):
            if value is not None and not isinstance(value, kind):
                raise ParameterError(f"{name} must be a {kind.__name__} or None, got {value!r}")
        raw = np.asarray(self.raw)
        if raw.ndim not in (2, 3) or not np.issubdtype(raw.dtype, np.floating):
            raise ParameterError(f"raw must be a float (H, W) or (H, W, C) image, got {raw.dtype} {raw.shape}")
        raw = raw.view()
        raw.setflags(write=False)
        name = str(self.raw_path)
        if self.camera is not None:
            sensor = (self.camera.sensor.height_px, self.camera.sensor.width_px)
            if raw.shape[:2] != sensor:
                raise FileFormatError(
                    f"{name!r} is {raw.shape[1]} x {raw.shape[0]} px, but the camera ({self.camera_source}) has a "
                    f"{sensor[1]} x {sensor[0]} px sensor"
                )
        self._check_range(raw, name)
        counts = UnrecordedValues.of(raw)
        recorded = None
        if counts.values:
            if self.nonfinite == "refuse":
                raise FileFormatError(
                    f"{name!r} has {counts.describe()}; pass --nonfinite mask (nonfinite='mask') to treat those "
                    "pixels as unrecorded"
                )
            recorded = np.all(np.isfinite(raw) & (raw >= 0), axis=2) if raw.ndim == 3 else np.isfinite(raw) & (raw >= 0)
            recorded.setflags(write=False)
        object.__setattr__(self, "raw", raw)
        object.__setattr__(self, "raw_path", Path(self.raw_path))
        object.__setattr__(self, "unrecorded", counts)
        object.__setattr__(self, "recorded", recorded)

    @staticmethod
    def _check_range(raw: np.ndarray, name: str) -> None:
        """Refuse finite values above :data:`MAX_RAW_VALUE` (NaN and infinities are ``nonfinite``'s)."""
        top = float(np.nanmax(raw, initial=-np.inf))  # inf if any value is +inf
        if top <= MAX_RAW_VALUE:
            return
        finite = np.isfinite(raw)
        large = finite & (raw > MAX_RAW_VALUE)
        if not large.any():
            return
        largest = float(raw[large].max())
        raise FileFormatError(
            f"{name!r} has {int(large.sum())} values above {MAX_RAW_VALUE:g} (the largest {largest:g}): "
            "later steps scale raw values in float32, where they would overflow to infinity; scale the image down "
            "(any unit of radiance is taken)"
        )

    @property
    def output(self) -> PinholeCamera:
        """The refraction-free (and conventional) image geometry: :attr:`ideal`, else
        :func:`virtual_camera_for` of the camera."""
        if self.ideal is not None:
            return self.ideal
        if self.camera is None:
            raise ParameterError(f"{str(self.raw_path)!r}: no camera, so no default image geometry")
        return virtual_camera_for(self.camera)

    @property
    def ray_recorded(self) -> np.ndarray | None:
        """Raw pixels holding a measurement whose ray is the camera model's, shape (H, W), or None for all.

        :attr:`recorded`, and for a Lytro capture developed by a white image its fully lit pixels
        (:attr:`lfrefract.formats.whites.DevelopedCapture.fully_lit`): a stop vignettes the others in
        part (a real lens's micro-images are smaller than the thin lens's usable disc), so their light
        passes the aperture off the point the model gives their ray.
        """
        if self.developed is None or self.developed.white is None:
            return self.recorded
        lit = self.developed.fully_lit
        return lit if self.recorded is None else self.recorded & lit

    @property
    def channels(self) -> int:
        """Channels of the raw image (1 for a 2-D one)."""
        return 1 if self.raw.ndim == 2 else int(self.raw.shape[2])

    def masked_summary(self) -> dict | None:
        """What was masked, for sidecars (None when nothing was): the counts and the policy."""
        if self.recorded is None:
            return None
        lytro = bool(self.sidecar) and "lytro" in (self.sidecar or {})
        policy = (
            "a Lytro capture's saturated pixels, its white image's bad pixels and the pixels the white does not light"
            if lytro
            else "--nonfinite mask"
        )
        return {"policy": f"masked as unrecorded ({policy})", **self.unrecorded.to_dict()}


@dataclass(frozen=True, kw_only=True, eq=False)
class CaptureParameters:
    """What a capture was taken with, from its sidecar and the options, before its raw image is
    read (:func:`capture_parameters`); the fields of :class:`Capture` of the same names."""

    raw_path: Path
    camera: LightFieldCamera | None
    port: FlatPort | None
    ideal: PinholeCamera | None
    pose: Pose | None
    sidecar_path: Path | None
    sidecar: dict | None
    camera_source: str


def capture_parameters(
    raw_path: str | os.PathLike,
    *,
    camera: LightFieldCamera | None = None,
    port: FlatPort | None = None,
    camera_required: bool = True,
) -> CaptureParameters:
    """The parameters of the capture of ``raw_path``, checked, without reading the raw image.

    Its sidecar is the ``meta.json`` beside it, if there is one (:func:`read_sidecar`); a given
    ``camera`` or ``port`` replaces the sidecar's. See :func:`read_capture` for the parameters.

    Raises
    ------
    FileFormatError
        If the sidecar is unreadable or a key of it is invalid, or no camera is given or found
        (when ``camera_required``); the message names the file and the key.
    ParameterError
        For an option of the wrong type.
    """
    if camera is not None and not isinstance(camera, LightFieldCamera):
        raise ParameterError(f"camera must be a LightFieldCamera, got {camera!r}")
    if port is not None and not isinstance(port, FlatPort):
        raise ParameterError(f"port must be a FlatPort, got {port!r}")
    raw_path = Path(raw_path)
    if is_lytro_file(raw_path):  # the file is the whole capture: its metadata, no sidecar
        lytro = read_lytro_file(raw_path)
        return CaptureParameters(
            raw_path=raw_path,
            camera=lytro.camera if camera is None else camera,
            port=port,
            ideal=None,
            pose=None,
            sidecar_path=None,
            sidecar=None,
            camera_source="the camera given" if camera is not None else f"the metadata of {str(raw_path)!r}",
        )
    if raw_path.is_dir():  # a capture folder: its raw image
        raw_path = raw_path / RAW_NAME
    sidecar_path = raw_path.parent / SIDECAR_NAME
    if sidecar_path.exists() and not sidecar_path.is_file():
        raise FileFormatError(f"{str(sidecar_path)!r} (the sidecar beside {str(raw_path)!r}) is not a file")
    sidecar = read_sidecar(sidecar_path, camera_required=False) if sidecar_path.exists() else None
    if camera is None and camera_required:
        if sidecar is not None and sidecar.camera is None:
            raise FileFormatError(
                f"{str(sidecar_path)!r} has no key 'camera' (the camera {str(raw_path)!r} was taken with), and no "
                "camera was given (--camera PRESET|FILE)"
            )
        if sidecar is None:
            if (problem := file_problem(raw_path)) is not None:
                raise FileFormatError(problem)
            raise FileFormatError(
                f"{str(raw_path)!r} has no {SIDECAR_NAME} beside it ({str(sidecar_path)!r}) and no camera was given "
                "(--camera PRESET|FILE)"
            )
    if camera is not None:
        source = "the camera given"
    elif sidecar is not None and sidecar.camera is not None:
        source = f"{str(sidecar.path)!r}"
    else:
        source = "none"
    return CaptureParameters(
        raw_path=raw_path,
        camera=camera if camera is not None else (None if sidecar is None else sidecar.camera),
        port=port if port is not None else (None if sidecar is None else sidecar.port),
        ideal=None if sidecar is None else sidecar.ideal,
        pose=None if sidecar is None else sidecar.pose,
        sidecar_path=None if sidecar is None else sidecar.path,
        sidecar=None if sidecar is None else sidecar.data,
        camera_source=source,
    )


def read_capture(
    raw_path: str | os.PathLike,
    *,
    camera: LightFieldCamera | None = None,
    port: FlatPort | None = None,
    nonfinite: str = "refuse",
    camera_required: bool = True,
    white: str | os.PathLike | WhiteImage | None = None,
) -> Capture:
    """Read a capture: the raw image and the sidecar ``meta.json`` beside it, a bare raw image, or a
    Lytro file (:func:`read_lytro_capture`).

    Parameters
    ----------
    raw_path : path-like
        The raw lenslet image (OpenEXR, float, (H, W) or (H, W, 3)), a capture folder (its
        ``raw.exr``), or a Lytro file (``.lfr``, or ``.raw`` with its metadata beside it).
    camera : LightFieldCamera, optional
        The camera, replacing the sidecar's (needed when there is no sidecar, or it has no camera).
    port : FlatPort, optional
        The port, replacing the sidecar's.
    nonfinite : {"refuse", "mask"}
        NaN, infinite and negative raw values: refuse the image (default), or mark their pixels as
        unrecorded (:attr:`Capture.recorded`).
    camera_required : bool
        Whether a capture without a camera is an error (``lfrefract calibrate mla`` needs none).
    white : path-like or WhiteImage, optional
        For a Lytro file: its white image, or a folder of them (:func:`read_lytro_capture`).

    Returns
    -------
    Capture

    Raises
    ------
    FileFormatError
        If a file is missing or unreadable, a key of the sidecar is missing or invalid (the message
        names the file and the key), the raw image does not match the camera, or it holds
        unrecorded values and ``nonfinite="refuse"``.
    ParameterError
        For an invalid option.
    """
    one_of("nonfinite", nonfinite, NONFINITE_POLICIES)
    if is_lytro_file(raw_path):
        return read_lytro_capture(raw_path, camera=camera, port=port, white=white)
    if white is not None:
        raise ParameterError(
            f"white {str(white)!r} (--white): a white image develops a Lytro capture (.lfr, .raw); "
            f"{str(raw_path)!r} is a linear raw image already: leave the white image out"
        )
    parameters = capture_parameters(raw_path, camera=camera, port=port, camera_required=camera_required)
    raw = read_exr(parameters.raw_path)
    fields = {f.name: getattr(parameters, f.name) for f in dataclasses.fields(CaptureParameters)}
    return Capture(raw=raw, nonfinite=nonfinite, **fields)


@dataclass(frozen=True, kw_only=True)
class WhiteChoice:
    """The white image :func:`white_for` chose for a capture, and why.

    Attributes
    ----------
    white : WhiteImage
    field : FlatField
        Its flat field (:meth:`WhiteImage.flat_field`).
    shift_px : float
        How far its micro-image centres lie from the capture's, by the two files' metadata
        (:func:`lfrefract.formats.whites.micro_image_shift_px`), pixels.
    passed_over : tuple of (str, str)
        Files of the folder nearer the capture's lens setting that were not taken, and why (no white
        image, another sensor, micro-images too far off).
    """

    white: WhiteImage
    field: FlatField
    shift_px: float
    passed_over: tuple[tuple[str, str], ...] = ()


def white_for(
    white: str | os.PathLike | WhiteImage,
    *,
    zoom_step: int,
    focus_step: int,
    camera: LightFieldCamera,
    capture: Path | None = None,
) -> WhiteChoice:
    """The white image ``white`` names for a capture of ``camera`` at lens steps ``zoom_step`` and
    ``focus_step``: a white-image file, or a folder of them.

    From a folder the files are tried nearest setting first (:func:`lfrefract.formats.whites.select_white_image`'s
    order: zoom, then focus, then name), and the first that is a white image of the capture's sensor
    whose micro-image centres lie within :data:`lfrefract.formats.whites.MAX_WHITE_SHIFT_PX` of the
    capture's is taken; the ones passed over are named in the result. The ``capture`` itself is never
    its own white. A file named alone must pass the same tests.

    Raises
    ------
    FileFormatError
        If no file qualifies: the message names each file and why.
    """
    if isinstance(white, WhiteImage):
        candidates, folder = [white], None
    else:
        path = existing_path(white, "white image")
        if path.is_dir():
            folder = path
            found = find_white_images(path)
            if capture is not None:
                found = [w for w in found if not same_file(w.path, capture)]
            if not found:
                raise FileFormatError(f"white-image folder {str(path)!r} holds no white image but the capture itself")
            candidates = sorted(
                found, key=lambda w: (abs(w.zoom_step - zoom_step), abs(w.focus_step - focus_step), w.path.name)
            )
        else:
            if capture is not None and same_file(path, capture):
                raise FileFormatError(f"{str(path)!r} is the capture itself, not its white image")
            candidates, folder = [WhiteImage.from_file(path)], None
    passed: list[tuple[str, str]] = []
    sensor = (camera.sensor.height_px, camera.sensor.width_px)
    for candidate in candidates:
        try:
            field, white_camera, problem = candidate.prepared()
        except FileFormatError as exc:
            if folder is None:
                raise
            passed.append((str(candidate.path), str(exc)))
            continue
        if problem is not None:
            if folder is None:
                raise FileFormatError(f"{str(candidate.path)!r} is no white image: {problem}")
            why = f"it is no white image: {problem}"
        elif field.shape != sensor:
            why = f"its sensor is {field.shape[1]} x {field.shape[0]} px, the capture's {sensor[1]} x {sensor[0]} px"
        else:
            shift = micro_image_shift_px(camera, white_camera)
            if shift <= MAX_WHITE_SHIFT_PX:
                return WhiteChoice(white=candidate, field=field, shift_px=shift, passed_over=tuple(passed))
            why = (
                f"its micro-image centres lie up to {shift:.2f} px from the capture's (zoom step "
                f"{candidate.zoom_step}, focus step {candidate.focus_step}; the capture's {zoom_step}, {focus_step}); "
                f"at most {MAX_WHITE_SHIFT_PX:g} px is taken: use the white of the capture's lens setting"
            )
        if folder is None:
            raise FileFormatError(f"white image {str(candidate.path)!r} does not fit the capture: {why}")
        passed.append((str(candidate.path), why))
    reasons = "; ".join(f"{file!r}: {why}" for file, why in passed)
    raise FileFormatError(f"white-image folder {str(folder)!r} holds no white image for this capture: {reasons}")


def _lytro_colour(metadata: dict, where: str) -> tuple[np.ndarray, tuple[float, float, float]]:
    """The colour matrix (``image.color.ccm``, the F01's ``ccmRgbToSrgbArray``) and the R, G, B white
    balance gains of a Lytro file's metadata (:func:`lfrefract.formats.lytro.colour_from_metadata`: a
    missing or malformed one is refused, not read as identity and 1)."""
    return colour_from_metadata(metadata, where=where)


def read_lytro_capture(
    path: str | os.PathLike,
    *,
    camera: LightFieldCamera | None = None,
    port: FlatPort | None = None,
    white: str | os.PathLike | WhiteImage | None = None,
) -> Capture:
    """Read a Lytro capture (Illum ``.lfr``, or ``.raw`` with its metadata) and develop it for the core.

    The file is the whole capture: its camera comes from its metadata (unless ``camera`` is given),
    and no ``meta.json`` is read. The mosaic is developed (:func:`lfrefract.formats.whites.develop`):
    black subtracted, devignetted by the white image when one is given (a file, or a folder of white
    images from which the one of the nearest zoom and focus steps is taken), demosaiced to camera
    RGB; its saturated pixels and the white's bad pixels are unrecorded (NaN, with
    :attr:`Capture.recorded` False: the commands give them no weight and report them).

    Returns
    -------
    Capture
        ``raw`` (H, W, 3) float32; ``sidecar`` holds ``lytro``: the file, the metadata's lens steps,
        the white image used (with its steps) and the counts of saturated and bad pixels.

    Raises
    ------
    FileFormatError
        If a file is missing or malformed, or the white image does not match the capture's sensor.
    """
    path = Path(path)
    lytro = read_lytro_file(path)
    steps = lens_steps(lytro.metadata, repr(str(path)))
    chosen = None
    flat = None
    choice = None
    if white is not None:
        known_steps = all(isinstance(v, int) and not isinstance(v, bool) for v in steps.values())
        if not known_steps and not isinstance(white, WhiteImage) and existing_path(white, "white image").is_dir():
            raise FileFormatError(f"{str(path)!r} has no lens steps (devices.lens): name the white image itself")
        choice = white_for(
            white,
            zoom_step=steps["zoomStep"] or 0,
            focus_step=steps["focusStep"] or 0,
            camera=lytro.camera,
            capture=path,
        )
        chosen, flat = choice.white, choice.field
    matrix, gains = _lytro_colour(lytro.metadata, repr(str(path)))
    try:
        developed = develop(lytro.mosaic, flat, white_image=chosen, color_matrix=matrix, white_balance_gain=gains)
    except ParameterError as exc:
        raise FileFormatError(f"{str(path)!r}: {exc}") from None
    summary = {
        "file": str(path),
        "zoom_step": steps["zoomStep"],
        "focus_step": steps["focusStep"],
        "white": None
        if choice is None
        else {
            "file": str(choice.white.path),
            "zoom_step": choice.white.zoom_step,
            "focus_step": choice.white.focus_step,
            "micro_image_shift_px": round(choice.shift_px, 3),
            "passed_over": [{"file": file, "reason": why} for file, why in choice.passed_over],
        },
        "saturated_pixels": int(developed.saturated.sum()),
        "bad_white_pixels": int(developed.bad.sum()),
    }
    return Capture(
        raw_path=path,
        raw=developed.image,
        camera=lytro.camera if camera is None else camera,
        port=port,
        sidecar={"lytro": summary},
        camera_source="the camera given" if camera is not None else f"the metadata of {str(path)!r}",
        nonfinite="mask",
        developed=developed,
    )


def _json_key(path: Path, key: str, what: str, data: dict | None = None) -> dict:
    """The table ``key`` of the lfrefract JSON file ``path`` (``what`` names the option); ``data``:
    the file's content, if it was read already."""
    data = read_json(path) if data is None else data
    if key not in data:
        raise FileFormatError(f"{str(path)!r} has no key {key!r}: it is not {what}")
    value = data[key]
    if not isinstance(value, dict):
        raise FileFormatError(f"{str(path)!r}: key {key!r} must be a table (a JSON object), got {value!r}")
    return value


def camera_model_from_option(value: str | os.PathLike) -> CameraModel:
    """The camera model a ``--camera`` option names, its file read once.

    ``value`` is an existing camera file, else a preset name (:data:`lfrefract.optics.presets.PRESETS`,
    the thin lens). A camera file is TOML with a ``[camera]`` table, or lfrefract JSON whose
    ``camera`` table is read (:func:`lfrefract.formats.paramfile.read_camera_file`: a render's
    ``meta.json``, ``lfrefract describe PRESET --json`` output, ``lfrefract calibrate mla`` output),
    of the thin lens too, or a camera calibration (``lfrefract calibrate camera`` output, kind
    ``lfrefract.calibrate.camera``, of any suffix but ``.toml``), which adds its ray model: its
    ``correction``, the radial model's ``correction_covariance`` (None where the file has none:
    written before it was recorded; only a refinement needs it, :meth:`CameraModel.estimate`) and
    its ``correction_spread`` rows (none, shape (0, n), where the file has none: a port's covariance
    then leaves the camera model out). A JSON file of another kind holding a ray model is refused
    (:func:`lfrefract.formats.paramfile.read_parameter_json`). The real main lens a render's
    ``meta.json`` records is kept as :attr:`CameraModel.main_lens` (:func:`check_lens_modelled`),
    and its prescription (:func:`recorded_prescription`) is traced: the model is the render's true
    rays (:class:`~lfrefract.optics.real_lens.TracedLens`, ray model ``"traced"``) on the camera
    with the lens's micro-image lattice (:attr:`~lfrefract.optics.real_lens.RealLensCamera.lattice_camera`,
    what an MLA calibration of its white measures), what a calibration from data is measured against.

    Returns
    -------
    CameraModel
        With :attr:`~CameraModel.source` ``str(value)``.

    Raises
    ------
    FileFormatError
        If the file is not a camera file, its ``camera`` is missing or invalid, a camera
        calibration's ``correction``, ``correction_covariance`` or ``correction_spread`` is missing or
        invalid, or the file's kind and content disagree; the message names the file and the key.
    ParameterError
        If ``value`` is neither a file nor a preset.

    Examples
    --------
    >>> camera_model_from_option("tiny").ray_model
    'thin-lens'
    """
    path = Path(value)
    if path.is_file():
        if path.suffix.lower() == ".toml":  # a TOML file holds a [camera] only
            return CameraModel(camera=read_camera_file(path), source=str(value))
        data = read_parameter_json(path)
        correction, covariance, spread, colour = None, None, None, None
        if data.get("kind") == CAMERA_CALIBRATION_KIND:
            correction, covariance, spread = _calibrated_rays(path, data)
            colour = data.get("board_colour")
            if colour not in (None, *BOARD_COLOURS):
                where = f"{str(path)!r}: board_colour"
                raise FileFormatError(f"{where} must be one of {BOARD_COLOURS}, got {shown(colour)}")
        camera = camera_from_json(path, data)
        lens = None if correction is not None else recorded_prescription(path, data)
        if lens is not None:  # a render's truth: its main lens traced, indexed by its micro-images
            try:
                correction = TracedLens(real=RealLensCamera(camera=camera, lens=lens))
            except ParameterError as exc:
                raise FileFormatError(f"{str(path)!r}: scene.lens does not fit its camera: {exc}") from None
            camera = correction.camera
        return CameraModel(
            camera=camera,
            correction=correction,
            covariance=covariance,
            spread=spread,
            source=str(value),
            main_lens=recorded_main_lens(data),
            board_colour=colour,
        )
    if str(value) in PRESETS:
        return CameraModel(camera=camera_preset(str(value)), source=str(value))
    raise ParameterError(
        f"--camera must be a preset ({', '.join(sorted(PRESETS))}) or a JSON or TOML camera file, got {str(value)!r}"
    )


def _calibrated_rays(path: Path, data: dict) -> tuple[Correction, np.ndarray | None, np.ndarray]:
    """The ``correction`` of a camera calibration's content ``data`` (read from ``path``), the radial
    model's ``correction_covariance`` (None if the file has none, or for the polynomial model, which
    carries no radial covariance) and its ``correction_spread`` rows ((0, n) if the file has none);
    every message names the file and the key."""
    try:
        correction = correction_from_dict(
            _json_key(path, "correction", "--camera", data), where=f"{str(path)!r}: correction"
        )
        covariance = None
        if isinstance(correction, RayCorrection) and "correction_covariance" in data:
            covariance = CorrectionEstimate.covariance_from_dict(
                data["correction_covariance"], where=f"{str(path)!r}: correction_covariance"
            )
    except ParameterError as exc:
        raise FileFormatError(str(exc)) from None
    n = correction.vector().size
    if "correction_spread" not in data:
        return correction, covariance, np.zeros((0, n))
    where = f"{str(path)!r}: correction_spread"
    table = data["correction_spread"]
    rows = table.get("rows") if isinstance(table, dict) else None
    if not isinstance(rows, list) or not all(isinstance(r, list) and len(r) == n for r in rows):
        raise FileFormatError(
            f"{where}.rows must be rows of {n} numbers (the correction's parameters), got {shown(rows)}"
        )
    try:
        spread = np.array(rows, dtype=np.float64).reshape(len(rows), n)
    except (TypeError, ValueError):
        raise FileFormatError(f"{where}.rows must hold numbers only") from None
    if not np.all(np.isfinite(spread)):
        raise FileFormatError(f"{where}.rows must be finite")
    return correction, covariance, spread


def _given(model: CameraModel | None) -> str:
    """How a message names the camera model: ``--camera 'VALUE'``, or the capture's own camera."""
    if model is None or model.source is None:
        return "the capture's camera"
    return f"--camera {model.source!r}"


def check_port_ray_model(port_path: str | os.PathLike, model: CameraModel) -> None:
    """Refuse a calibrated port with another ray model than the one it was calibrated on.

    A port is calibrated on one ray model of the camera (``lfrefract calibrate port`` records it in
    its JSON as ``ray_model``); with another, its normal and distance are wrong for the rays. Port
    files that record none (a flat-port ``.txt``, TOML, a render's ``meta.json``, a port calibration
    of an earlier lfrefract) pass; a ``ray_model`` in a file of another kind is refused
    (:func:`lfrefract.formats.paramfile.read_parameter_json`).

    Parameters
    ----------
    port_path : path-like
        The ``--port`` file.
    model : CameraModel
        The camera model the port is to be used with (``--camera``'s; its :attr:`~CameraModel.source`
        names it in the message).

    Raises
    ------
    ParameterError
        If the port records a different ray model.
    FileFormatError
        If its ``ray_model`` is not valid.
    """
    path = Path(port_path)
    if path.suffix.lower() in (".txt", ".toml"):  # as read_port_file reads them: no ray model
        return
    data = read_parameter_json(path)  # a ray_model only in a port calibration
    if "ray_model" not in data:
        return
    table = data["ray_model"]
    if not isinstance(table, dict) or "correction" not in table:
        raise FileFormatError(f"{str(path)!r}: ray_model must be a table with a correction (or null), got {table!r}")
    try:
        recorded = (
            None
            if table["correction"] is None
            else correction_from_dict(table["correction"], where=f"{str(path)!r}: ray_model.correction")
        )
    except ParameterError as exc:
        raise FileFormatError(str(exc)) from None
    correction = model.correction
    same = (recorded is None and correction is None) or (
        recorded is not None
        and correction is not None
        and type(recorded) is type(correction)
        and recorded.vector().shape == correction.vector().shape
        and np.allclose(recorded.vector(), correction.vector(), rtol=0.0, atol=1e-12)
    )
    if not same:
        calibrated_on = table.get("camera", "a camera file")
        raise ParameterError(
            f"--port {str(path)!r} was calibrated on the ray model of {calibrated_on!r} "
            f"({'the thin lens' if recorded is None else 'a calibrated correction'}), not on that of {_given(model)} "
            f"({'the thin lens' if correction is None else 'another correction'}): give the camera "
            "file the port was calibrated with (after --refine-camera: the refined one)"
        )


def recorded_main_lens(data: Mapping | None) -> str | None:
    """The real (multi-element) main lens a capture's sidecar, or a camera file, says the camera
    has: its name; None for the thin lens, or where the file records no lens.

    ``lfsim render`` records it in its ``meta.json`` twice: ``scene.lens`` (``"thin"``, or the
    prescription: a table with its ``name``) and ``derived.main_lens`` (null, or a summary of the
    lens with its ``name``).
    """
    if not isinstance(data, Mapping):
        return None
    found = []
    scene, derived = data.get("scene"), data.get("derived")
    if isinstance(scene, Mapping) and isinstance(scene.get("lens"), Mapping):
        found.append(scene["lens"].get("name"))
    if isinstance(derived, Mapping) and isinstance(derived.get("main_lens"), Mapping):
        found.append(derived["main_lens"].get("name"))
    if not found:
        return None
    return next((name for name in found if isinstance(name, str) and name), "an unnamed prescription")


def recorded_prescription(path: str | os.PathLike, data: Mapping | None) -> LensPrescription | None:
    """The real main lens's prescription a render's ``meta.json`` content ``data`` records
    (``scene.lens``, a table; ``"thin"`` or nothing: None), read from ``path``.

    Raises
    ------
    FileFormatError
        If ``scene.lens`` is a table that is no valid prescription (the message names the file and key).
    """
    scene = data.get("scene") if isinstance(data, Mapping) else None
    table = scene.get("lens") if isinstance(scene, Mapping) else None
    if not isinstance(table, Mapping):
        return None
    try:
        return LensPrescription.from_dict(dict(table))
    except ParameterError as exc:
        raise FileFormatError(f"{str(path)!r}: scene.lens is no valid lens prescription: {exc}") from None


def check_lens_modelled(capture: Capture | CaptureParameters, model: CameraModel | None) -> None:
    """Refuse a capture taken through a real main lens when the camera model is the bare thin lens.

    The core's camera model is a thin lens, plus the ray correction of a camera calibration
    (``lfrefract calibrate camera`` output). A render through a real lens (``lfsim render --lens
    double-gauss``) records that lens (:func:`recorded_main_lens`), and the thin lens it is scaled to
    does not give its rays: a synthesis or a port fit on it is wrong without saying so (the board
    of a double-Gauss render was not found in the refraction-free image). The core does not trace
    the recorded prescription unless asked (``--camera`` the render's ``meta.json``: its true rays,
    :func:`camera_model_from_option`): a user's ray model comes from calibration on data, which
    holds for any lens.

    Parameters
    ----------
    capture : Capture or CaptureParameters
        Its sidecar (if any) is read for the lens.
    model : CameraModel or None
        The camera model of ``--camera`` (None: none given, the capture's own camera, the thin
        lens): the real main lens its file records (:attr:`CameraModel.main_lens`, a render's
        ``meta.json``) is checked too.

    Raises
    ------
    ParameterError
        If the capture's sidecar or the camera file records a real main lens and the model is the thin lens.
    """
    if model is not None and model.correction is not None:
        return
    sources: list[tuple[str, str | None, str]] = []
    if capture.sidecar_path is not None:
        sources.append(
            (
                str(capture.sidecar_path),
                recorded_main_lens(capture.sidecar),
                f"the capture {str(capture.raw_path)!r} was taken",
            )
        )
    if model is not None and model.source is not None:
        sources.append((model.source, model.main_lens, "the camera of --camera was taken"))
    for path, lens, what in sources:
        if lens is not None:
            given = "the thin lens of its camera" if model is None else f"{_given(model)}, a thin lens"
            raise ParameterError(
                f"{path!r} says {what} through the real main lens {lens!r}, but the camera model is "
                f"{given} with no calibrated ray model: its rays are not that lens's, and the result would be "
                "wrong without saying so. Calibrate the camera from in-air boards (lfrefract calibrate camera "
                "BOARD ... --out camera.json) and pass --camera camera.json (or, for a render, --camera its meta.json: "
                "its recorded lens traced, the true rays)"
            )


def port_from_file(path: str | os.PathLike) -> FlatPort:
    """The port of a port file (:func:`lfrefract.formats.paramfile.read_port_file`): TOML with a
    ``[port]`` table (by tilt angles or by normal), a ``.txt`` in the flat-port layout of Refractive
    COLMAP / calibmar (what ``lfrefract calibrate port`` writes beside its JSON), or a JSON file with
    a ``port`` table (``lfrefract calibrate port`` output, a render's ``meta.json``).

    Raises
    ------
    FileFormatError
        If the file is missing, not of any of these kinds, or its port is missing, null or invalid.
    """
    return read_port_file(path)


def mla_from_file(path: str | os.PathLike):
    """The MLA calibration of a ``lfrefract calibrate mla`` output (its ``mla`` table).

    Returns
    -------
    lfrefract.calibration.MlaCalibration

    Raises
    ------
    FileFormatError
        If the file is missing, not lfrefract JSON, or its ``mla`` is missing or invalid.
    """
    from lfrefract.calibration import MlaCalibration

    path = Path(path)
    data = read_parameter_json(path)  # an mla only in an MLA calibration
    return _parse(path, "mla", _json_key(path, "mla", "an MLA calibration", data), MlaCalibration.from_dict)


def apply_depth_aware(synthesis: DepthAwareSynthesis, capture: Capture) -> DepthAwareResult:
    """The depth-aware synthesis of a capture as read (:meth:`DepthAwareSynthesis.apply
    <lfrefract.synthesis.depth_aware.DepthAwareSynthesis.apply>`), as ``lfrefract synth`` runs it.

    The rays used are those whose value and ray are the camera model's (:attr:`Capture.ray_recorded`).
    A Lytro capture's depth is searched on its mosaic, not demosaiced
    (:meth:`~lfrefract.formats.whites.DevelopedCapture.grey`: demosaicing mixes each pixel with its
    neighbours, other rays of the same micro-image), each colour's sites compared only with each
    other (a coloured texture's neighbouring sites of different colours differ); its image is
    rendered from the demosaiced raw. Through the double Gauss at tiny-2x this took the search's median
    confidence from 0.09 to 0.66 (tests/simulator/test_depth_aware_real_lens.py).

    Parameters
    ----------
    synthesis : DepthAwareSynthesis
        Built for the capture's camera and port.
    capture : Capture
        The capture (:func:`read_capture`).

    Returns
    -------
    DepthAwareResult
    """
    developed = capture.developed
    if developed is None:
        return synthesis.apply(capture.raw, recorded=capture.ray_recorded)
    grey = developed.grey()
    search = SearchImage(raw=grey, recorded=np.isfinite(grey), groups=cfa_channels(developed.cfa_pattern, grey.shape))
    return synthesis.apply(capture.raw, recorded=capture.ray_recorded, search=search)


def mask_warp_map(warp, recorded: np.ndarray | None):
    """A warp map that gives unrecorded raw pixels no weight.

    Every entry on an unrecorded raw pixel is dropped and each row's remaining weights are
    renormalised to sum to 1, so an output pixel is the weighted mean of the recorded rays among
    those it selected. A row left with none is empty: the pixel is not filled (its value is 0 and
    :attr:`WarpMap.filled` False) and its coverage is set to 0 (the camera recorded none of its rays).

    Parameters
    ----------
    warp : lfrefract.synthesis.warp_map.WarpMap
    recorded : ndarray of bool, shape (H_raw, W_raw), or None
        :attr:`Capture.recorded`; None returns ``warp`` itself.

    Returns
    -------
    lfrefract.synthesis.warp_map.WarpMap
        Same output, key and meta (plus ``meta["unrecorded_raw_pixels"]``); not to be cached under
        that key.
    """
    if recorded is None:
        return warp
    recorded = np.asarray(recorded)
    if recorded.dtype != np.bool_ or recorded.shape != tuple(warp.raw_shape):
        raise ParameterError(
            f"recorded must be a bool array of shape {tuple(warp.raw_shape)}, got {recorded.dtype} {recorded.shape}"
        )
    n = len(warp.indptr) - 1
    counts = np.diff(warp.indptr)
    rows = np.repeat(np.arange(n), counts)
    keep = recorded.ravel()[warp.indices]
    kept_rows = rows[keep]
    total = np.bincount(kept_rows, weights=warp.weights[keep], minlength=n)
    kept_counts = np.bincount(kept_rows, minlength=n)
    indptr = np.zeros(n + 1, dtype=warp.indptr.dtype)
    np.cumsum(kept_counts, out=indptr[1:])
    weights = (warp.weights[keep] / total[kept_rows]).astype(warp.weights.dtype)
    emptied = ((counts > 0) & (kept_counts == 0)).reshape(warp.coverage.shape)
    coverage = np.where(emptied, 0.0, warp.coverage).astype(warp.coverage.dtype)
    meta = {**warp.meta, "unrecorded_raw_pixels": int(recorded.size - np.count_nonzero(recorded))}
    return dataclasses.replace(
        warp, indptr=indptr, indices=warp.indices[keep], weights=weights, coverage=coverage, meta=meta
    )


# =============================================================================== writing
@dataclass(frozen=True, kw_only=True, eq=False)
class CaptureTruth:
    """The ground truth of a rendered capture, written beside its raw image (:func:`write_capture`).

    Parameters
    ----------
    ideal : ndarray, float, shape (h, w, 3) or (h, w)
        The ideal refraction-free image, of the ``ideal`` pinhole's geometry (radiance in the water).
    depth_m : ndarray, float, shape (h, w)
        Camera-frame z of the ideal image's pixel centres, metres; +inf where no surface.
    lenses : mapping of str to ndarray, optional
        Microlens ground truth (``lens_index`` (M, 2), ``lens_centre_m`` (M, 2), ``micro_image_centre_px``
        (M, 2)), stored as ``lenses.npz``; None writes no such file.

    Raises
    ------
    ParameterError
        If an image is not real-valued of those shapes, or the two disagree in size.
    """

    ideal: np.ndarray
    depth_m: np.ndarray
    lenses: Mapping[str, np.ndarray] | None = None

    def __post_init__(self) -> None:
        ideal, depth = np.asarray(self.ideal), np.asarray(self.depth_m)
        if ideal.ndim not in (2, 3) or (ideal.ndim == 3 and ideal.shape[2] != 3) or not _real(ideal):
            raise ParameterError(
                f"ground truth ideal must be a real (h, w) or (h, w, 3) image, got {ideal.dtype} {ideal.shape}"
            )
        if depth.ndim != 2 or not _real(depth):
            raise ParameterError(f"ground truth depth_m must be a real (h, w) image, got {depth.dtype} {depth.shape}")
        if depth.shape != ideal.shape[:2]:
            raise ParameterError(
                f"ground truth depth_m is {depth.shape[1]} x {depth.shape[0]} px, its ideal image "
                f"{ideal.shape[1]} x {ideal.shape[0]} px: they must be of one size"
            )
        if self.lenses is not None and (
            not isinstance(self.lenses, Mapping) or not all(isinstance(k, str) and k for k in self.lenses)
        ):
            raise ParameterError(
                f"ground truth lenses must be a mapping of names to arrays, got {type(self.lenses).__name__}"
            )


def _real(image: np.ndarray) -> bool:
    return bool(np.issubdtype(image.dtype, np.floating) or np.issubdtype(image.dtype, np.integer))


def write_capture_files(
    folder: str | os.PathLike,
    *,
    raw: np.ndarray,
    camera: LightFieldCamera,
    port: FlatPort | None = None,
    ideal: PinholeCamera | None = None,
    pose: Pose | None = None,
    ground_truth: CaptureTruth | None = None,
    metadata: Mapping | None = None,
    kind: str = CAPTURE_KIND,
) -> dict:
    """Write the files of a capture into ``folder``, an existing directory being assembled (the stage
    of :func:`lfrefract.formats.outputs.staged_directory`); each file is written atomically.

    :func:`write_capture` is this in a staged output directory; call this one to add a capture's files
    to an output that holds more (a render's previews, a dataset sample's extras).

    Parameters
    ----------
    folder : path-like
        The directory the files go into (created if missing).
    raw : ndarray, float, shape (H, W) or (H, W, 3)
        The raw lenslet image, of the camera's sensor (H = ``camera.sensor.height_px``). NaN,
        infinite and negative values are written as they are (:func:`read_capture` refuses or masks them).
    camera : LightFieldCamera
        The camera it was taken with.
    port : FlatPort, optional
        Its port (None: in air, or not known; written as null).
    ideal : PinholeCamera, optional
        The refraction-free image geometry; required with ``ground_truth`` (the ideal image's).
    pose : Pose, optional
        The camera's pose in the world (camera to world).
    ground_truth : CaptureTruth, optional
        Writes ``ideal.exr``, ``depth.exr`` and (with lenses) ``lenses.npz``.
    metadata : mapping, optional
        The caller's own keys of the sidecar (plain data), after the capture's; it may not hold
        ``schema_version``, ``kind``, ``files``, ``camera``, ``pose``, ``port`` or ``ideal``.
    kind : str
        The sidecar's ``kind`` (and the output's, with :func:`write_capture`).

    Returns
    -------
    dict
        The sidecar as written (without ``schema_version``).

    Raises
    ------
    ParameterError
        If a value has the wrong type, the raw image does not match the camera's sensor, the ground
        truth does not match ``ideal`` (or comes without it), or ``metadata`` holds a capture key.
    """
    sidecar = _capture_sidecar(
        raw=raw,
        camera=camera,
        port=port,
        ideal=ideal,
        pose=pose,
        ground_truth=ground_truth,
        metadata=metadata,
        kind=kind,
    )
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    write_exr(folder / RAW_NAME, raw, role="raw")
    if ground_truth is not None:
        write_exr(folder / IDEAL_NAME, ground_truth.ideal, role="ideal")
        write_exr(folder / DEPTH_NAME, ground_truth.depth_m, role="depth")
        if ground_truth.lenses is not None:
            with atomic_file(folder / LENSES_NAME) as tmp, tmp.open("wb") as fh:
                arrays: dict[str, Any] = {k: np.asarray(v) for k, v in ground_truth.lenses.items()}
                np.savez_compressed(fh, **arrays)
    write_json(folder / SIDECAR_NAME, sidecar)
    return sidecar


def _capture_sidecar(*, raw, camera, port, ideal, pose, ground_truth, metadata, kind) -> dict:
    """The sidecar of :func:`write_capture_files`, every argument checked before anything is written."""
    if not isinstance(kind, str) or not kind:
        raise ParameterError(f"kind must be a non-empty string, got {kind!r}")
    for name, value, expected in (
        ("camera", camera, LightFieldCamera),
        ("port", port, FlatPort),
        ("ideal", ideal, PinholeCamera),
        ("pose", pose, Pose),
        ("ground_truth", ground_truth, CaptureTruth),
    ):
        if (value is not None or name == "camera") and not isinstance(value, expected):
            raise ParameterError(
                f"{name} must be a {expected.__name__}{'' if name == 'camera' else ' or None'}, got {value!r}"
            )
    image = np.asarray(raw)
    if (
        image.ndim not in (2, 3)
        or (image.ndim == 3 and image.shape[2] != 3)
        or not np.issubdtype(image.dtype, np.floating)
    ):
        raise ParameterError(f"raw must be a float (H, W) or (H, W, 3) image, got {image.dtype} {image.shape}")
    sensor = (camera.sensor.height_px, camera.sensor.width_px)
    if image.shape[:2] != sensor:
        raise ParameterError(
            f"raw is {image.shape[1]} x {image.shape[0]} px, but the camera has a {sensor[1]} x {sensor[0]} px sensor"
        )
    files = {"raw": RAW_NAME}
    if ground_truth is not None:
        if ideal is None:
            raise ParameterError("ground_truth needs ideal, the PinholeCamera of its ideal image")
        size = np.asarray(ground_truth.depth_m).shape
        if size != (ideal.height_px, ideal.width_px):
            raise ParameterError(
                f"ground truth images are {size[1]} x {size[0]} px, but ideal is "
                f"{ideal.width_px} x {ideal.height_px} px"
            )
        files.update(ideal=IDEAL_NAME, depth=DEPTH_NAME)
        if ground_truth.lenses is not None:
            files["lenses"] = LENSES_NAME
    if metadata is not None and not (isinstance(metadata, Mapping) and all(isinstance(k, str) for k in metadata)):
        raise ParameterError(f"metadata must be a mapping of str keys to plain data, got {metadata!r}")
    extra = dict(metadata or {})
    clash = sorted(set(extra) & {*_SIDECAR_KEYS, "schema_version"})
    if clash:
        raise ParameterError(f"metadata may not set {clash} (the capture's own keys, written here)")
    return {
        "kind": kind,
        "files": files,
        "camera": camera.to_dict(),
        "pose": None if pose is None else pose.to_dict(),
        "port": None if port is None else port.to_dict(),
        "ideal": None if ideal is None else ideal.to_dict(),
        **extra,
    }


def write_capture(
    out_dir: str | os.PathLike,
    *,
    raw: np.ndarray,
    camera: LightFieldCamera,
    port: FlatPort | None = None,
    ideal: PinholeCamera | None = None,
    pose: Pose | None = None,
    ground_truth: CaptureTruth | None = None,
    metadata: Mapping | None = None,
    kind: str = CAPTURE_KIND,
    overwrite: bool = False,
    inputs: Iterable[str | os.PathLike] = (),
) -> Path:
    """Write a capture folder: ``raw.exr`` and ``meta.json`` (and its ground truth), assembled in a
    staging directory that takes the place of ``out_dir`` only when complete
    (:func:`lfrefract.formats.outputs.staged_directory`).

    :func:`read_capture` reads it back (``read_capture(out_dir)``). See :func:`write_capture_files`
    for the parameters of the capture.

    Parameters
    ----------
    out_dir : path-like
        The folder; must be absent or empty unless ``overwrite``.
    overwrite : bool
        Replace an earlier output of the same ``kind`` that holds only the files it wrote.
    inputs : iterable of path-like
        Files the caller read: ``out_dir`` may not be one of them nor hold one.

    Returns
    -------
    Path
        ``out_dir``.

    Raises
    ------
    ParameterError
        For an invalid argument (before anything is written).
    FileExistsError
        If ``out_dir`` may not be written or replaced.
    """
    _capture_sidecar(
        raw=raw,
        camera=camera,
        port=port,
        ideal=ideal,
        pose=pose,
        ground_truth=ground_truth,
        metadata=metadata,
        kind=kind,
    )
    with staged_directory(out_dir, kind=kind, overwrite=overwrite, inputs=inputs) as stage:
        write_capture_files(
            stage,
            raw=raw,
            camera=camera,
            port=port,
            ideal=ideal,
            pose=pose,
            ground_truth=ground_truth,
            metadata=metadata,
            kind=kind,
        )
    return Path(out_dir)


def read_ground_truth(folder: str | os.PathLike) -> CaptureTruth:
    """The ground truth of a rendered capture folder: ``ideal.exr``, ``depth.exr`` and ``lenses.npz``
    (None when absent).

    Returns
    -------
    CaptureTruth
        ``ideal`` float32 (h, w, 3), or (h, w) for a grey render; ``depth_m`` float32 (h, w).

    Raises
    ------
    FileFormatError
        If an image is missing, not an EXR of its role, or not of the size the sidecar's ``ideal``
        geometry gives; or if the lens table is not a NumPy ``.npz`` archive of arrays.
    """
    folder = Path(folder)
    ideal = read_exr(folder / IDEAL_NAME, role="ideal")
    depth = read_exr(folder / DEPTH_NAME, role="depth")
    if (folder / SIDECAR_NAME).is_file():
        geometry = read_sidecar(folder / SIDECAR_NAME, camera_required=False).ideal
        if geometry is not None and ideal.shape[:2] != (geometry.height_px, geometry.width_px):
            raise FileFormatError(
                f"{str(folder / IDEAL_NAME)!r} is {ideal.shape[1]} x {ideal.shape[0]} px, but the sidecar's ideal "
                f"image is {geometry.width_px} x {geometry.height_px} px"
            )
    lenses = None
    path = folder / LENSES_NAME
    if path.is_file():
        try:
            # Our own handle: np.load of a plain .npy returns an array, and of a broken zip leaks its handle.
            with path.open("rb") as fh:
                data = np.load(fh, allow_pickle=False)
                if not isinstance(data, np.lib.npyio.NpzFile):
                    raise FileFormatError(f"{str(path)!r} is a single NumPy array, not an .npz archive of arrays")
                with data:
                    lenses = {k: data[k] for k in data.files}
        except FileFormatError:
            raise
        except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
            raise FileFormatError(f"{str(path)!r} is not a NumPy .npz archive of arrays: {exc}") from None
    try:
        return CaptureTruth(ideal=ideal, depth_m=depth, lenses=lenses)
    except ParameterError as exc:
        raise FileFormatError(f"{str(folder)!r}: {exc}") from None
