"""The methods the stereo experiments compare, by name: a registry read when an experiment runs.

A *method* turns the raw captures of a stereo rig into what the experiment measures. Its
*factory* is called once per run with the rig (:class:`MethodRig`: each camera's optics, port,
pose and warp map, and the calibration chessboards) and returns either

- :class:`CentralImages`: a central-projection image per camera and capture, with its intrinsics.
  The experiment calibrates the rig on the method's own images of the chessboards, rectifies, runs
  its stereo matchers and compares the points with the ground truth; or
- :class:`DepthMaps`: a depth map per capture in the first camera's frame. The stereo step is
  skipped for it; its depth is compared with the ground truth directly (``matcher = "none"``).

Built in, in table order (:data:`BUILTIN_METHODS`): ``approx far`` and ``approx near`` (the
approximation baseline calibrated per camera on the chessboards at the far / near depth),
``proposed`` (the refraction-free synthesis), ``proposed+distortion`` (with a residual distortion
fitted on the far boards), ``depth-aware`` (the synthesis with the pixels outside its exact coverage
rendered at a depth found in each capture's light field, :mod:`lfrefract.synthesis.depth_aware`)
and ``ideal`` (the simulator's ground-truth refraction-free images: the floor). Others are added
with :func:`register_method` or, from an installed package, through the entry-point group
``lfrefract.methods`` (:data:`ENTRY_POINT_GROUP`), whose entries name a factory::

    [project.entry-points."lfrefract.methods"]
    "my method" = "mypackage.methods:my_factory"

:func:`method_factories` reads all three sources each time it is called (nothing is fixed at
import). A factory or a projection that raises makes table rows with ``status = "failed"`` and
the error, not a failed run.
"""

from __future__ import annotations

import importlib.metadata
import re
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from lfrefract.errors import ParameterError
from lfrefract.methods import CalibrationViews, build_projector
from lfrefract.optics.camera import LightFieldCamera
from lfrefract.optics.pinhole import PinholeCamera
from lfrefract.optics.port import FlatPort
from lfrefract.optics.pose import Pose
from lfrefract.synthesis.warp_map import WarpMap
from lfrefract.validate import shown, text

__all__ = [
    "BUILTIN_METHODS",
    "ENTRY_POINT_GROUP",
    "CentralImages",
    "DepthMaps",
    "MethodCamera",
    "MethodFactory",
    "MethodRig",
    "Shot",
    "check_file_stems",
    "file_stem",
    "method_factories",
    "method_names",
    "register_method",
    "unregister_method",
]

#: Entry-point group of third-party method factories.
ENTRY_POINT_GROUP = "lfrefract.methods"


@runtime_checkable
class Shot(Protocol):
    """One capture of the rig: every camera's images, read when asked for (an Illum raw is 0.5 GB)."""

    def raw(self, camera: str) -> np.ndarray:
        """The raw lenslet image of camera ``camera``, float32 (H, W, 3)."""
        ...

    def ideal(self, camera: str) -> np.ndarray:
        """Ground truth: the camera's refraction-free pinhole image (``virtual_camera_for(camera)``)."""
        ...

    def depth(self, camera: str) -> np.ndarray:
        """Ground truth: camera-frame z along each pixel of :meth:`ideal`, metres, ``inf`` where no surface."""
        ...


@dataclass(frozen=True, kw_only=True)
class MethodCamera:
    """One camera of the rig, as a method sees it.

    Attributes
    ----------
    name : str
        The camera's name in the rig (``"left"``, ``"right"``).
    camera : LightFieldCamera
    port : FlatPort
        The wall in this camera's frame (the true port).
    pose : Pose
        Camera to world.
    warp : WarpMap
        The refraction-free synthesis's warp map with the paper's options (k = ``PAPER_K`` = 32;
        built once per run).
    """

    name: str
    camera: LightFieldCamera
    port: FlatPort
    pose: Pose
    warp: WarpMap


@dataclass(frozen=True, kw_only=True)
class MethodRig:
    """What a method factory is given.

    Attributes
    ----------
    cameras : tuple of MethodCamera
        In the rig's order; the first is the reference frame of :class:`DepthMaps`.
    calibration_depths_m : (float, float)
        The near and far depths of the chessboard captures.
    calibration : callable
        ``calibration(camera_name, depth_m) -> CalibrationViews``: that camera's raw images of
        the chessboards at one of :attr:`calibration_depths_m`, with their true corners.
    """

    cameras: tuple[MethodCamera, ...]
    calibration_depths_m: tuple[float, float]
    calibration: Callable[[str, float], CalibrationViews] = field(repr=False)

    def camera(self, name: str) -> MethodCamera:
        """The camera called ``name``."""
        for camera in self.cameras:
            if camera.name == name:
                return camera
        raise ParameterError(f"the rig has no camera {name!r}; it has {[c.name for c in self.cameras]}")

    @property
    def near_m(self) -> float:
        """The nearer calibration depth, metres."""
        return min(self.calibration_depths_m)

    @property
    def far_m(self) -> float:
        """The farther calibration depth, metres."""
        return max(self.calibration_depths_m)


