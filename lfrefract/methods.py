"""Refraction handling methods behind one interface, chosen by name.

A method turns a raw lenslet image into a central-projection image with a known pinhole ``K``
(:class:`CentralProjector`), so experiments can switch between them by name
(:data:`METHODS`, :func:`build_projector`):

``naive``
    The conventional image with no refraction handling: the central sub-aperture view
    (:func:`conventional_image`). A pinhole image in air; behind a port it is not the central
    projection its ``K`` claims.
``approx``
    The approximation baseline of paper section 3.1 (Ferreira et al. 2005): the conventional image
    undistorted with a pinhole plus radial-tangential distortion calibrated from chessboard views
    at one depth (:func:`lfrefract.calibration.approx.calibrate_approx`). Right near that depth.
``proposed``
    The refraction-free synthesis (:mod:`lfrefract.synthesis.warp_map`): exact at every depth inside the
    coverage.
``proposed+distortion``
    Paper condition (d): the synthesized image, with a residual distortion fitted on the
    synthesized images of the calibration views (``K`` fixed to the warp map's) removed.
``depth-aware``
    The depth-aware synthesis (:mod:`lfrefract.synthesis.depth_aware`): the warp map's image inside
    its exact coverage; outside it, pixels rendered from the rays that see their scene point at a
    depth estimated from the light field itself (exact given that depth), else the warp map's.

Every projector's :meth:`~CentralProjector.apply` returns float32 with NaN where it has no value
(outside the lenses' hull, or output pixels the warp map did not fill and, for ``depth-aware``,
the render given depth did not either).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np
from scipy import sparse

from lfrefract.calibration.approx import ApproxCalibration, calibrate_approx
from lfrefract.errors import ParameterError
from lfrefract.optics.camera import LightFieldCamera
from lfrefract.optics.camera_model import CameraModel, as_camera_model
from lfrefract.optics.pinhole import PinholeCamera, virtual_camera_for
from lfrefract.optics.port import FlatPort
from lfrefract.synthesis.depth_aware import DepthAwareOptions, DepthAwareSynthesis
from lfrefract.synthesis.views import (
    apply_resampling,
    micro_image_samples,
    naive_view,
    raw_channels,
    recorded_mask,
    resampling_matrix,
)
from lfrefract.synthesis.warp_map import SynthesisOptions, WarpMap, build_warp_map
from lfrefract.validate import as_points, one_of, positive_float, require_keys

__all__ = [
    "METHODS",
    "ApproxProjector",
    "CalibrationViews",
    "CentralProjector",
    "ConventionalView",
    "DepthAwareProjector",
    "NaiveProjector",
    "ProposedDistortionProjector",
    "ProposedProjector",
    "build_projector",
    "conventional_image",
]


@runtime_checkable
class CentralProjector(Protocol):
    """Turns a raw lenslet image into a central-projection image with intrinsics ``output.K``.

    What each method claims: the image's centre of projection is the main-lens centre and its axes
    are the camera frame's. ``proposed`` makes it true inside its coverage, ``depth-aware`` there and
    wherever its depth is right, ``approx`` near its calibration depth, ``naive`` nowhere behind a
    port. A calibration fitted without known corners (``ApproxCalibration.known_corners`` False)
    gives images in the fit's own frame instead.
    """

    @property
    def name(self) -> str:
        """The method's name in :data:`METHODS`."""
        ...

    @property
    def output(self) -> PinholeCamera:
        """Geometry of the images :meth:`apply` returns."""
        ...

    def apply(self, raw: np.ndarray) -> np.ndarray:
        """Image of one raw frame, float32, shape ``(output.height_px, output.width_px)`` (+ channels);
        NaN where the method has no value."""
        ...

    def to_dict(self) -> dict:
        """Plain data describing the method and its parameters (for sidecars)."""
        ...


