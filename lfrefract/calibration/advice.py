"""Which board views would determine a port better: the advice of a port calibration.

A port calibration knows how well its views determine the port (its covariance,
:attr:`lfrefract.calibration.port.PortCalibration.covariance`). Where the normal or the distance is
known worse than a target, :func:`advise_port_views` says which, and which views to add: it places
candidate boards, like the user's, over the field of view (centre, edges and corners), at the
depths the boards were seen at and nearer and farther, facing the camera or turned 30 deg towards
or away about either axis, and kept where the view sees the whole board through the calibrated port
(its outer squares and a margin, as a chessboard detector needs them); each candidate's information
on the port is that of its corners' lines of sight through the calibrated port (the calibration's own residuals,
:func:`lfrefract.calibration.port.board_residuals_px`, their Jacobian by finite differences, the
board's own pose eliminated); and the candidates are taken greedily, each the one that most lowers
the remaining uncertainty relative to the targets, with the uncertainty it leaves.

Each board of the calibration is counted as it was: the candidates' corners are as noisy as the
calibration's residuals said, inflated as its capture-clustered covariance was over the pixel
noise's. What the camera model's uncertainty adds depends on the boards too: per direction of the
model's spread, the port's first-order shift is ``-(J^T J)^-1 J^T dr`` over all boards (``dr`` their
residuals' change with the model moved, each board's pose eliminated); the calibration's own boards
give theirs (:attr:`lfrefract.calibration.port.PortCalibration.camera_model_shifts`), each candidate
its lines of sight as the moved model would have them. So the advice counts that part with the
views added, and names the camera model only where it still exceeds a target with them.

Frames and units: camera frame (OpenCV axes: x right, y down, z forward), metres; board turns are
extrinsic x-y rotations of a board facing the camera, degrees; image positions in the view's pixels.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial.distance import pdist
from scipy.spatial.transform import Rotation

from lfrefract.calibration.port import (
    BoardView,
    PortCalibration,
    normal_std_deg,
    port_from_parameters,
    project_through_port,
)
from lfrefract.errors import ParameterError
from lfrefract.optics.camera_model import CameraModel
from lfrefract.optics.pinhole import PinholeCamera
from lfrefract.optics.port import FlatPort
from lfrefract.optics.ray_correction import Correction
from lfrefract.validate import positive_float, positive_int

__all__ = ["AdvisedView", "PortAdvice", "advise_port_views"]

#: Where candidate boards are centred in the view, as fractions of its width and height.
FIELD_FRACTIONS = (0.25, 0.5, 0.75)
#: Candidate board turns about x and about y, degrees (0: facing the camera).
TURNS_DEG = (-30.0, 0.0, 30.0)
#: Candidate depths beyond the seen ones: this much nearer than the nearest, farther than the farthest.
NEARER, FARTHER = 0.75, 1.3
#: How far beyond its outer squares a candidate board must still lie inside the view, in squares of
#: the board: OpenCV's chessboard detector finds each outer square as a dark quadrilateral, which needs
#: the square's whole outline and some light border around it. On renders
#: (docs/results/2026-12-07-port-advice-renders.md) advised boards with their inner corners in view and
#: their outer squares cut by the view's edge (by 6-17 px, squares of 14-20 px) were located in 10 of 18
#: captures, by chance rather than by the size of the cut; the quarter square also covers the calibrated
#: model's pixels differing from those of the image the detector reads (1-2 px at the view's edge there).
OUTLINE_MARGIN_SQUARES = 0.25
#: Finite-difference steps: port tilts, board rotation and ray slopes (rad), port distance, board and
#: ray positions (m).
_STEP_RAD, _STEP_M = 1e-6, 1e-7


@dataclass(frozen=True)
class AdvisedView:
    """One board view to add, with the uncertainty the port would have with it (and those before).

    Attributes
    ----------
    description : str
        In words: how far, where in the view, how turned.
    centre_m : ndarray, shape (3,)
        The board's centre, camera frame, metres.
    turn_deg : (float, float)
        The board's turn about x and about y from facing the camera, degrees.
    image_px : (float, float)
        Where its centre appears in the view, pixels.
    normal_std_deg, distance_std_m : float
        The port's predicted standard deviations with this view and those advised before it.
    camera_model_normal_deg, camera_model_distance_m : float
        The camera model's part of them (degrees, metres): what its uncertainty alone leaves with these
        views (0 without a camera model).
    """

    description: str
    centre_m: np.ndarray
    turn_deg: tuple[float, float]
    image_px: tuple[float, float]
    normal_std_deg: float
    distance_std_m: float
    camera_model_normal_deg: float = 0.0
    camera_model_distance_m: float = 0.0

    def to_dict(self) -> dict:
        """Plain data for a JSON file."""
        return {
            "description": self.description,
            "centre_m": self.centre_m.tolist(),
            "turn_deg": list(self.turn_deg),
            "image_px": list(self.image_px),
            "normal_std_deg": self.normal_std_deg,
            "distance_std_m": self.distance_std_m,
            "camera_model_normal_deg": self.camera_model_normal_deg,
            "camera_model_distance_m": self.camera_model_distance_m,
        }


@dataclass(frozen=True)
class PortAdvice:
    """What a port calibration's views leave poorly determined, and which views would fix it.

    Attributes
    ----------
    poorly_determined : tuple of str
        ``"normal"`` and/or ``"distance"``: known worse than their targets; empty if neither.
    normal_std_deg, distance_std_m : float
        The port's standard deviations now.
    target_normal_std_deg, target_distance_std_m : float
        The targets.
    views : tuple of AdvisedView
        The views to add, best first (each assuming those before it added); empty if nothing is
        poorly determined.
    camera_model_normal_deg, camera_model_distance_m : float
        What the camera model's uncertainty alone leaves with the calibration's views (degrees, metres;
        0 without one); each advised view states it with the views added.
    """

    poorly_determined: tuple[str, ...]
    normal_std_deg: float
    distance_std_m: float
    target_normal_std_deg: float
    target_distance_std_m: float
    views: tuple[AdvisedView, ...]
    camera_model_normal_deg: float
    camera_model_distance_m: float

    def to_dict(self) -> dict:
        """Plain data for a JSON file."""
        return {
            "poorly_determined": list(self.poorly_determined),
            "normal_std_deg": self.normal_std_deg,
            "distance_std_m": self.distance_std_m,
            "target_normal_std_deg": self.target_normal_std_deg,
            "target_distance_std_m": self.target_distance_std_m,
            "camera_model_normal_deg": self.camera_model_normal_deg,
            "camera_model_distance_m": self.camera_model_distance_m,
            "views": [v.to_dict() for v in self.views],
        }

    def lines(self) -> list[str]:
        """The advice in words, a line each (empty if nothing is poorly determined)."""
        if not self.poorly_determined:
            return []
        known = {
            "normal": f"the normal (+- {self.normal_std_deg:.3f} deg, target {self.target_normal_std_deg:g})",
            "distance": f"the distance (+- {self.distance_std_m * 1e3:.2f} mm, target "
            f"{self.target_distance_std_m * 1e3:g})",
        }
        out = [f"the views leave {' and '.join(known[p] for p in self.poorly_determined)} poorly determined"]
        if not self.views:
            out.append(
                "  no board like these fits whole in the view at the places tried (the field's centre, edges and "
                "corners, turned up to 30 deg): use smaller boards, tilted towards and away from the camera"
            )
        for k, view in enumerate(self.views, 1):
            out.append(
                f"  add {k}: {view.description} (then +- {view.normal_std_deg:.3f} deg, "
                f"+- {view.distance_std_m * 1e3:.2f} mm)"
            )
        # The camera model limits the port only where its part exceeds a target with the views advised.
        last = self.views[-1] if self.views else None
        model_n = self.camera_model_normal_deg if last is None else last.camera_model_normal_deg
        model_d = self.camera_model_distance_m if last is None else last.camera_model_distance_m
        if model_n > self.target_normal_std_deg or model_d > self.target_distance_std_m:
            out.append(
                f"  {'with these views' if last is not None else 'with the views'} the camera model's own "
                f"uncertainty still leaves +- {model_n:.3f} deg, +- {model_d * 1e3:.2f} mm: calibrate the camera "
                "from more in-air boards"
            )
        return out


def advise_port_views(
    camera: PinholeCamera,
    calibration: PortCalibration,
    views: Sequence[BoardView],
    *,
    target_normal_std_deg: float = 0.1,
    target_distance_std_m: float = 1e-3,
    count: int = 3,
    camera_model: CameraModel | None = None,
) -> PortAdvice:
    """Say what a port calibration leaves poorly determined and which board views would fix it.

    Parameters
    ----------
    camera : PinholeCamera
        The view the corners are expressed in (that of the calibration).
    calibration : PortCalibration
        The calibration (:func:`lfrefract.calibration.port.calibrate_port`) of ``views``.
    views : sequence of BoardView
        Its views: the candidates are boards like theirs (the corners of the view seen nearest the
        candidate's depth), seen from the same aperture points as the first view.
    target_normal_std_deg, target_distance_std_m : float
        How well the normal (degrees) and distance (metres) should be known.
    count : int
        How many views to advise at most (fewer once the targets are met).
    camera_model : CameraModel, optional
        The camera model the calibration propagated (its ``model_views``: this model's
        :meth:`~lfrefract.optics.camera_model.CameraModel.spread_corrections`): needed where the
        calibration has a camera model's part (:attr:`PortCalibration.camera_model_shifts`), to say
        what added views make of it; unused where it has none. A calibration with a camera model's
        part but no shifts (made by hand) has that part held as it is.

    Returns
    -------
    PortAdvice

    Raises
    ------
    ParameterError
        For wrong inputs, or a calibration with camera model shifts and no (or another) ``camera_model``.

    Examples
    --------
    >>> advice = advise_port_views(view, calibration, board_views, camera_model=model)  # doctest: +SKIP
    >>> print("\\n".join(advice.lines()))  # doctest: +SKIP
    the views leave the normal (+- 0.240 deg, target 0.1) poorly determined
      add 1: a board 0.30 m away near the view's left edge, turned -30 deg about y (then +- 0.150 deg, ...)
    """
    if not isinstance(camera, PinholeCamera):
        raise ParameterError(f"camera must be a PinholeCamera, got {camera!r}")
    if not isinstance(calibration, PortCalibration):
        raise ParameterError(f"calibration must be a PortCalibration, got {calibration!r}")
    views = list(views)
    if len(views) != len(calibration.board_poses) or not all(isinstance(v, BoardView) for v in views):
        raise ParameterError(
            f"views must be the calibration's {len(calibration.board_poses)} BoardView objects, got {len(views)}"
        )
    target_n = positive_float("target_normal_std_deg", target_normal_std_deg)
    target_d = positive_float("target_distance_std_m", target_distance_std_m)
    count = positive_int("count", count)
    moved = _moved_corrections(calibration, camera_model)
    port = calibration.port
    noise, model = _noise_and_model(calibration)
    now_n, now_d = calibration.normal_std_deg, calibration.distance_std_m
    poorly = tuple(p for p, bad in (("normal", now_n > target_n), ("distance", now_d > target_d)) if bad)
    advised: list[AdvisedView] = []
    if poorly:
        sigma = calibration.rms_px * math.sqrt(_inflation(calibration))
        candidates = _candidates(camera, calibration, views, moved)
        infos = np.array([info for info, _, _ in candidates]).reshape(-1, 3, 3)
        gradients = np.array([g for _, g, _ in candidates]).reshape(
            len(candidates), 3, 0 if moved is None else len(moved[1])
        )
        information = np.linalg.inv(noise)  # the noise part's, per residual variance sigma^2
        # The camera model's part, as least squares over all boards weighs them (alike): the port's
        # information and, per model direction, gradient (J^T dr, poses eliminated) of the boards so far.
        model_information, model_gradient = _model_start(calibration, views) if moved else (None, None)
        taken: set[int] = set()
        for _ in range(min(count, len(candidates))):
            noise_cov = np.linalg.inv(information + infos / sigma**2)
            if model_information is not None and model_gradient is not None:
                shifts = -np.linalg.solve(model_information + infos, model_gradient + gradients)  # (C, 3, k)
                model_cov = shifts @ shifts.transpose(0, 2, 1)
            else:
                model_cov = np.broadcast_to(model, noise_cov.shape)
            cov = noise_cov + model_cov
            n = np.array([normal_std_deg(port, c) for c in cov])
            d = np.sqrt(np.maximum(cov[:, 2, 2], 0.0))
            # Relative to the targets; a view already advised is not advised twice (one pose twice is
            # one view: the calibration refuses it).
            scores = (n / target_n) ** 2 + (d / target_d) ** 2
            scores[list(taken)] = np.inf
            best = int(np.argmin(scores))
            taken.add(best)
            information = information + infos[best] / sigma**2
            if model_information is not None and model_gradient is not None:
                model_information = model_information + infos[best]
                model_gradient = model_gradient + gradients[best]
            advised.append(
                dataclasses.replace(
                    candidates[best][2],
                    normal_std_deg=float(n[best]),
                    distance_std_m=float(d[best]),
                    camera_model_normal_deg=normal_std_deg(port, model_cov[best]),
                    camera_model_distance_m=math.sqrt(max(float(model_cov[best][2, 2]), 0.0)),
                )
            )
            if n[best] <= target_n and d[best] <= target_d:
                break
    return PortAdvice(
        poorly_determined=poorly,
        normal_std_deg=now_n,
        distance_std_m=now_d,
        target_normal_std_deg=target_n,
        target_distance_std_m=target_d,
        views=tuple(advised),
        camera_model_normal_deg=normal_std_deg(port, model),
        camera_model_distance_m=math.sqrt(max(float(model[2, 2]), 0.0)),
    )


def _moved_corrections(
    calibration: PortCalibration, camera_model: CameraModel | None
) -> tuple[Correction, tuple[Correction, ...]] | None:
    """The camera model's correction and its moves along each spread direction, as the calibration
    propagated them; None where the calibration has no camera model shifts."""
    if camera_model is not None and not isinstance(camera_model, CameraModel):
        raise ParameterError(f"camera_model must be a CameraModel or None, got {type(camera_model).__name__}")
    shifts = calibration.camera_model_shifts
    if len(shifts) == 0:
        return None
    moves = () if camera_model is None else camera_model.spread_corrections()
    if camera_model is None or camera_model.correction is None or len(moves) != len(shifts):
        given = "none" if camera_model is None else f"one with {len(moves)}"
        raise ParameterError(
            f"the calibration propagated a camera model's uncertainty along {len(shifts)} directions: "
            f"camera_model must be that model (its spread_corrections), got {given}"
        )
    return camera_model.correction, moves


def _noise_and_model(calibration: PortCalibration) -> tuple[np.ndarray, np.ndarray]:
    """The covariance part of the boards' noise and that of the camera model (3, 3) each."""
    parts = calibration.covariance_parts
    model = parts.get("camera_model", np.zeros((3, 3)))
    noise = parts.get("noise", calibration.covariance - model)
    return noise, model


def _model_start(calibration: PortCalibration, views: list[BoardView]) -> tuple[np.ndarray, np.ndarray]:
    """The calibration's own boards' port information ``J^T J`` (3, 3; poses eliminated, unweighted) and
    their gradient ``J^T dr`` per camera model direction (3, k), from its pixel-noise covariance
    ``(J^T J)^-1 sigma^2`` and its shifts ``-(J^T J)^-1 J^T dr``."""
    n = 2 * sum(len(v.corners_px) for v in views)
    dof = max(n - 3 - 6 * len(views), 1)
    sigma2 = calibration.rms_px**2 * n / dof  # the residual variance the fit scaled its covariance by
    information = sigma2 * np.linalg.inv(calibration.covariance_parts["pixel_noise"])
    return information, -information @ calibration.camera_model_shifts.T


def _inflation(calibration: PortCalibration) -> float:
    """How much noisier the calibration found its boards than their pixel residuals say: the largest
    ratio of its noise covariance to the pixel noise's over directions (1 without the parts)."""
    parts = calibration.covariance_parts
    if "pixel_noise" not in parts or "noise" not in parts:
        return 1.0
    # "noise" is already the larger of the two in every direction (calibrate_port): the ratio is >= 1.
    values = np.linalg.eigvals(np.linalg.solve(parts["pixel_noise"], parts["noise"])).real
    return float(max(1.0, values.max(initial=1.0)))


def _outline(board: np.ndarray) -> np.ndarray:
    """Points along a board's outline (M, 2, board frame, metres): its inner-corner grid ``board`` (N, 2)
    extended by its outer squares and :data:`OUTLINE_MARGIN_SQUARES` on every side, a point at least
    every square along each edge."""
    square = float(pdist(board).min())  # neighbouring inner corners: one square apart
    reach = (1.0 + OUTLINE_MARGIN_SQUARES) * square
    lo, hi = board.min(axis=0) - reach, board.max(axis=0) + reach
    nx, ny = (math.ceil((h - low) / square) + 1 for low, h in zip(lo, hi, strict=True))
    xs, ys = np.linspace(lo[0], hi[0], nx), np.linspace(lo[1], hi[1], ny)
    return np.concatenate(
        [np.column_stack([xs, np.full(nx, y)]) for y in (lo[1], hi[1])]
        + [np.column_stack([np.full(ny, x), ys]) for x in (lo[0], hi[0])]
    )


def _seen(
    camera: PinholeCamera, port: FlatPort, boards: list[np.ndarray], pose6: np.ndarray, apertures: np.ndarray
) -> tuple[np.ndarray, ...]:
    """Every point of every board ``boards[k]`` (board frame) at pose ``pose6[k]`` from every aperture
    point, as rows: (candidate index, aperture point (3,), board point (2,), pixel (2,), in view)."""
    which = np.concatenate([np.full(len(b) * len(apertures), k) for k, b in enumerate(boards)])
    points = np.concatenate([np.tile(b, (len(apertures), 1)) for b in boards])
    origins = np.concatenate([np.repeat(apertures, len(b), axis=0) for b in boards])
    rotations = Rotation.from_rotvec(pose6[:, :3]).as_matrix()
    world = np.einsum("nij,nj->ni", rotations[which], np.column_stack([points, np.zeros(len(points))]))
    world += pose6[which, 3:]
    pixels = np.full((len(world), 2), np.nan)
    for aperture in apertures:
        rows = np.all(origins == aperture, axis=1)
        pixels[rows] = project_through_port(camera, port, world[rows], centre_m=tuple(aperture))
    inside = np.all(np.isfinite(pixels), axis=1) & np.all(
        (pixels >= 0.0) & (pixels <= [camera.width_px - 1, camera.height_px - 1]), axis=1
    )
    return which, origins, points, pixels, inside


def _candidates(
    camera: PinholeCamera,
    calibration: PortCalibration,
    views: list[BoardView],
    moved: tuple[Correction, tuple[Correction, ...]] | None,
) -> list[tuple[np.ndarray, np.ndarray, AdvisedView]]:
    """Candidate boards that the view sees whole (outer squares and margin, :func:`_outline`, in the central
    view) through the calibrated port, each with its information on the port per unit residual variance (3, 3) and its
    gradient ``J^T dr`` per camera model direction (3, k; k = 0 without ``moved``), poses eliminated,
    all candidates at once (none where no board like the views' fits whole at any candidate place)."""
    port = calibration.port
    depths_seen = np.array([pose.position_m[2] for pose in calibration.board_poses])
    seen_at = np.quantile(depths_seen, [0.0, 0.5, 1.0])
    depths = sorted({round(float(z), 4) for z in (*seen_at, NEARER * seen_at[0], FARTHER * seen_at[2])})
    apertures = np.unique(views[0].centres, axis=0)
    boards, outlines, poses, described = [], [], [], []
    for depth in depths:
        like = views[int(np.argmin(np.abs(depths_seen - depth)))]
        board = np.unique(like.board_points_m[like.central] if like.central.any() else like.board_points_m, axis=0)
        outline = _outline(board)
        for fu in FIELD_FRACTIONS:
            for fv in FIELD_FRACTIONS:
                uv = np.array([[fu * camera.width_px, fv * camera.height_px]])
                trace = port.trace_from_air(np.zeros((1, 3)), camera.pixel_directions(uv))
                start, direction = trace.exit_points_cam[0], trace.directions_cam[0]
                if not (np.all(np.isfinite(direction)) and direction[2] > 0.0):
                    continue
                centre = start + direction * (depth - start[2]) / direction[2]
                for tx in TURNS_DEG:
                    for ty in TURNS_DEG:
                        boards.append(board)
                        outlines.append(outline)
                        poses.append(
                            np.concatenate([Rotation.from_euler("xy", [tx, ty], degrees=True).as_rotvec(), centre])
                        )
                        described.append(
                            AdvisedView(
                                description=_describe(depth, fu, fv, tx, ty),
                                centre_m=centre,
                                turn_deg=(tx, ty),
                                image_px=(float(uv[0, 0]), float(uv[0, 1])),
                                normal_std_deg=math.nan,
                                distance_std_m=math.nan,
                            )
                        )
    pose6 = np.array(poses)
    # Whole in view: the outline in the central view, where the board is found (a detector needs its
    # outer squares there: lfrefract.calibration.port.board_view_from_light_field), and every inner
    # corner from every aperture point (their lines of sight give the information).
    which_o, *_, inside_o = _seen(camera, port, outlines, pose6, np.zeros((1, 3)))
    which, origins, points, pixels, inside = _seen(camera, port, boards, pose6, apertures)
    outside = np.bincount(which_o, weights=~inside_o, minlength=len(poses)) + np.bincount(
        which, weights=~inside, minlength=len(poses)
    )
    whole = outside == 0
    keep = whole[which]
    information, gradient = _information(
        camera, port, origins[keep], pixels[keep], points[keep], pose6, which[keep], moved
    )
    return [
        (information[k], gradient[k], described[k])
        for k in np.flatnonzero(whole)
        if np.all(np.isfinite(information[k])) and np.all(np.isfinite(gradient[k]))
    ]


def _ray_moves(
    moved: tuple[Correction, tuple[Correction, ...]], origins: np.ndarray, directions: np.ndarray
) -> list[np.ndarray]:
    """How each direction of the camera model's spread moves the model's rays (origins (R, 3) on z = 0,
    unit directions (R, 3)): per direction, (R, 4) changes of the origin's (x, y) (m) and the slopes
    (x, y); NaN where the model has no thin-lens ray for a ray."""
    correction, moves = moved
    a, t, _ = correction.thin_lens_rays(origins, directions)
    o0, d0 = correction.apply(a, t)
    out = []
    for move in moves:
        o, d = move.apply(a, t)
        out.append(np.column_stack([o[:, :2] - o0[:, :2], d[:, :2] / d[:, 2:3] - d0[:, :2] / d0[:, 2:3]]))
    return out


def _information(
    camera: PinholeCamera,
    port: FlatPort,
    origins: np.ndarray,
    pixels: np.ndarray,
    points: np.ndarray,
    pose6: np.ndarray,
    which: np.ndarray,
    moved: tuple[Correction, tuple[Correction, ...]] | None,
) -> tuple[np.ndarray, np.ndarray]:
    """Each candidate's information on (tilt x, tilt y, distance), its board pose eliminated, per
    unit residual variance: (K, 3, 3) for the K poses, from rows of aperture points ``origins``,
    corner pixels, board points and candidate indices ``which``; and its gradient ``J^T dr`` (K, 3, k)
    for the residuals' change ``dr`` along each of the camera model's ``k`` directions (``moved``),
    its pose eliminated alike (k = 0 without ``moved``)."""
    directions = camera.pixel_directions(pixels)
    base = np.array([port.tilt_x_rad, port.tilt_y_rad, port.distance_m])

    def residuals(
        params: np.ndarray, poses: np.ndarray, origins: np.ndarray = origins, directions: np.ndarray = directions
    ) -> np.ndarray:
        """The calibration's residuals (:func:`lfrefract.calibration.port.board_residuals_px`), rows (R, 2)."""
        trace = port_from_parameters(params, port).trace_from_air(origins, directions)
        origin, d = trace.exit_points_cam, trace.directions_cam
        rot = Rotation.from_rotvec(poses[:, :3]).as_matrix()[which]
        t = poses[which, 3:]
        normal = rot[:, :, 2]
        s = np.sum((t - origin) * normal, axis=1) / np.sum(d * normal, axis=1)
        hit = origin + s[:, None] * d
        local = np.einsum("nji,nj->ni", rot, hit - t)[:, :2]
        return (local - points) * (camera.focal_px / hit[:, 2:3])

    r0 = residuals(base, pose6)
    columns = []
    for k, step in enumerate((_STEP_RAD, _STEP_RAD, _STEP_M)):
        columns.append((residuals(base + np.eye(3)[k] * step, pose6) - r0) / step)
    for k, step in enumerate((_STEP_RAD,) * 3 + (_STEP_M,) * 3):
        columns.append((residuals(base, pose6 + np.eye(6)[k] * step) - r0) / step)
    jac = np.stack(columns, axis=2)  # (R, 2, 9)
    gram = np.zeros((len(pose6), 9, 9))
    np.add.at(gram, which, np.einsum("rci,rcj->rij", jac, jac))
    a, b, c = gram[:, :3, :3], gram[:, :3, 3:], gram[:, 3:, 3:]
    moves = [] if moved is None else _ray_moves(moved, origins, directions)
    gradient = np.zeros((len(pose6), 9, len(moves)))
    if moves:
        # The residuals' change along a move of the rays, linear in it: their Jacobian in the origin's
        # (x, y) and the slopes (x, y) of each line of sight.
        slopes = directions[:, :2] / directions[:, 2:3]
        ray_columns = []
        for k, step in enumerate((_STEP_M, _STEP_M, _STEP_RAD, _STEP_RAD)):
            if k < 2:
                shifted = origins + np.eye(3)[k] * step
                ray_columns.append((residuals(base, pose6, origins=shifted) - r0) / step)
            else:
                tilted = np.column_stack([slopes + np.eye(2)[k - 2] * step, np.ones(len(slopes))])
                tilted /= np.linalg.norm(tilted, axis=1, keepdims=True)
                ray_columns.append((residuals(base, pose6, directions=tilted) - r0) / step)
        ray_jac = np.stack(ray_columns, axis=2)  # (R, 2, 4)
        for f, move in enumerate(moves):
            change = np.einsum("rcj,rj->rc", ray_jac, move)  # (R, 2), pixels per unit of the direction
            np.add.at(gradient[:, :, f], which, np.einsum("rci,rc->ri", jac, change))
    with np.errstate(invalid="ignore"):
        reg = c + 1e-12 * np.eye(6)
        information = a - b @ np.linalg.solve(reg, b.transpose(0, 2, 1))
        eliminated = gradient[:, :3] - b @ np.linalg.solve(reg, gradient[:, 3:])
    return information, eliminated


def _describe(depth_m: float, fu: float, fv: float, tx: float, ty: float) -> str:
    """A candidate in words."""
    column = {0.25: "left", 0.5: "", 0.75: "right"}[fu]
    row = {0.25: "top", 0.5: "", 0.75: "bottom"}[fv]
    if not row and not column:
        where = "at the view's centre"
    elif row and column:
        where = f"near the view's {row}-{column} corner"
    else:
        where = f"near the view's {row or column} edge"
    turns = [f"turned {t:+.0f} deg about {axis}" for t, axis in ((tx, "x"), (ty, "y")) if t]
    turned = ", ".join(turns) if turns else "facing the camera"
    return f"a board {depth_m:.2f} m away {where}, {turned}"
