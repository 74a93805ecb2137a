"""Which board views would determine a port better: the advice of a port calibration.

A port calibration knows how well its views determine the port (its covariance,
:attr:`lfrefract.calibration.port.PortCalibration.covariance`). Where the normal or the distance is
known worse than a target, :func:`advise_port_views` says which, and which views to add: it places
candidate boards, like the user's, over the field of view (centre, edges and corners), at the
depths the boards were seen at and nearer and farther, facing the camera or turned 30 deg towards
or away about either axis; each candidate's information on the port is that of its corners' lines
of sight through the calibrated port (the calibration's own residuals,
:func:`lfrefract.calibration.port.board_residuals_px`, their Jacobian by finite differences, the
board's own pose eliminated); and the candidates are taken greedily, each the one that most lowers
the remaining uncertainty relative to the targets, with the uncertainty it leaves.

Each board of the calibration is counted as it was: the candidates' corners are as noisy as the
calibration's residuals said, inflated as its capture-clustered covariance was over the pixel
noise's, and what the camera model's uncertainty adds (a part no further board reduces) stays.

Frames and units: camera frame (OpenCV axes: x right, y down, z forward), metres; board turns are
extrinsic x-y rotations of a board facing the camera, degrees; image positions in the view's pixels.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from lfrefract.calibration.port import (
    BoardView,
    PortCalibration,
    normal_std_deg,
    port_from_parameters,
    project_through_port,
)
from lfrefract.errors import ParameterError
from lfrefract.optics.pinhole import PinholeCamera
from lfrefract.optics.port import FlatPort
from lfrefract.validate import positive_float, positive_int

__all__ = ["AdvisedView", "PortAdvice", "advise_port_views"]

#: Where candidate boards are centred in the view, as fractions of its width and height.
FIELD_FRACTIONS = (0.25, 0.5, 0.75)
#: Candidate board turns about x and about y, degrees (0: facing the camera).
TURNS_DEG = (-30.0, 0.0, 30.0)
#: Candidate depths beyond the seen ones: this much nearer than the nearest, farther than the farthest.
NEARER, FARTHER = 0.75, 1.3
#: Finite-difference steps: port tilts and board rotation (rad), port distance and board position (m).
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
    """

    description: str
    centre_m: np.ndarray
    turn_deg: tuple[float, float]
    image_px: tuple[float, float]
    normal_std_deg: float
    distance_std_m: float

    def to_dict(self) -> dict:
        """Plain data for a JSON file."""
        return {
            "description": self.description,
            "centre_m": self.centre_m.tolist(),
            "turn_deg": list(self.turn_deg),
            "image_px": list(self.image_px),
            "normal_std_deg": self.normal_std_deg,
            "distance_std_m": self.distance_std_m,
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
    camera_model_floor_normal_deg, camera_model_floor_distance_m : float
        What the camera model's uncertainty alone leaves (no board reduces it; 0 without one).
    """

    poorly_determined: tuple[str, ...]
    normal_std_deg: float
    distance_std_m: float
    target_normal_std_deg: float
    target_distance_std_m: float
    views: tuple[AdvisedView, ...]
    camera_model_floor_normal_deg: float
    camera_model_floor_distance_m: float

    def to_dict(self) -> dict:
        """Plain data for a JSON file."""
        return {
            "poorly_determined": list(self.poorly_determined),
            "normal_std_deg": self.normal_std_deg,
            "distance_std_m": self.distance_std_m,
            "target_normal_std_deg": self.target_normal_std_deg,
            "target_distance_std_m": self.target_distance_std_m,
            "camera_model_floor_normal_deg": self.camera_model_floor_normal_deg,
            "camera_model_floor_distance_m": self.camera_model_floor_distance_m,
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
        floor = self.camera_model_floor_normal_deg > self.target_normal_std_deg or (
            self.camera_model_floor_distance_m > self.target_distance_std_m
        )
        if floor:
            out.append(
                f"  the camera model's own uncertainty leaves +- {self.camera_model_floor_normal_deg:.3f} deg, "
                f"+- {self.camera_model_floor_distance_m * 1e3:.2f} mm whatever the views: calibrate the camera "
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

    Returns
    -------
    PortAdvice

    Examples
    --------
    >>> advice = advise_port_views(view, calibration, board_views)  # doctest: +SKIP
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
    port = calibration.port
    noise, model = _noise_and_model(calibration)
    floor_n, floor_d = normal_std_deg(port, model), math.sqrt(max(float(model[2, 2]), 0.0))
    now_n, now_d = calibration.normal_std_deg, calibration.distance_std_m
    poorly = tuple(p for p, bad in (("normal", now_n > target_n), ("distance", now_d > target_d)) if bad)
    advised: list[AdvisedView] = []
    if poorly:
        sigma = calibration.rms_px * math.sqrt(_inflation(calibration))
        candidates = _candidates(camera, calibration, views)
        infos = [info / sigma**2 for info, _ in candidates]
        information = np.linalg.inv(noise)
        taken: set[int] = set()
        for _ in range(min(count, len(infos))):
            scores = []
            for k, info in enumerate(infos):
                cov = np.linalg.inv(information + info) + model
                n, d = normal_std_deg(port, cov), math.sqrt(max(float(cov[2, 2]), 0.0))
                # Relative to the targets; a view already advised is not advised twice (one pose twice
                # is one view: the calibration refuses it).
                scores.append((math.inf if k in taken else (n / target_n) ** 2 + (d / target_d) ** 2, n, d))
            best = int(np.argmin([score for score, _, _ in scores]))
            taken.add(best)
            information = information + infos[best]
            _, n, d = scores[best]
            advised.append(dataclasses.replace(candidates[best][1], normal_std_deg=n, distance_std_m=d))
            if n <= target_n and d <= target_d:
                break
    return PortAdvice(
        poorly_determined=poorly,
        normal_std_deg=now_n,
        distance_std_m=now_d,
        target_normal_std_deg=target_n,
        target_distance_std_m=target_d,
        views=tuple(advised),
        camera_model_floor_normal_deg=floor_n,
        camera_model_floor_distance_m=floor_d,
    )


def _noise_and_model(calibration: PortCalibration) -> tuple[np.ndarray, np.ndarray]:
    """The covariance more views reduce (the boards' noise) and the part they do not (the camera model's)."""
    parts = calibration.covariance_parts
    model = parts.get("camera_model", np.zeros((3, 3)))
    noise = parts.get("noise", calibration.covariance - model)
    return noise, model


def _inflation(calibration: PortCalibration) -> float:
    """How much noisier the calibration found its boards than their pixel residuals say: the largest
    ratio of its noise covariance to the pixel noise's over directions (1 without the parts)."""
    parts = calibration.covariance_parts
    if "pixel_noise" not in parts or "noise" not in parts:
        return 1.0
    # "noise" is already the larger of the two in every direction (calibrate_port): the ratio is >= 1.
    values = np.linalg.eigvals(np.linalg.solve(parts["pixel_noise"], parts["noise"])).real
    return float(max(1.0, values.max(initial=1.0)))


def _candidates(
    camera: PinholeCamera, calibration: PortCalibration, views: list[BoardView]
) -> list[tuple[np.ndarray, AdvisedView]]:
    """Candidate boards that the view sees whole through the calibrated port, each with its
    information on the port per unit residual variance (3, 3), all candidates at once (none where no
    board like the views' fits whole in the view at any candidate place)."""
    port = calibration.port
    depths_seen = np.array([pose.position_m[2] for pose in calibration.board_poses])
    seen_at = np.quantile(depths_seen, [0.0, 0.5, 1.0])
    depths = sorted({round(float(z), 4) for z in (*seen_at, NEARER * seen_at[0], FARTHER * seen_at[2])})
    apertures = np.unique(views[0].centres, axis=0)
    boards, poses, described = [], [], []
    for depth in depths:
        like = views[int(np.argmin(np.abs(depths_seen - depth)))]
        board = np.unique(like.board_points_m[like.central] if like.central.any() else like.board_points_m, axis=0)
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
    # Every corner of every candidate from every aperture point, as rows.
    which = np.concatenate([np.full(len(b) * len(apertures), k) for k, b in enumerate(boards)])
    points = np.concatenate([np.tile(b, (len(apertures), 1)) for b in boards])
    origins = np.concatenate([np.repeat(apertures, len(b), axis=0) for b in boards])
    pose6 = np.array(poses)
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
    whole = np.bincount(which, weights=~inside, minlength=len(poses)) == 0
    keep = whole[which]
    information = _information(camera, port, origins[keep], pixels[keep], points[keep], pose6, which[keep])
    return [(information[k], described[k]) for k in np.flatnonzero(whole) if np.all(np.isfinite(information[k]))]


def _information(
    camera: PinholeCamera,
    port: FlatPort,
    origins: np.ndarray,
    pixels: np.ndarray,
    points: np.ndarray,
    pose6: np.ndarray,
    which: np.ndarray,
) -> np.ndarray:
    """Each candidate's information on (tilt x, tilt y, distance), its board pose eliminated, per
    unit residual variance: (K, 3, 3) for the K poses, from rows of aperture points ``origins``,
    corner pixels, board points and candidate indices ``which``."""
    directions = camera.pixel_directions(pixels)
    base = np.array([port.tilt_x_rad, port.tilt_y_rad, port.distance_m])

    def residuals(params: np.ndarray, poses: np.ndarray) -> np.ndarray:
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
    with np.errstate(invalid="ignore"):
        return a - b @ np.linalg.solve(c + 1e-12 * np.eye(6), b.transpose(0, 2, 1))


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