def conventional_image(camera: LightFieldCamera, raw: np.ndarray, *, view: PinholeCamera | None = None) -> np.ndarray:
    """The image a conventional camera would take: the central sub-aperture view.

    One sample per microlens at its micro-image centre (the ray through the main-lens centre),
    resampled onto the pinhole ``view`` (:func:`lfrefract.synthesis.views.naive_view`, ``kind="central"``):
    an exact pinhole image in air with ``view.K``, whose centre of projection is the main-lens
    centre; behind a port, the port's refraction is in it. For many frames of one camera,
    :class:`ConventionalView` gives the same images faster.

    Parameters
    ----------
    camera : LightFieldCamera
    raw : ndarray, shape (H, W) or (H, W, C)
        Raw lenslet image of ``camera``'s sensor size.
    view : PinholeCamera, optional
        Its geometry; default :func:`virtual_camera_for` ``(camera)``.

    Returns
    -------
    ndarray, float32, shape (view.height_px, view.width_px) (+ channels)
        NaN outside the lenses' hull.
    """
    return naive_view(camera, raw, output=view, kind="central")


@dataclass(frozen=True, eq=False)
class ConventionalView:
    """:func:`conventional_image` with its resampling computed once per camera and view.

    The central view interpolates linearly between the lens positions over their Delaunay
    triangulation, as ``scipy.interpolate.LinearNDInterpolator`` does in
    :func:`~lfrefract.synthesis.views.naive_view`; the interpolation matrix
    (:func:`~lfrefract.synthesis.views.resampling_matrix`) is built once here and kept.

    Attributes
    ----------
    camera : LightFieldCamera or CameraModel
        The camera and its ray model: a calibrated camera's radial model (``lfrefract calibrate
        camera``) puts each lens where its corrected chief ray points, so the main lens's distortion
        is not in the image; a bare camera: the thin lens's rays.
    view : PinholeCamera
        Output geometry.
    """

    camera: LightFieldCamera | CameraModel
    view: PinholeCamera
    _model: CameraModel = field(init=False, repr=False)
    _idx: np.ndarray = field(init=False, repr=False)
    _matrix: sparse.csr_matrix = field(init=False, repr=False)
    _inside: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_model", as_camera_model(self.camera))
        if not isinstance(self.view, PinholeCamera):
            raise ParameterError(f"view must be a PinholeCamera, got {self.view!r}")
        idx, matrix, inside = resampling_matrix(self._model, self.view)
        object.__setattr__(self, "_idx", idx)
        object.__setattr__(self, "_matrix", matrix)
        object.__setattr__(self, "_inside", inside)

    def apply(self, raw: np.ndarray, *, recorded: np.ndarray | None = None) -> np.ndarray:
        """The conventional image of ``raw`` (see :func:`conventional_image`); ``recorded`` ((H, W)
        bool, e.g. :func:`~lfrefract.synthesis.views.finite_pixels`): only those raw pixels are used,
        as in :func:`~lfrefract.synthesis.views.subaperture_view`."""
        camera = self._model.camera
        image = raw_channels(camera, raw)
        recorded = recorded_mask(camera, recorded)
        samples = micro_image_samples(camera, image, self._idx, recorded=recorded)
        grey = np.ndim(raw) == 2
        return apply_resampling(self._matrix, self._inside, samples, self.view, grey=grey, masked=recorded is not None)


@dataclass(frozen=True, eq=False)
class NaiveProjector:
    """``naive``: the conventional image, no refraction handling."""

    conventional: ConventionalView
    name: str = field(default="naive", init=False)

    @property
    def output(self) -> PinholeCamera:
        """The conventional image's geometry."""
        return self.conventional.view

    def apply(self, raw: np.ndarray) -> np.ndarray:
        """See :class:`CentralProjector`."""
        return self.conventional.apply(raw)

    def to_dict(self) -> dict:
        """See :class:`CentralProjector`."""
        return {"method": self.name, "output": self.output.to_dict()}


@dataclass(frozen=True, eq=False)
class ProposedProjector:
    """``proposed``: a :class:`~lfrefract.synthesis.warp_map.WarpMap`, with unfilled pixels NaN."""

    warp: WarpMap
    name: str = field(default="proposed", init=False)

    def __post_init__(self) -> None:
        if not isinstance(self.warp, WarpMap):
            raise ParameterError(f"warp must be a WarpMap, got {self.warp!r}")

    @property
    def output(self) -> PinholeCamera:
        """The warp map's output geometry."""
        return self.warp.output

    def apply(self, raw: np.ndarray) -> np.ndarray:
        """``warp.apply(raw)`` with NaN where the map has no entry (:attr:`WarpMap.filled`)."""
        image = self.warp.apply(raw)
        image[~self.warp.filled] = math.nan
        return image

    def to_dict(self) -> dict:
        """See :class:`CentralProjector`; the map itself is stored by :meth:`WarpMap.save`."""
        return {
            "method": self.name,
            "output": self.output.to_dict(),
            "warp_map_key": self.warp.key,
            "port": self.warp.meta["port"],
            "options": self.warp.meta["options"],
        }