@dataclass(frozen=True, kw_only=True)
class CentralImages:
    """A method that makes central-projection images (the experiment runs stereo on them).

    Attributes
    ----------
    outputs : mapping of str to PinholeCamera
        Each camera's image geometry (its ``K``; the rig calibration keeps it fixed).
    project : callable
        ``project(camera_name, shot) -> ndarray`` of shape ``(output.height_px, output.width_px)``
        (+ channels), float, NaN where the method has no value.
    """

    outputs: Mapping[str, PinholeCamera]
    project: Callable[[str, Shot], np.ndarray]


@dataclass(frozen=True, kw_only=True)
class DepthMaps:
    """A method that estimates depth itself (the stereo step is skipped for it).

    Attributes
    ----------
    output : PinholeCamera
        Geometry of the depth maps, in the first camera's frame (its centre is that camera's
        main-lens centre).
    depth : callable
        ``depth(shot) -> ndarray`` of shape ``(output.height_px, output.width_px)``: camera-frame
        z of the surface seen through each pixel, metres; NaN (or inf) where there is no estimate.
    """

    output: PinholeCamera
    depth: Callable[[Shot], np.ndarray]


#: A method factory: the rig in, a :class:`CentralImages` or :class:`DepthMaps` out.
MethodFactory = Callable[[MethodRig], "CentralImages | DepthMaps"]


# ------------------------------------------------------------------------------------ built in
def _projectors(rig: MethodRig, build: Callable[[MethodCamera], object]) -> CentralImages:
    projectors = {c.name: build(c) for c in rig.cameras}

    def project(name: str, shot: Shot) -> np.ndarray:
        return projectors[name].apply(shot.raw(name))

    return CentralImages(outputs={n: p.output for n, p in projectors.items()}, project=project)


def _approx(which: str) -> MethodFactory:
    def factory(rig: MethodRig) -> CentralImages:
        depth = rig.far_m if which == "far" else rig.near_m
        return _projectors(
            rig, lambda c: build_projector("approx", c.camera, calibration=rig.calibration(c.name, depth))
        )

    factory.__doc__ = f"The approximation baseline calibrated per camera on the chessboards at the {which} depth."
    return factory


def _proposed(rig: MethodRig) -> CentralImages:
    """The refraction-free synthesis (the warp map of the true port)."""
    return _projectors(rig, lambda c: build_projector("proposed", c.camera, c.port, warp=c.warp))


def _proposed_distortion(rig: MethodRig) -> CentralImages:
    """The synthesis with a residual distortion fitted on its images of the far chessboards."""
    return _projectors(
        rig,
        lambda c: build_projector(
            "proposed+distortion", c.camera, c.port, warp=c.warp, calibration=rig.calibration(c.name, rig.far_m)
        ),
    )


def _depth_aware(rig: MethodRig) -> CentralImages:
    """The depth-aware synthesis (the warp map of the true port, the camera's rays traced through it)."""
    return _projectors(rig, lambda c: build_projector("depth-aware", c.camera, c.port, warp=c.warp))


def _ideal(rig: MethodRig) -> CentralImages:
    """The simulator's ground-truth refraction-free images (the floor every method is held to)."""
    return CentralImages(
        outputs={c.name: c.warp.output for c in rig.cameras}, project=lambda name, shot: shot.ideal(name)
    )


#: The built-in methods, in table order.
BUILTIN_METHODS: dict[str, MethodFactory] = {
    "approx far": _approx("far"),
    "approx near": _approx("near"),
    "proposed": _proposed,
    "proposed+distortion": _proposed_distortion,
    "depth-aware": _depth_aware,
    "ideal": _ideal,
}

# Methods registered with register_method, in registration order.
_REGISTERED: dict[str, MethodFactory] = {}


