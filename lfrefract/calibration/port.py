"""Flat-port calibration from underwater chessboard views (paper section 4.2; Agrawal et al. 2012).

The camera behind the port is a pinhole in air whose intrinsics are known from in-air
calibration: for a light-field camera, its central sub-aperture view (the ray through the
main-lens centre and each microlens centre), resampled onto a ``K`` by
:func:`lfrefract.synthesis.views.naive_view`. A pixel's line of sight ``K^-1 p`` is refracted by the port
(its normal and distance unknown; glass thickness and refractive indices known) and meets the
board somewhere in the water. The unknowns are the port's two tilt angles and its distance, and
one board pose per view.

Initialisation (no ground truth): for a flat port, whatever its distance and layers, the refracted
ray stays in the plane spanned by the line of sight ``v`` and the normal ``n`` (the plane of
refraction), so a board point ``X = R P + t`` seen along ``v`` obeys ``X . (n x v) = 0``. For a
planar board this is linear in the nine entries of ``[n]x [r1 r2 t]`` (Agrawal et al.'s axial
constraint), and ``n`` is that matrix's left null vector: one estimate per view, combined. The
constraint rests on how far the refracted rays pass from the camera centre (millimetres at a
board's distance), so corner noise easily turns it by tens of degrees; it is therefore one start
among a robust search: it, the optical axis and normals 10-40 deg off it in eight directions, each
with eight distances over ``distance_range_m`` and each view's board pose in closed form, scored
by the residual. The four best get per-view pose fits, a few joint steps each, and the best of
them is refined to convergence by nonlinear least squares (scipy) on the
geometric error: where the refracted line of sight meets the board, against the corner, scaled to
pixels by ``f / depth``. Views that straight lines of sight (no port) explain as well as the
fitted port show no refraction (boards captured in air) and are refused. The covariance of the port
parameters follows from the Jacobian; a calibration whose standard deviations exceed the caller's
limits is an error (degenerate views), not an answer.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import typing
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import lil_matrix
from scipy.spatial.transform import Rotation

from lfrefract.calibration.approx import detect_board_lattice, detect_chessboard, lattice_points_m, square_size
from lfrefract.calibration.corners import RIM_MARGIN_PX as LIGHT_FIELD_RIM_MARGIN_PX
from lfrefract.calibration.corners import light_field_corners
from lfrefract.calibration.distinct import require_distinct_corners, view_names
from lfrefract.calibration.uncertainty import fit_covariances, larger_covariance, propagated_shifts
from lfrefract.errors import CalibrationError, ParameterError
from lfrefract.formats.jsonio import PORT_CALIBRATION_KIND
from lfrefract.optics.camera import LightFieldCamera
from lfrefract.optics.pinhole import PinholeCamera
from lfrefract.optics.port import FlatPort
from lfrefract.optics.pose import Pose
from lfrefract.synthesis.views import finite_pixels, subaperture_centre_m, subaperture_view
from lfrefract.validate import as_points, finite_vector, one_of, positive_float, positive_int

__all__ = [
    "CORNER_METHODS",
    "DISTANCE_AT_BOUND_M",
    "MIN_BOARD_CORNERS",
    "NO_REFRACTION_CHI2",
    "PORT_CALIBRATION_KIND",
    "BoardView",
    "CalibrationError",
    "PortCalibration",
    "PortUndeterminedError",
    "board_view_from_light_field",
    "calibrate_port",
    "estimate_normal",
    "normal_std_deg",
    "project_through_port",
]


#: Fewest corners a :class:`BoardView` holds (a board's pose and the port's parameters from fewer are
#: not determined); :func:`board_view_from_light_field` finds a board with fewer inner corners as none.
MIN_BOARD_CORNERS = 8


@dataclass(frozen=True, eq=False)
class BoardView:
    """Chessboard corners seen in one underwater view.

    One board pose, seen by one or several in-air pinhole cameras that share the intrinsics and
    orientation of ``camera`` in :func:`calibrate_port` but may sit elsewhere: a light-field
    camera's sub-aperture views are pinholes at points of the main-lens plane
    (:func:`lfrefract.synthesis.views.subaperture_centre_m`), so each corner carries the centre of the view
    it was found in.

    Attributes
    ----------
    corners_px : ndarray, shape (N, 2)
        Detected corners (pixels, OpenCV convention).
    board_points_m : ndarray, shape (N, 2)
        The same corners in the board's own frame (metres, on its plane z = 0).
    centres_m : ndarray, shape (N, 3), optional
        Centre of projection of the view each corner was found in, camera frame, metres
        (default: the origin, the main-lens centre).
    central_rows : ndarray of bool, shape (N,), optional
        The rows seen through the centre of the main-lens aperture (the central sub-aperture
        view), which start the calibration as one central camera (default: the rows whose centre
        is the origin). A calibrated ray model's central rays need not start exactly at the origin
        (:func:`lfrefract.calibration.camera.corrected_view` keeps the mask of the view it corrects).
    """

    corners_px: np.ndarray
    board_points_m: np.ndarray
    centres_m: np.ndarray | None = None
    central_rows: np.ndarray | None = None

    def __post_init__(self) -> None:
        corners = as_points("corners_px", self.corners_px, 2)
        board = as_points("board_points_m", self.board_points_m, 2)
        if len(corners) != len(board):
            raise ParameterError(
                f"corners_px and board_points_m must have the same length, got {len(corners)} and {len(board)}"
            )
        if len(corners) < MIN_BOARD_CORNERS:
            raise ParameterError(f"a board view needs at least {MIN_BOARD_CORNERS} corners, got {len(corners)}")
        centres = np.zeros((len(corners), 3)) if self.centres_m is None else as_points("centres_m", self.centres_m, 3)
        if len(centres) != len(corners):
            raise ParameterError(f"centres_m must have one row per corner ({len(corners)}), got {len(centres)}")
        if self.central_rows is None:
            central = np.all(centres == 0.0, axis=1)
        else:
            central = np.asarray(self.central_rows)
            if central.dtype != bool or central.shape != (len(corners),):
                raise ParameterError(
                    f"central_rows must be a boolean array of shape ({len(corners)},), got "
                    f"{central.dtype} of shape {central.shape}"
                )
        object.__setattr__(self, "corners_px", corners)
        object.__setattr__(self, "board_points_m", board)
        object.__setattr__(self, "centres_m", centres)
        object.__setattr__(self, "central_rows", central)

    @property
    def centres(self) -> np.ndarray:
        """:attr:`centres_m` as constructed: (N, 3), never None (None is the origin for every corner)."""
        return typing.cast(np.ndarray, self.centres_m)

    @property
    def central(self) -> np.ndarray:
        """Rows seen through the main-lens centre, boolean (N,) (:attr:`central_rows` as constructed)."""
        return typing.cast(np.ndarray, self.central_rows)


@dataclass(frozen=True, eq=False)
class PortCalibration:
    """Result of :func:`calibrate_port`.

    Attributes
    ----------
    port : FlatPort
        The estimated port (with the given thickness and indices).
    board_poses : tuple of Pose
        Pose of each view's board in the camera frame: ``Pose.to_world`` maps board coordinates
        (metres, z = 0 on the board) to the camera frame.
    rms_px : float
        Root mean square of the geometric residuals: where each refracted line of sight misses its
        corner on the board, scaled by focal length / depth. In air that is the image error in
        pixels; through water it is about ``n_air / n_water`` of it (angles shrink in the water).
    view_rms_px : ndarray, shape (V,)
        The same per view.
    covariance : ndarray, shape (3, 3)
        Covariance of ``(tilt_x_rad, tilt_y_rad, distance_m)``: the sum of :attr:`covariance_parts`
        (from :func:`calibrate_port`: the larger of the Jacobian's and the capture-clustered one, plus
        what the camera model's uncertainty adds), or the Jacobian's alone.
    normal_std_deg : float
        Standard deviation of the normal's direction (degrees): the larger axis of its covariance.
    distance_std_m : float
        Standard deviation of the port distance (metres).
    covariance_parts : dict of str to ndarray (3, 3)
        What :attr:`covariance` is made of: ``"pixel_noise"`` (from the fit's Jacobian, scaled by the
        residual variance), ``"by_capture"`` (each capture's corners as one sample: errors the corners
        of a capture share), ``"noise"`` (the larger of the two in every direction, which the total
        takes) and ``"camera_model"`` (the camera's ray model's uncertainty, propagated; zero when none
        was given). Empty where the covariance is the Jacobian's alone.
    camera_model_shifts : ndarray, shape (k, 3)
        The port's first-order change ``-(J^T J)^-1 J^T dr`` in ``(tilt_x_rad, tilt_y_rad, distance_m)``
        with the views moved along each of the ``k`` directions of the camera model's spread
        (``model_views`` of :func:`calibrate_port`; ``dr`` the residuals' change): their outer products
        sum to ``covariance_parts["camera_model"]``. Shape (0, 3) without a camera model. What more
        boards make of that part (:func:`lfrefract.calibration.advice.advise_port_views`) starts here.
    """

    port: FlatPort
    board_poses: tuple[Pose, ...]
    rms_px: float
    view_rms_px: np.ndarray
    covariance: np.ndarray
    normal_std_deg: float
    distance_std_m: float
    covariance_parts: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)
    camera_model_shifts: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 3)))

    def to_dict(self) -> dict:
        """Plain data for a JSON file."""
        return {
            "port": self.port.to_dict(),
            "board_poses": [p.to_dict() for p in self.board_poses],
            "rms_px": self.rms_px,
            "view_rms_px": self.view_rms_px.tolist(),
            "covariance": self.covariance.tolist(),
            "covariance_parameters": ["tilt_x_rad", "tilt_y_rad", "distance_m"],
            "normal_std_deg": self.normal_std_deg,
            "distance_std_m": self.distance_std_m,
            **(
                {"covariance_parts": {name: part.tolist() for name, part in self.covariance_parts.items()}}
                if self.covariance_parts
                else {}
            ),
        }


class PortUndeterminedError(CalibrationError):
    """The views do not determine the port to the limits asked: the fit is attached as
    ``calibration`` (a :class:`PortCalibration`), so that a caller can say what views would
    determine it (:func:`lfrefract.calibration.advice.advise_port_views`)."""

    def __init__(self, message: str, *, calibration: PortCalibration) -> None:
        super().__init__(message)
        self.calibration = calibration


#: How near an end of ``distance_range_m`` a fitted port distance counts as at that end (metres): far
#: above the margin the bounded solver keeps inside a bound, far below any port distance's precision.
DISTANCE_AT_BOUND_M = 1e-6
#: How much better than straight lines of sight (no port) the port's fit must explain the corners, in
#: units of their variance: chi-square's 99.9th percentile for the port's three parameters. Measured
#: on tiny-2x renders: boards behind a port 25 deg tilted gain 9e4-2e5, boards in air lose 450-1100
#: (the port fits them 6-7 times worse than straight lines).
NO_REFRACTION_CHI2 = 16.27
#: Fewest board captures :func:`calibrate_port` takes: the port's three parameters and one pose per
#: board are not separable from a single board.
MIN_VIEWS = 2
#: How :func:`board_view_from_light_field` locates corners.
CORNER_METHODS = ("light-field", "views")


def board_view_from_light_field(
    camera: LightFieldCamera,
    raw: np.ndarray,
    *,
    pattern: tuple[int, int],
    square_size_m: float,
    view: PinholeCamera,
    method: str = "light-field",
    offsets_px: tuple[tuple[float, float], ...] = ((0.0, 0.0),),
    aperture_fraction: float = 0.6,
    name: str = "raw",
) -> BoardView | None:
    """Chessboard corners of one light-field capture, as seen from points of the main lens.

    The board is found in the central view (OpenCV). Then, with ``method="light-field"``, the whole
    board or the part of it the view shows (:func:`lfrefract.calibration.approx.detect_board_lattice`:
    a board reaching past the image, or past a lens's image circle), every corner is refined on all
    raw pixels around it (:func:`lfrefract.calibration.corners.light_field_corners`:
    0.01-0.03 px RMS from the exact refracted projection on the tiny-2x camera, against 0.2-0.4 px
    for the central view's corners) and reported from the main-lens centre and from four points at
    ``aperture_fraction`` of the usable aperture radius on the axes: its affine track over the
    aperture is fixed by three of them, and five keep the weights symmetric. Corners whose fit
    failed are left out. With ``method="views"``, OpenCV's corners of the whole board in the
    sub-aperture views at ``offsets_px`` are used as found.

    Parameters
    ----------
    camera : LightFieldCamera
    raw : ndarray, shape (H, W) or (H, W, C)
        The raw lenslet image; NaN where nothing was recorded (a pixel NaN in any channel is left out
        of the views and of the light-field fit).
    pattern : (int, int)
        Inner corners per row and column (OpenCV's ``patternSize``).
    square_size_m : float
        Edge of a square, metres.
    view : PinholeCamera
        Geometry the views are resampled onto (``K`` of :func:`calibrate_port`).
    method : {"light-field", "views"}
        How the corners are located (above).
    offsets_px : sequence of (float, float)
        ``method="views"``: sub-aperture offsets from the micro-image centres, pixels; the first
        must be ``(0, 0)`` (the central view, whose corners fix the order the others are matched to).
    aperture_fraction : float
        ``method="light-field"``: where on the aperture the outer four points lie, in (0, 1].
    name : str
        How errors name the capture.

    Returns
    -------
    BoardView or None
        The corners, each with the centre of projection it is seen from; None if the central view
        does not show the board, or fewer than 8 corners were located. Board coordinates are
        centred on the inner-corner lattice seen, so a detector's half-turned order, or a part of
        the board, is just another pose.
    """
    one_of("method", method, CORNER_METHODS)
    offsets: list[tuple[float, float]] = []
    for o in offsets_px:
        du, dv = finite_vector("offsets_px[i]", o, 2)
        offsets.append((du, dv))
    if not offsets or offsets[0] != (0.0, 0.0):
        raise ParameterError(f"offsets_px must start with (0, 0), the central view; got {offsets_px!r}")
    if method == "light-field" and len(offsets) > 1:
        raise ParameterError(f"offsets_px={offsets_px!r} is for method='views'; the light field uses every view")
    fraction = positive_float("aperture_fraction", aperture_fraction)
    if fraction > 1.0:
        raise ParameterError(f"aperture_fraction must be in (0, 1], got {aperture_fraction!r}")
    square = square_size("square_size_m", square_size_m)
    recorded = finite_pixels(raw)
    central_view = subaperture_view(camera, raw, (0.0, 0.0), output=view, recorded=recorded)
    if method == "light-field":
        lattice = detect_board_lattice(central_view, pattern, name=name)
        if lattice is None:
            return None
        tracks = light_field_corners(
            camera, raw, lattice.corners_px, pattern=lattice.pattern, square_size_m=square, view=view
        )
        located = tracks.ok & lattice.valid
        if np.count_nonzero(located) < MIN_BOARD_CORNERS:
            return None
        reach = fraction * camera.usable_aperture_radius_m(LIGHT_FIELD_RIM_MARGIN_PX)
        points = [(0.0, 0.0), (reach, 0.0), (-reach, 0.0), (0.0, reach), (0.0, -reach)]
        corners = [tracks.at(a)[located] for a in points]
        centres = [np.tile([a[0], a[1], 0.0], (int(np.count_nonzero(located)), 1)) for a in points]
        board = lattice.board_points_m(square)[located]
    else:
        central = detect_chessboard(central_view, pattern, name=name)
        if central is None:
            return None
        corners, centres = [central], [np.zeros((len(central), 3))]
        board = lattice_points_m((pattern[1], pattern[0]), square)
    for offset in offsets[1:] if method == "views" else ():
        found = detect_chessboard(
            subaperture_view(camera, raw, offset, output=view, recorded=recorded), pattern, name=name
        )
        if found is None:
            continue
        if np.linalg.norm(found[::-1] - corners[0]) < np.linalg.norm(found - corners[0]):
            found = found[::-1]  # the same order as the central view's
        corners.append(found)
        centres.append(np.tile(subaperture_centre_m(camera, offset), (len(found), 1)))
    return BoardView(
        corners_px=np.concatenate(corners),
        board_points_m=np.tile(board, (len(corners), 1)),
        centres_m=np.concatenate(centres),
    )


def board_corners(view: BoardView) -> tuple[np.ndarray, np.ndarray]:
    """A view's central rows (all rows if it has none) as (board points (N, 2), metres; corners (N, 2),
    pixels): what :func:`lfrefract.calibration.distinct.require_distinct_corners` compares."""
    rows = view.central if view.central.any() else np.ones(len(view.corners_px), dtype=bool)
    return view.board_points_m[rows], view.corners_px[rows]


def _water_rays(port: FlatPort, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points on the water face and unit directions in the water of lines of sight."""
    trace = port.trace_from_air(origins, directions)
    return trace.exit_points_cam, trace.directions_cam


def project_through_port(
    camera: PinholeCamera,
    port: FlatPort,
    points_cam: np.ndarray,
    *,
    centre_m: tuple[float, float, float] = (0.0, 0.0, 0.0),
    iterations: int = 30,
) -> np.ndarray:
    """Pixels at which points in the water appear through the port (forward refractive projection).

    Solved per point by Gauss-Newton on the pixel, from the refraction-free projection, with the
    exact back-projection (:meth:`FlatPort.trace_from_air`) inside: vectorised over all points.

    Parameters
    ----------
    camera : PinholeCamera
        The in-air pinhole camera (centre of projection at the origin of the camera frame).
    port : FlatPort
    points_cam : array_like, shape (N, 3)
        Points beyond the port, camera frame, metres.
    centre_m : (float, float, float)
        Centre of projection of the pinhole (its orientation is the camera frame's), metres.
    iterations : int
        Gauss-Newton steps (converges in a handful).

    Returns
    -------
    ndarray, shape (N, 2)
        Pixels; NaN where a point cannot be seen (behind the port's water face, or total internal
        reflection).
    """
    x = as_points("points_cam", points_cam, 3)
    centre = np.asarray(finite_vector("centre_m", centre_m, 3))
    positive_int("iterations", iterations)
    eps = 1e-3  # pixels, for the finite-difference Jacobian
    # Only points in the water, in front of the centre, can be seen; the others stay NaN.
    water = (x @ port.normal > port.distance_m + port.thickness_m) & (x[:, 2] > centre[2])
    uv = np.full((len(x), 2), np.nan)
    uv[water] = camera.project(x[water] - centre)

    def offsets(q: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """How far points ``rows`` lie off the refracted lines of sight of pixels ``q`` (metres,
        perpendicular to the water ray), and how far along it they are."""
        origin, d = _water_rays(port, np.broadcast_to(centre, (len(q), 3)), camera.pixel_directions(q))
        rel = x[rows] - origin
        along = np.sum(rel * d, axis=1, keepdims=True)
        return rel - along * d, along[:, 0]

    active = water.copy()
    for _ in range(iterations):
        rows = np.flatnonzero(active & np.all(np.isfinite(uv), axis=1))
        if len(rows) == 0:
            break
        q = uv[rows]
        with np.errstate(invalid="ignore"):
            r, _ = offsets(q, rows)
            ju = (offsets(q + np.array([eps, 0.0]), rows)[0] - r) / eps
            jv = (offsets(q + np.array([0.0, eps]), rows)[0] - r) / eps
        step = _batched_lstsq(np.stack([ju, jv], axis=2), -r)
        uv[rows] = q + step
        active[rows] = ~(np.all(np.abs(step) < 1e-9, axis=1))
    # Keep only converged solutions with the point ahead on the water ray.
    seen = np.flatnonzero(water & np.all(np.isfinite(uv), axis=1))
    ok = np.zeros(len(x), dtype=bool)
    if len(seen):
        with np.errstate(invalid="ignore"):
            miss, along = offsets(uv[seen], seen)
        scale = np.linalg.norm(x[seen] - centre, axis=1)
        ok[seen] = (np.linalg.norm(miss, axis=1) <= 1e-9 * np.maximum(scale, 1.0)) & (along > 0.0)
    uv[~ok] = np.nan
    return uv


def _batched_lstsq(jac: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Least-squares solutions of N small systems jac (N, 3, 2) x = rhs (N, 3)."""
    jtj = np.einsum("nij,nik->njk", jac, jac)
    jtr = np.einsum("nij,ni->nj", jac, rhs)
    det = jtj[:, 0, 0] * jtj[:, 1, 1] - jtj[:, 0, 1] * jtj[:, 1, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.stack(
            [
                (jtj[:, 1, 1] * jtr[:, 0] - jtj[:, 0, 1] * jtr[:, 1]) / det,
                (jtj[:, 0, 0] * jtr[:, 1] - jtj[:, 1, 0] * jtr[:, 0]) / det,
            ],
            axis=1,
        )


def estimate_normal(camera: PinholeCamera, views: list[BoardView]) -> np.ndarray:
    """Port normal from the axial (coplanarity) constraint, without distance or poses.

    Returns
    -------
    ndarray, shape (3,)
        Unit normal (camera frame, ``n_z > 0``): the direction the per-view estimates agree on
        (the principal eigenvector of the sum of their outer products).
    """
    scatter = np.zeros((3, 3))
    used = 0
    for view in views:
        central = view.central
        if central.sum() < 8:
            continue
        used += 1
        v = camera.pixel_directions(view.corners_px[central])
        p = np.concatenate([view.board_points_m[central], np.ones((len(v), 1))], axis=1)
        # v^T M p = 0 for M = [n]x [r1 r2 t], row-major unknowns M_ij: coefficient v_i p_j.
        rows = (v[:, :, None] * p[:, None, :]).reshape(len(v), 9)
        rows /= np.linalg.norm(rows, axis=1, keepdims=True)
        m = np.linalg.svd(rows)[2][-1].reshape(3, 3)
        # n^T M = 0: n is M's left null vector.
        u = np.linalg.svd(m)[0]
        n = u[:, -1]
        scatter += np.outer(n, n)
    if used == 0:
        raise CalibrationError("no view has 8 or more corners seen from the main-lens centre (centres_m = 0)")
    vecs = np.linalg.eigh(scatter)[1]
    n = vecs[:, -1]  # the direction the per-view estimates agree on
    n = n if n[2] > 0 else -n
    if n[2] < 1e-6:
        raise CalibrationError(f"the axial constraint gives a normal across the optical axis, {n.round(6).tolist()}")
    return n


def port_from_parameters(params: np.ndarray, template: FlatPort) -> FlatPort:
    """The port of fit parameters ``(tilt_x_rad, tilt_y_rad, distance_m)`` with ``template``'s glass."""
    return FlatPort(
        distance_m=float(params[2]),
        thickness_m=template.thickness_m,
        tilt_x_rad=float(params[0]),
        tilt_y_rad=float(params[1]),
        n_air=template.n_air,
        n_glass=template.n_glass,
        n_water=template.n_water,
    )


def board_residuals_px(
    port: FlatPort | None,
    origins_cam: np.ndarray,
    directions_cam: np.ndarray,
    board_points_m: np.ndarray,
    pose6: np.ndarray,
    focal_px: float,
) -> np.ndarray:
    """The port calibration's geometric residuals of one board view, pixels.

    Each line of sight (in air, from ``origins_cam`` (N, 3) along ``directions_cam`` (N, 3), camera
    frame) is refracted by ``port`` (None: no port, the line goes on straight, as in air) and meets
    the board of pose ``pose6`` (rotation vector, rad, and translation, m: board to camera frame); its
    miss of the corner ``board_points_m`` (N, 2, board frame) is scaled by ``focal_px`` / depth.

    Returns
    -------
    ndarray, shape (2 N,)
        (x, y) misses per corner; 1000 px where a line of sight misses the board (or cannot enter the water).
    """
    if port is None:
        origin, d = origins_cam, directions_cam
    else:
        origin, d = _water_rays(port, origins_cam, directions_cam)
    rot = Rotation.from_rotvec(pose6[:3]).as_matrix()
    t = pose6[3:]
    normal_b = rot[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        s = ((t - origin) @ normal_b) / (d @ normal_b)
    hit = origin + s[:, None] * d
    local = (hit - t) @ rot  # board frame
    miss = local[:, :2] - board_points_m
    scale = focal_px / np.maximum(hit[:, 2], 1e-6)
    res = (miss * scale[:, None]).ravel()
    return np.where(np.isfinite(res), res, 1e3)  # a ray that misses the board costs a lot


class _Problem:
    """Residuals of all views for port parameters and board poses."""

    def __init__(self, camera: PinholeCamera, views: list[BoardView], template: FlatPort):
        self.camera = camera
        self.views = views
        self.template = template
        self.directions = [camera.pixel_directions(v.corners_px) for v in views]
        self.sizes = [len(v.corners_px) for v in views]

    def view_residuals(self, port: FlatPort, view: int, pose6: np.ndarray) -> np.ndarray:
        """Residuals (2N,) of one view, pixels (:func:`board_residuals_px`)."""
        v = self.views[view]
        return board_residuals_px(port, v.centres, self.directions[view], v.board_points_m, pose6, self.camera.focal_px)

    def residuals(self, x: np.ndarray) -> np.ndarray:
        port = port_from_parameters(x[:3], self.template)
        return np.concatenate([self.view_residuals(port, i, x[3 + 6 * i : 9 + 6 * i]) for i in range(len(self.views))])

    def sparsity(self) -> lil_matrix:
        n_res = 2 * sum(self.sizes)
        jac = lil_matrix((n_res, 3 + 6 * len(self.views)), dtype=int)
        row = 0
        for i, size in enumerate(self.sizes):
            jac[row : row + 2 * size, :3] = 1
            jac[row : row + 2 * size, 3 + 6 * i : 9 + 6 * i] = 1
            row += 2 * size
        return jac


def _linear_pose(problem: _Problem, port: FlatPort, view: int) -> np.ndarray | None:
    """Board pose from the refracted rays in closed form (linear least squares), or None.

    A board point ``X = x r1 + y r2 + t`` on the water ray through ``q`` along ``w`` satisfies
    ``w x (x r1 + y r2 + t) = w x q``: linear in ``(r1, r2, t)``. The rotation is the nearest
    one to ``(r1, r2, r1 x r2)``, and ``t`` is solved again with it.
    """
    q, w = _water_rays(port, problem.views[view].centres, problem.directions[view])
    if not np.all(np.isfinite(w)):
        return None
    board = problem.views[view].board_points_m
    cross = np.zeros((len(w), 3, 3))  # [w]x
    cross[:, 0, 1], cross[:, 0, 2], cross[:, 1, 2] = -w[:, 2], w[:, 1], -w[:, 0]
    cross -= cross.transpose(0, 2, 1)
    a = np.concatenate([cross * board[:, 0, None, None], cross * board[:, 1, None, None], cross], axis=2)
    b = np.einsum("nij,nj->ni", cross, q)
    solution = np.linalg.lstsq(a.reshape(-1, 9), b.ravel(), rcond=None)[0]
    r1, r2 = solution[:3], solution[3:6]
    if min(np.linalg.norm(r1), np.linalg.norm(r2)) < 1e-6:
        return None
    # Noise shrinks the solved scale of r1, r2: normalise before the third column is formed.
    r1, r2 = r1 / np.linalg.norm(r1), r2 / np.linalg.norm(r2)
    u, _, vt = np.linalg.svd(np.stack([r1, r2, np.cross(r1, r2)], axis=1))
    rot = u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt
    rhs = b - np.einsum("nij,nj->ni", cross, board @ rot[:, :2].T)
    t = np.linalg.lstsq(cross.reshape(-1, 3), rhs.ravel(), rcond=None)[0]
    if t[2] <= 0.0:
        return None
    return np.concatenate([Rotation.from_matrix(rot).as_rotvec(), t])


def _initial_pose(camera: PinholeCamera, view: BoardView) -> np.ndarray:
    """Board pose ignoring refraction (OpenCV PnP on the central rows), as (rotation vector, translation)."""
    rows = view.central if view.central.sum() >= 8 else np.ones(len(view.corners_px), dtype=bool)
    obj = np.concatenate([view.board_points_m[rows], np.zeros((rows.sum(), 1))], axis=1)
    ok, rvec, tvec = cv2.solvePnP(obj, view.corners_px[rows], camera.K, None, flags=cv2.SOLVEPNP_ITERATIVE)
    if not ok:
        raise CalibrationError("OpenCV could not estimate an initial board pose for a view")
    return np.concatenate([rvec.ravel(), tvec.ravel()])


def _straight_line_residuals_px(camera: PinholeCamera, views: Sequence[BoardView]) -> np.ndarray | None:
    """The views' residuals with no port: straight lines of sight, as in air (the in-air model).

    Each view's board pose is fitted alone (from OpenCV's, :func:`_initial_pose`) to the residuals
    of :func:`board_residuals_px` with ``port=None``.

    Returns
    -------
    ndarray, shape (2 N,) or None
        Every view's residuals in turn, pixels; None if a view's starting pose cannot be found.
    """
    parts = []
    for view in views:
        directions = camera.pixel_directions(view.corners_px)
        try:
            start = _initial_pose(camera, view)
        except CalibrationError:
            return None

        def residuals(pose6: np.ndarray, view: BoardView = view, directions: np.ndarray = directions) -> np.ndarray:
            return board_residuals_px(None, view.centres, directions, view.board_points_m, pose6, camera.focal_px)

        parts.append(least_squares(residuals, start, method="lm", max_nfev=400).fun)
    return np.concatenate(parts)


def _fit_pose(
    problem: _Problem, port: FlatPort, view: int, pose6: np.ndarray, *, max_nfev: int = 200
) -> tuple[np.ndarray, float]:
    fit = least_squares(lambda p: problem.view_residuals(port, view, p), pose6, method="lm", max_nfev=max_nfev)
    return fit.x, float(np.sum(fit.fun**2))


def _candidate_tilts(axial_normal: np.ndarray) -> list[tuple[float, float]]:
    """(tilt_x, tilt_y) radians to start from: the axial estimate, the optical axis, and normals
    10-40 deg off it in eight directions."""
    axial = FlatPort.from_normal(axial_normal, distance_m=1.0)
    tilts = [(axial.tilt_x_rad, axial.tilt_y_rad), (0.0, 0.0)]
    for total in np.radians([10.0, 20.0, 30.0, 40.0]):
        for azimuth in np.radians(np.arange(0.0, 360.0, 45.0)):
            n = np.array([math.sin(total) * math.cos(azimuth), math.sin(total) * math.sin(azimuth), math.cos(total)])
            p = FlatPort.from_normal(n, distance_m=1.0)
            tilts.append((p.tilt_x_rad, p.tilt_y_rad))
    return tilts


def calibrate_port(
    camera: PinholeCamera,
    views: list[BoardView],
    *,
    thickness_m: float,
    n_air: float = 1.0,
    n_glass: float = 1.5,
    n_water: float = 1.333,
    distance_range_m: tuple[float, float] = (0.002, 0.3),
    max_normal_std_deg: float = 0.5,
    max_distance_std_m: float = 0.002,
    names: Sequence[str] | None = None,
    model_views: Sequence[Sequence[BoardView]] = (),
) -> PortCalibration:
    """Estimate a flat port's normal and distance from underwater chessboard views.

    Parameters
    ----------
    camera : PinholeCamera
        The in-air pinhole model of the images the corners were found in.
    views : list of BoardView
        At least two views of a planar board (different poses).
    thickness_m, n_air, n_glass, n_water : float
        Known glass thickness and refractive indices.
    distance_range_m : (float, float)
        Range searched for the port distance (air-side face along its normal), metres.
    max_normal_std_deg, max_distance_std_m : float
        Largest standard deviations accepted; beyond them the views do not determine the port
        and :class:`CalibrationError` is raised.
    names : sequence of str, optional
        How errors name the views (their files); default ``views[i]``.
    model_views : sequence of sequences of BoardView, optional
        The camera model's uncertainty, as the views would be with the model moved along each
        direction of its spread (:func:`lfrefract.calibration.uncertainty.spread_factors`; e.g.
        :func:`lfrefract.calibration.camera.corrected_view` with each perturbed correction): each a
        list like ``views``. The port's covariance then includes what that uncertainty does to it.

    Returns
    -------
    PortCalibration
        Its covariance is the larger (in every direction) of the Jacobian's and the capture-clustered
        one, plus the camera model's share (:attr:`PortCalibration.covariance_parts`).

    Raises
    ------
    CalibrationError
        Degenerate views: two views of one board pose (the same capture twice is one view,
        :func:`lfrefract.calibration.distinct.require_distinct_corners`), views that show no
        refraction (straight lines of sight fit them as well as the best port, within
        :data:`NO_REFRACTION_CHI2`: boards captured in air), or the normal or distance not determined
        to the stated limits (:class:`PortUndeterminedError`, with the fit).
    """
    if not isinstance(camera, PinholeCamera):
        raise ParameterError(f"camera must be a PinholeCamera, got {camera!r}")
    views = list(views)
    if len(views) < MIN_VIEWS or not all(isinstance(v, BoardView) for v in views):
        raise ParameterError(f"views must be at least {MIN_VIEWS} BoardView objects, got {len(views)}")
    require_distinct_corners(
        [board_corners(v) for v in views], view_names(names, len(views), "views"), what="a port calibration"
    )
    model_views = [list(moved) for moved in model_views]
    for k, moved in enumerate(model_views):
        if len(moved) != len(views) or not all(isinstance(v, BoardView) for v in moved):
            raise ParameterError(
                f"model_views[{k}] must be {len(views)} BoardView objects (one per view), got {len(moved)}"
            )
    lo = positive_float("distance_range_m[0]", distance_range_m[0])
    hi = positive_float("distance_range_m[1]", distance_range_m[1])
    if not lo < hi:
        raise ParameterError(f"distance_range_m must be increasing, got {distance_range_m!r}")
    positive_float("max_normal_std_deg", max_normal_std_deg)
    positive_float("max_distance_std_m", max_distance_std_m)
    template = FlatPort(distance_m=lo, thickness_m=thickness_m, n_air=n_air, n_glass=n_glass, n_water=n_water)
    if n_air == n_water and (thickness_m == 0.0 or n_glass == n_air):
        raise ParameterError("the port does not refract (equal indices): its normal and distance are undefined")

    problem = _Problem(camera, views, template)
    lower = np.full(3 + 6 * len(views), -np.inf)
    upper = np.full(3 + 6 * len(views), np.inf)
    lower[:3] = [-math.radians(80.0), -math.radians(80.0), lo]  # the normal stays well in front
    upper[:3] = [math.radians(80.0), math.radians(80.0), hi]
    # Starting points: the axial estimate and a grid of normals, each with a coarse logarithmic
    # search of the distance, scored with the linear pose of every view; the best few get
    # per-view pose fits and are refined jointly.
    pnp: dict[int, np.ndarray] = {}  # OpenCV poses where the linear pose is undetermined, on demand
    starts = []
    for tilt_x, tilt_y in _candidate_tilts(estimate_normal(camera, views)):
        for distance in np.geomspace(lo, hi, 8):
            trial = port_from_parameters(np.array([tilt_x, tilt_y, distance]), template)
            linear: list[np.ndarray] = []
            for i in range(len(views)):
                pose = _linear_pose(problem, trial, i)
                if pose is None:
                    if i not in pnp:
                        pnp[i] = _initial_pose(camera, views[i])
                    pose = pnp[i]
                linear.append(pose)
            cost = sum(float(np.sum(problem.view_residuals(trial, i, p) ** 2)) for i, p in enumerate(linear))
            starts.append((cost, [tilt_x, tilt_y, distance], linear))
    starts.sort(key=lambda item: item[0])
    refined = []
    for cost, params, linear in starts[:4]:
        trial = port_from_parameters(np.array(params), template)
        refined.append((cost, params, [_fit_pose(problem, trial, i, p)[0] for i, p in enumerate(linear)]))
    starts = refined

    def refine(x0: np.ndarray, max_nfev: int):
        return least_squares(
            problem.residuals,
            np.clip(x0, lower + 1e-9, upper - 1e-9),
            jac_sparsity=problem.sparsity(),
            bounds=(lower, upper),
            x_scale="jac",
            method="trf",
            xtol=1e-10,
            ftol=1e-10,
            gtol=1e-10,
            max_nfev=max_nfev,
        )

    # A few steps from each start, then the best to convergence.
    trials = [refine(np.concatenate([params, *poses]), 20) for _, params, poses in starts]
    fit = refine(min(trials, key=lambda t: t.cost).x, 200)
    port = port_from_parameters(fit.x[:3], template)
    residuals = fit.fun
    dof = max(len(residuals) - len(fit.x), 1)
    sigma2 = float(np.sum(residuals**2)) / dof
    _require_refraction(camera, views, residuals, sigma2)
    jac = fit.jac.toarray() if hasattr(fit.jac, "toarray") else np.asarray(fit.jac)
    try:
        bread = np.linalg.inv(jac.T @ jac)
    except np.linalg.LinAlgError:
        raise CalibrationError("the views do not determine the port: the normal equations are singular") from None
    parts, shifts = _covariance_parts(problem, fit.x, jac, residuals, bread, sigma2, model_views, template)
    # The bounded solver stays a little inside a bound it presses against (1e-8 m was seen): a
    # distance within DISTANCE_AT_BOUND_M of either end is the end of the range, not an answer.
    at_bound = fit.active_mask[2] != 0 or min(abs(fit.x[2] - lo), abs(hi - fit.x[2])) <= DISTANCE_AT_BOUND_M
    if at_bound:
        raise CalibrationError(
            f"the port distance ended at {fit.x[2] * 1e3:.4g} mm, the end of distance_range_m={distance_range_m!r}: "
            "widen the range (--distance-range-m MIN MAX), or the views do not determine the distance"
        )
    return port_result(
        port,
        fit.x[3:].reshape(-1, 6),
        residuals,
        problem.sizes,
        parts["noise"] + parts["camera_model"],
        max_normal_std_deg=max_normal_std_deg,
        max_distance_std_m=max_distance_std_m,
        parts=parts,
        model_shifts=shifts,
    )


def _covariance_parts(
    problem: _Problem,
    x: np.ndarray,
    jac: np.ndarray,
    residuals: np.ndarray,
    bread: np.ndarray,
    sigma2: float,
    model_views: Sequence[Sequence[BoardView]],
    template: FlatPort,
) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """The port's covariance parts (:attr:`PortCalibration.covariance_parts`), port block (3, 3), and the
    port's shift per direction of the camera model's spread (:attr:`PortCalibration.camera_model_shifts`)."""
    bounds = np.cumsum([0, *(2 * s for s in problem.sizes)])
    pixel, by_capture = (c[:3, :3] for c in fit_covariances(jac, residuals, bread, sigma2, bounds))
    changes = [_Problem(problem.camera, list(moved), template).residuals(x) - residuals for moved in model_views]
    shifts = propagated_shifts(bread[:3] @ jac.T, changes)  # the port's rows of the fit's change
    parts = {
        "pixel_noise": pixel,
        "by_capture": by_capture,
        "noise": larger_covariance(pixel, by_capture),
        "camera_model": shifts.T @ shifts,
    }
    return parts, shifts


def _require_refraction(
    camera: PinholeCamera, views: list[BoardView], port_residuals: np.ndarray, sigma2: float
) -> None:
    """Refuse views that straight lines of sight explain as well as the best port (within noise).

    Boards captured in air (no port in the light) fit the port model worse than no port at all, and
    its distance runs anywhere in its range; the port's three parameters must improve on straight
    lines by more than :data:`NO_REFRACTION_CHI2` times the corners' variance ``sigma2``.
    """
    straight = _straight_line_residuals_px(camera, views)
    if straight is None:
        return  # no pose without refraction either: nothing to compare
    s_port, s_straight = float(np.sum(port_residuals**2)), float(np.sum(straight**2))
    if s_straight - s_port <= NO_REFRACTION_CHI2 * sigma2:
        n = len(port_residuals)
        raise CalibrationError(
            f"the boards show no refraction: straight lines of sight (no port) fit their corners to "
            f"{math.sqrt(s_straight / n):.3g} px RMS, the best port to {math.sqrt(s_port / n):.3g} px; they look "
            "like in-air captures (for the camera's calibration: lfrefract calibrate camera); give captures "
            "through the port"
        )


def normal_std_deg(port: FlatPort, covariance: np.ndarray) -> float:
    """Standard deviation of ``port``'s normal direction (degrees, the larger axis) for a covariance
    (3, 3) of ``(tilt_x_rad, tilt_y_rad, distance_m)``: through d n / d (tilt_x, tilt_y)."""
    tx, ty = port.tilt_x_rad, port.tilt_y_rad
    dn = np.array(
        [
            [-math.sin(ty) * math.sin(tx), math.cos(ty) * math.cos(tx)],
            [-math.cos(tx), 0.0],
            [-math.cos(ty) * math.sin(tx), -math.sin(ty) * math.cos(tx)],
        ]
    )
    normal_cov = dn @ covariance[:2, :2] @ dn.T
    return math.degrees(math.sqrt(max(float(np.linalg.eigvalsh(normal_cov)[-1]), 0.0)))


def port_result(
    port: FlatPort,
    poses6: np.ndarray,
    residuals_px: np.ndarray,
    sizes: list[int],
    covariance: np.ndarray,
    *,
    max_normal_std_deg: float,
    max_distance_std_m: float,
    parts: dict[str, np.ndarray] | None = None,
    model_shifts: np.ndarray | None = None,
) -> PortCalibration:
    """A fitted port as a :class:`PortCalibration`, after its uncertainty is checked.

    Parameters
    ----------
    port : FlatPort
    poses6 : ndarray, shape (V, 6)
        Each view's board pose: rotation vector (rad) and translation (m), board to camera frame.
    residuals_px : ndarray, shape (2 sum(sizes),)
        The geometric residuals of every view in turn (:func:`board_residuals_px`), pixels.
    sizes : list of int
        Corners per view.
    covariance : ndarray, shape (3, 3)
        Covariance of ``(tilt_x_rad, tilt_y_rad, distance_m)``.
    max_normal_std_deg, max_distance_std_m : float
        As :func:`calibrate_port`.
    parts : dict of str to ndarray, optional
        :attr:`PortCalibration.covariance_parts`.
    model_shifts : ndarray, shape (k, 3), optional
        :attr:`PortCalibration.camera_model_shifts` (default: none, shape (0, 3)).

    Raises
    ------
    CalibrationError
        If the covariance is not finite.
    PortUndeterminedError
        If a standard deviation exceeds its limit (the fit it refuses attached).
    """
    if not np.all(np.isfinite(covariance)):
        raise CalibrationError("the views do not determine the port: its covariance is not finite")
    normal_deg = normal_std_deg(port, covariance)
    distance_std_m = math.sqrt(max(float(covariance[2, 2]), 0.0))
    bounds = np.cumsum([0, *[2 * s for s in sizes]])
    view_rms = np.array([math.sqrt(np.mean(residuals_px[a:b] ** 2)) for a, b in itertools.pairwise(bounds)])
    board_poses = tuple(Pose(rotation=Rotation.from_rotvec(p[:3]).as_matrix(), position_m=p[3:]) for p in poses6)
    result = PortCalibration(
        port=port,
        board_poses=board_poses,
        rms_px=float(math.sqrt(np.mean(residuals_px**2))),
        view_rms_px=view_rms,
        covariance=covariance,
        normal_std_deg=normal_deg,
        distance_std_m=distance_std_m,
        covariance_parts={} if parts is None else dict(parts),
        camera_model_shifts=np.zeros((0, 3)) if model_shifts is None else np.reshape(model_shifts, (-1, 3)),
    )
    if not (normal_deg <= max_normal_std_deg and distance_std_m <= max_distance_std_m):
        raise PortUndeterminedError(
            f"the views do not determine the port: normal std {normal_deg:.3g} deg "
            f"(limit {max_normal_std_deg:g}), distance std {distance_std_m * 1e3:.3g} mm "
            f"(limit {max_distance_std_m * 1e3:g}); use more views, tilted towards and away from the camera",
            calibration=result,
        )
    return result