@dataclass(frozen=True, eq=False)
class DepthAwareProjector:
    """``depth-aware``: a :class:`~lfrefract.synthesis.depth_aware.DepthAwareSynthesis`'s images.

    Inside the warp map's exact coverage they are :class:`ProposedProjector`'s; outside it, pixels
    rendered from the rays that see their scene point at the depth found in the frame's light field,
    else the warp map's approximated pixels; NaN where neither has a value.
    """

    synthesis: DepthAwareSynthesis
    name: str = field(default="depth-aware", init=False)

    def __post_init__(self) -> None:
        if not isinstance(self.synthesis, DepthAwareSynthesis):
            raise ParameterError(f"synthesis must be a DepthAwareSynthesis, got {self.synthesis!r}")

    @property
    def output(self) -> PinholeCamera:
        """The warp map's output geometry."""
        return self.synthesis.output

    def apply(self, raw: np.ndarray) -> np.ndarray:
        """See :class:`CentralProjector`: ``synthesis.apply(raw).image``."""
        return self.synthesis.apply(raw).image

    def to_dict(self) -> dict:
        """See :class:`CentralProjector`; :meth:`ProposedProjector.to_dict` plus ``depth_options``."""
        return {
            **ProposedProjector(self.synthesis.warp).to_dict(),
            "method": self.name,
            "depth_options": self.synthesis.options.to_dict(),
        }


@dataclass(frozen=True, eq=False)
class ApproxProjector:
    """``approx``: the conventional image undistorted with a calibration at one depth.

    Attributes
    ----------
    conventional : ConventionalView
        The conventional image (camera and geometry ``view``) the calibration was made on.
    calibration : ApproxCalibration
        Calibrated on conventional images of that geometry.
    output : PinholeCamera
        Geometry of the undistorted image.
    """

    conventional: ConventionalView
    calibration: ApproxCalibration
    output: PinholeCamera
    name: str = field(default="approx", init=False)
    _maps: tuple[np.ndarray, np.ndarray] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not isinstance(self.conventional, ConventionalView):
            raise ParameterError(f"conventional must be a ConventionalView, got {self.conventional!r}")
        if not isinstance(self.calibration, ApproxCalibration):
            raise ParameterError(f"calibration must be an ApproxCalibration, got {self.calibration!r}")
        size = (self.view.width_px, self.view.height_px)
        if size != self.calibration.image_size:
            raise ParameterError(
                f"the conventional view is {size[0]} x {size[1]} px but the calibration is for "
                f"{self.calibration.image_size[0]} x {self.calibration.image_size[1]} px images"
            )
        object.__setattr__(self, "_maps", self.calibration.undistort_maps(self.output))

    @property
    def view(self) -> PinholeCamera:
        """Geometry of the conventional image."""
        return self.conventional.view

    @property
    def depth_m(self) -> float:
        """The calibration depth, metres."""
        return self.calibration.depth_m

    def apply(self, raw: np.ndarray) -> np.ndarray:
        """See :class:`CentralProjector`."""
        return self.calibration.undistort(self.conventional.apply(raw), self.output, maps=self._maps)

    def to_dict(self) -> dict:
        """See :class:`CentralProjector`; :meth:`from_dict` reads it back given the camera."""
        return {
            "method": self.name,
            "calibration_depth_m": self.depth_m,
            "calibration": self.calibration.to_dict(),
            "view": self.view.to_dict(),
            "output": self.output.to_dict(),
        }

    @classmethod
    def from_dict(cls, data: dict, camera: LightFieldCamera) -> ApproxProjector:
        """Inverse of :meth:`to_dict`, for ``camera``."""
        if not isinstance(data, dict):
            raise ParameterError(f"an approx projector must be a dict, got {type(data).__name__}")
        require_keys("approx projector", data, {"method", "calibration", "view", "output"})
        one_of("method", data["method"], ("approx",))
        return cls(
            conventional=ConventionalView(camera, PinholeCamera.from_dict(data["view"])),
            calibration=ApproxCalibration.from_dict(data["calibration"]),
            output=PinholeCamera.from_dict(data["output"]),
        )