def register_method(name: str, factory: MethodFactory, *, replace: bool = False) -> None:
    """Add a method to the registry (after the built-in ones, in registration order).

    Parameters
    ----------
    name : str
        Its name in tables and in ``--methods`` (not empty; no comma, which separates ``--methods``).
    factory : callable
        ``factory(rig: MethodRig) -> CentralImages | DepthMaps`` (see the module docstring).
    replace : bool
        Replace a method registered earlier under ``name`` (a built-in one cannot be replaced).

    Raises
    ------
    ParameterError
        For an empty name or one with a comma, a factory that is not callable, or a name taken.
    """
    name = text("name", name)
    if not name.strip() or "," in name or name != name.strip():
        raise ParameterError(f"a method name must be non-empty, without a comma or outer spaces, got {name!r}")
    if not callable(factory):
        raise ParameterError(f"factory of method {name!r} must be callable, got {shown(factory)}")
    if name in BUILTIN_METHODS:
        raise ParameterError(f"method {name!r} is built in; choose another name")
    if name in _REGISTERED and not replace:
        raise ParameterError(f"method {name!r} is already registered (replace=True replaces it)")
    _REGISTERED[name] = factory


def unregister_method(name: str) -> None:
    """Remove a method added by :func:`register_method` (:class:`ParameterError` if there is none)."""
    if name not in _REGISTERED:
        raise ParameterError(f"no method {name!r} was registered with register_method")
    del _REGISTERED[name]


def _failing(error: Exception, where: str) -> MethodFactory:
    def factory(rig: MethodRig):
        raise RuntimeError(f"{where} could not be loaded: {type(error).__name__}: {error}")

    return factory


def method_factories() -> dict[str, MethodFactory]:
    """Every method now: the built-in ones, then :func:`register_method`'s, then those of the
    ``lfrefract.methods`` entry points (sorted by name). An entry point that cannot be loaded is
    kept as a method that fails (its rows say why); one whose name is taken is left out, with a
    warning."""
    methods = dict(BUILTIN_METHODS) | _REGISTERED
    for entry in sorted(importlib.metadata.entry_points(group=ENTRY_POINT_GROUP), key=lambda e: e.name):
        if entry.name in methods:
            warnings.warn(
                f"entry point {entry.name!r} = {entry.value!r} of group {ENTRY_POINT_GROUP!r} is left out: "
                "a method of that name is already registered",
                stacklevel=2,
            )
            continue
        try:
            factory = entry.load()
            if not callable(factory):
                raise TypeError(f"{entry.value!r} is a {type(factory).__name__}, not a callable")
        except Exception as exc:  # a broken plugin is a failed method, not a failed run
            factory = _failing(exc, f"entry point {entry.name!r} = {entry.value!r}")
        methods[entry.name] = factory
    return methods


def file_stem(name: str) -> str:
    """The stem of a method's output files (``cloud_<stem>.ply``): its name with every run of
    characters other than ASCII letters and digits made one ``_`` (``proposed+distortion`` ->
    ``proposed_distortion``)."""
    return re.sub(r"[^A-Za-z0-9]+", "_", name).strip("_") or "_"


def check_file_stems(names: Sequence[str]) -> None:
    """Refuse methods whose output files would share a name (:func:`file_stem`), before any work.

    Raises
    ------
    ParameterError
        Naming the methods and the stem they share.
    """
    seen: dict[str, str] = {}
    for name in names:
        stem = file_stem(name)
        if stem in seen and seen[stem] != name:
            raise ParameterError(
                f"methods {seen[stem]!r} and {name!r} would write the same files (cloud_{stem}*.ply); rename one"
            )
        seen[stem] = name


def method_names() -> tuple[str, ...]:
    """Names of :func:`method_factories`, in table order."""
    return tuple(method_factories())


def check_result(name: str, result) -> CentralImages | DepthMaps:
    """``result`` if a factory may return it, else :class:`ParameterError` naming the method."""
    if not isinstance(result, (CentralImages, DepthMaps)):
        raise ParameterError(f"method {name!r} returned {shown(result)}, not CentralImages or DepthMaps")
    return result


def depth_points(depth: np.ndarray, output: PinholeCamera) -> np.ndarray:
    """The points (N, 3) of a depth map (camera z, metres; NaN / inf: none) in its camera's frame."""
    depth = np.asarray(depth, dtype=np.float64)
    if depth.shape != (output.height_px, output.width_px):
        raise ParameterError(
            f"a depth map must have shape {(output.height_px, output.width_px)} (its output geometry), "
            f"got {depth.shape}"
        )
    directions = output.pixel_directions().reshape(output.height_px, output.width_px, 3)
    valid = np.isfinite(depth) & (depth > 0)
    rays = directions[valid]
    return rays * (depth[valid] / rays[:, 2])[:, None]