@dataclass(frozen=True, eq=False)
class ProposedDistortionProjector:
    """``proposed+distortion``: the synthesized image with a fitted residual distortion removed.

    Attributes
    ----------
    warp : WarpMap
    calibration : ApproxCalibration
        Calibrated on synthesized images (``warp.output``'s geometry).
    """

    warp: WarpMap
    calibration: ApproxCalibration
    name: str = field(default="proposed+distortion", init=False)
    _maps: tuple[np.ndarray, np.ndarray] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not isinstance(self.warp, WarpMap):
            raise ParameterError(f"warp must be a WarpMap, got {self.warp!r}")
        if not isinstance(self.calibration, ApproxCalibration):
            raise ParameterError(f"calibration must be an ApproxCalibration, got {self.calibration!r}")
        size = (self.warp.output.width_px, self.warp.output.height_px)
        if size != self.calibration.image_size:
            raise ParameterError(
                f"the warp map's output is {size[0]} x {size[1]} px but the calibration is for "
                f"{self.calibration.image_size[0]} x {self.calibration.image_size[1]} px images"
            )
        object.__setattr__(self, "_maps", self.calibration.undistort_maps(self.output))

    @property
    def output(self) -> PinholeCamera:
        """The warp map's output geometry (the undistorted image keeps it)."""
        return self.warp.output

    def apply(self, raw: np.ndarray) -> np.ndarray:
        """See :class:`CentralProjector`."""
        image = ProposedProjector(self.warp).apply(raw)
        return self.calibration.undistort(image, self.output, maps=self._maps)

    def to_dict(self) -> dict:
        """See :class:`CentralProjector`."""
        return {
            **ProposedProjector(self.warp).to_dict(),
            "method": self.name,
            "calibration_depth_m": self.calibration.depth_m,
            "calibration": self.calibration.to_dict(),
        }


@dataclass(frozen=True, eq=False, kw_only=True)
class CalibrationViews:
    """Raw images of a chessboard at about one depth, for the methods that calibrate.

    Attributes
    ----------
    raws : sequence of ndarray, each shape (H, W) or (H, W, C)
        Raw lenslet images of the camera.
    pattern : (int, int)
        Inner corners per row and column.
    square_size_m : float
        Edge length of a square, metres.
    corners_cam : sequence of ndarray, each shape (N, 3), optional
        The boards' inner corners in the camera frame, metres (ground truth): the model is then
        fitted with the camera's pose (:func:`calibrate_approx`).
    """

    raws: Sequence[np.ndarray]
    pattern: tuple[int, int]
    square_size_m: float
    corners_cam: Sequence[np.ndarray] | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "raws", tuple(self.raws))
        positive_float("square_size_m", self.square_size_m)
        if self.corners_cam is not None:
            corners = tuple(as_points(f"corners_cam[{i}]", c, 3) for i, c in enumerate(self.corners_cam))
            if len(corners) != len(self.raws):
                raise ParameterError(
                    f"corners_cam must have one array per raw image ({len(self.raws)}), got {len(corners)}"
                )
            object.__setattr__(self, "corners_cam", corners)

    def calibrate(self, images: Sequence[np.ndarray], **options) -> ApproxCalibration:
        """:func:`calibrate_approx` on ``images`` made from :attr:`raws`, with this board."""
        return calibrate_approx(
            images, pattern=self.pattern, square_size_m=self.square_size_m, corners_cam=self.corners_cam, **options
        )


def _need_calibration(name: str, calibration: CalibrationViews | None) -> CalibrationViews:
    if not isinstance(calibration, CalibrationViews):
        raise ParameterError(f"method {name!r} needs calibration views (a CalibrationViews), got {calibration!r}")
    return calibration


def _warp(camera, port, output, options, warp) -> WarpMap:
    if warp is not None:
        if not isinstance(warp, WarpMap):
            raise ParameterError(f"warp must be a WarpMap, got {warp!r}")
        if output is not None and output != warp.output:
            raise ParameterError(f"output {output!r} differs from the warp map's {warp.output!r}")
        return warp
    if port is None:
        raise ParameterError("the proposed methods need the port (or a prebuilt warp map)")
    return build_warp_map(camera, port, output=output, options=options)


def _build_naive(camera, port, *, calibration, output, options, warp, depth_options) -> NaiveProjector:
    return NaiveProjector(ConventionalView(camera, output if output is not None else virtual_camera_for(camera)))


def _build_approx(camera, port, *, calibration, output, options, warp, depth_options) -> ApproxProjector:
    views = _need_calibration("approx", calibration)
    view = virtual_camera_for(camera)
    conventional = ConventionalView(camera, view)
    images = [conventional.apply(raw) for raw in views.raws]
    return ApproxProjector(
        conventional=conventional, calibration=views.calibrate(images), output=output if output is not None else view
    )


def _build_proposed(camera, port, *, calibration, output, options, warp, depth_options) -> ProposedProjector:
    return ProposedProjector(_warp(camera, port, output, options, warp))


def _build_proposed_distortion(
    camera, port, *, calibration, output, options, warp, depth_options
) -> ProposedDistortionProjector:
    views = _need_calibration("proposed+distortion", calibration)
    proposed = ProposedProjector(_warp(camera, port, output, options, warp))
    images = [proposed.apply(raw) for raw in views.raws]
    return ProposedDistortionProjector(proposed.warp, views.calibrate(images, intrinsics=proposed.output))


def _build_depth_aware(camera, port, *, calibration, output, options, warp, depth_options) -> DepthAwareProjector:
    if port is None:
        raise ParameterError("method 'depth-aware' needs the port (it traces the camera's rays through it)")
    warp = _warp(camera, port, output, options, warp)
    return DepthAwareProjector(DepthAwareSynthesis.build(camera, port, warp=warp, options=depth_options))


#: Method names and their builders (see :func:`build_projector`).
METHODS: dict[str, Callable[..., CentralProjector]] = {
    "naive": _build_naive,
    "approx": _build_approx,
    "proposed": _build_proposed,
    "proposed+distortion": _build_proposed_distortion,
    "depth-aware": _build_depth_aware,
}


def build_projector(
    name: str,
    camera: LightFieldCamera,
    port: FlatPort | None = None,
    *,
    calibration: CalibrationViews | None = None,
    output: PinholeCamera | None = None,
    options: SynthesisOptions | None = None,
    warp: WarpMap | None = None,
    depth_options: DepthAwareOptions | None = None,
) -> CentralProjector:
    """Build the projector of a method by name.

    Parameters
    ----------
    name : str
        One of :data:`METHODS`: ``"naive"``, ``"approx"``, ``"proposed"``, ``"proposed+distortion"``,
        ``"depth-aware"``.
    camera : LightFieldCamera
    port : FlatPort, optional
        Needed by the proposed methods unless ``warp`` is given, and always by ``depth-aware``
        (it traces the camera's rays through it; ``warp`` must be of this port); the others never
        look at it (the approximation knows the port only through its calibration views).
    calibration : CalibrationViews, optional
        Needed by ``approx`` (calibrated on their conventional images; the calibration depth is
        theirs) and ``proposed+distortion`` (on their synthesized images, ``K`` fixed).
    output : PinholeCamera, optional
        Output geometry; default :func:`virtual_camera_for` ``(camera)`` (the warp map's for the
        proposed methods and ``depth-aware``), so that every method's images share one ``K``.
    options : SynthesisOptions, optional
        For the warp map of the proposed methods and ``depth-aware``.
    warp : WarpMap, optional
        A prebuilt warp map for the proposed methods and ``depth-aware`` (it fixes ``output``).
    depth_options : DepthAwareOptions, optional
        The depth search and render of ``depth-aware`` (default :class:`DepthAwareOptions` ``()``);
        refused for the other methods.

    Returns
    -------
    CentralProjector
    """
    one_of("name", name, tuple(METHODS))
    if not isinstance(camera, LightFieldCamera):
        raise ParameterError(f"camera must be a LightFieldCamera, got {camera!r}")
    if output is not None and not isinstance(output, PinholeCamera):
        raise ParameterError(f"output must be a PinholeCamera, got {output!r}")
    if depth_options is not None:
        if name != "depth-aware":
            raise ParameterError(f"depth_options are for method 'depth-aware' only, not {name!r}")
        if not isinstance(depth_options, DepthAwareOptions):
            raise ParameterError(f"depth_options must be DepthAwareOptions, got {depth_options!r}")
    return METHODS[name](
        camera, port, calibration=calibration, output=output, options=options, warp=warp, depth_options=depth_options
    )
