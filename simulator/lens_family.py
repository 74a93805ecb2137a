"""The lens family as ground truth without rendering: board light fields seen along a real lens's rays.

A real main lens (a preset or a lens file, scaled and stopped to a camera) is traced exactly by
:class:`lfrefract.optics.real_lens.RealLensCamera`; :func:`truth_model` fits its true rays by a
polynomial ray model of high capacity in the calibrated model's frame (0.002 mm from them on the
presets), so that a calibration and the truth share one frame. :func:`board_views` then gives the
corners of chessboards at chosen poses, in air or behind a port, as a light field sees them: each from
a few aperture points, along the thin-lens slope whose true ray passes it, with Gaussian corner noise.
The camera calibration and the port calibration run on them as on renders, in seconds, so their
accuracy and the coverage of their stated uncertainty can be measured over many lenses and seeds
(``benchmarks/measure_port_uncertainty.py``, ``tests/simulator/test_lens_family_calibration.py``).

Frames and units: camera frame (OpenCV axes), metres.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy.spatial.transform import Rotation

from lfrefract import camera_preset
from lfrefract.calibration.camera import corrected_view
from lfrefract.calibration.port import BoardView, PortCalibration, calibrate_port
from lfrefract.optics.camera import LightFieldCamera
from lfrefract.optics.pinhole import PinholeCamera
from lfrefract.optics.port import FlatPort
from lfrefract.optics.ray_correction import (
    Correction,
    PolynomialCorrection,
    frame_directions,
    moved,
    polynomial_exponents,
)
from lfrefract.optics.real_lens import RealLensCamera
from simulator.config import main_lens

__all__ = ["APERTURE_FRACTION", "PATTERN", "board_views", "port_on_model", "slopes_seeing", "truth_model"]

#: Where the four outer aperture points lie, as a fraction of the aperture radius: inside the pupil
#: of the designs that vignette their axial beam at the camera's f-number (working at about twice it).
APERTURE_FRACTION = 0.3
#: The board: inner corners and their spacing relative to the board's distance.
PATTERN = (7, 5)


def truth_model(
    lens_name: str,
    *,
    camera: str = "tiny-2x",
    pixel_step: int = 2,
    capacity: tuple[int, int] = (7, 3),
    calibration_frame: bool = True,
) -> tuple[LightFieldCamera, PolynomialCorrection]:
    """The thin-lens camera with the lens's micro-image lattice (what an MLA calibration from a white
    image measures), and the lens's true rays of every ``pixel_step``-th raw pixel fitted by a
    polynomial model of ``capacity``.

    Parameters
    ----------
    lens_name : str
        A lens preset or a lens file (:func:`simulator.config.main_lens`), scaled and stopped to the camera.
    camera : str
        The camera preset.
    calibration_frame : bool
        True: the rays in the frame a calibration reports (moved to the paraxial entrance pupil,
        :attr:`~lfrefract.optics.real_lens.RealLensCamera.calibration_origin_cam`, and the fit's
        remaining frame directions, a few micrometres of the fit's own, removed); False: in the
        simulator's camera frame, the frame of a render's truth (its port, its boards).
    """
    nominal = camera_preset(camera)
    real = RealLensCamera(camera=nominal, lens=main_lens(lens_name, nominal))
    camera = real.lattice_camera
    vv, uu = np.mgrid[0 : nominal.sensor.height_px : pixel_step, 0 : nominal.sensor.width_px : pixel_step]
    uv = np.stack([uu.ravel(), vv.ravel()], axis=1).astype(float)
    thin, true = camera.captured_rays(uv), real.chief_rays(uv)
    ok = thin.in_aperture & true.in_aperture & np.all(np.isfinite(true.directions_cam), axis=1)
    a = thin.origins_cam[ok, :2]
    t = thin.directions_cam[ok, :2] / thin.directions_cam[ok, 2:3]
    slopes = true.directions_cam[ok, :2] / true.directions_cam[ok, 2:3]
    # the true rays where they cross z = 0 of the frame: the simulator's, or the one a calibration
    # reports (the same rays, moved to the paraxial entrance pupil)
    start = true.origins_cam[ok] - (real.calibration_origin_cam if calibration_frame else 0.0)
    origins = start[:, :2] - start[:, 2:3] * slopes
    half_diagonal = 0.5 * math.hypot(camera.sensor.width_px, camera.sensor.height_px) * camera.sensor.pixel_pitch_m
    template = PolynomialCorrection(
        degree=capacity[0],
        aperture_degree=capacity[1],
        aperture_norm_m=camera.aperture_radius_m,
        slope_norm=half_diagonal / camera.lens_to_mla_m,
        coefficients=np.zeros((len(polynomial_exponents(*capacity)), 4)),
    )
    phi = template.monomials(a, t)
    norms = np.array([template.aperture_norm_m] * 2 + [template.slope_norm] * 2)
    target = np.column_stack([origins - a, slopes - t]) / norms
    coefficients = np.linalg.lstsq(phi, target, rcond=None)[0]  # normalised (M, 4)
    if not calibration_frame:
        return camera, dataclasses.replace(template, coefficients=coefficients * norms)
    fixed = frame_directions(template.exponents)
    flat = coefficients.ravel() - fixed.T @ (fixed @ coefficients.ravel())
    return camera, dataclasses.replace(template, coefficients=flat.reshape(-1, 4) * norms)


def slopes_seeing(truth: PolynomialCorrection, a: np.ndarray, corners: np.ndarray, port: FlatPort | None) -> np.ndarray:
    """Thin-lens slopes (N, 2) from aperture points ``a`` whose true rays (through ``port``) pass ``corners``."""
    t = (corners[:, :2] - a) / corners[:, 2:3]

    def miss(t_: np.ndarray) -> np.ndarray:
        t_ = np.where(np.isfinite(t_), t_, 0.0)  # a diverged row: kept finite, refused below
        origins, directions = truth.apply(a, t_)
        if port is not None:
            trace = port.trace_from_air(origins, directions)
            origins, directions = trace.exit_points_cam, trace.directions_cam
        s = (corners[:, 2] - origins[:, 2]) / directions[:, 2]
        return origins[:, :2] + s[:, None] * directions[:, :2] - corners[:, :2]

    for _ in range(30):
        r = miss(t)
        h = 1e-7
        step_x, step_y = np.array([h, 0.0]), np.array([0.0, h])
        jac = np.stack([(miss(t + step_x) - r) / h, (miss(t + step_y) - r) / h], axis=2)
        det = jac[:, 0, 0] * jac[:, 1, 1] - jac[:, 0, 1] * jac[:, 1, 0]
        with np.errstate(invalid="ignore", divide="ignore"):
            step = (
                np.column_stack(
                    [jac[:, 1, 1] * r[:, 0] - jac[:, 0, 1] * r[:, 1], jac[:, 0, 0] * r[:, 1] - jac[:, 1, 0] * r[:, 0]]
                )
                / det[:, None]
            )  # the 2 x 2 inverse; a singular row becomes NaN, refused below
            t = t - step
    return np.where(np.all(np.abs(miss(t)) < 1e-9, axis=1)[:, None], t, np.nan)


def board_views(
    truth: PolynomialCorrection,
    camera: LightFieldCamera,
    view: PinholeCamera,
    rng: np.random.Generator,
    *,
    n: int,
    depths: tuple[float, float],
    port: FlatPort | None,
    noise_px: float,
) -> list[BoardView]:
    """``n`` boards of :data:`PATTERN` inner corners at random poses (0.4-0.6 of the view wide, their
    centres in its middle half, turned up to 25 deg about x and y and 7.5 about z, depth uniform in
    ``depths``, metres), each corner seen from the aperture's centre and four points at
    :data:`APERTURE_FRACTION` of its radius along the true ray that passes it (through ``port``, or in
    air), as pixels of ``view`` with ``noise_px`` of Gaussian noise; a board any of whose corners is
    out of the view or unseen is drawn again."""
    r = APERTURE_FRACTION * camera.aperture_radius_m
    aperture = np.array([(0.0, 0.0), (r, 0.0), (-r, 0.0), (0.0, r), (0.0, -r)])
    gx, gy = np.meshgrid(np.arange(PATTERN[0]) - (PATTERN[0] - 1) / 2, np.arange(PATTERN[1]) - (PATTERN[1] - 1) / 2)
    grid = np.column_stack([gx.ravel(), gy.ravel()])
    k_inverse = np.linalg.inv(view.K)
    views = []
    while len(views) < n:
        depth = rng.uniform(*depths)
        centre_px = rng.uniform(
            [0.25 * view.width_px, 0.25 * view.height_px], [0.75 * view.width_px, 0.75 * view.height_px]
        )
        sight = k_inverse @ np.array([*centre_px, 1.0])
        centre = sight / sight[2] * depth
        width = rng.uniform(0.4, 0.6) * view.width_px / view.K[0, 0] * depth
        board = grid * width / (PATTERN[0] - 1)
        rotation = Rotation.from_euler("xyz", rng.uniform(-25, 25, 3) * [1, 1, 0.3], degrees=True).as_matrix()
        corners = np.column_stack([board, np.zeros(len(board))]) @ rotation.T + centre
        a = np.repeat(aperture, len(corners), axis=0)
        points = np.tile(corners, (len(aperture), 1))
        t = slopes_seeing(truth, a, points, port)
        pixels = np.column_stack([t, np.ones(len(t))]) @ view.K.T
        inside = np.all(np.isfinite(pixels), axis=1) & np.all(
            (pixels[:, :2] > 0) & (pixels[:, :2] < [view.width_px - 1, view.height_px - 1]), axis=1
        )
        if not inside.all():
            continue
        views.append(
            BoardView(
                corners_px=pixels[:, :2] + rng.normal(0.0, noise_px, (len(t), 2)),
                board_points_m=np.tile(board, (len(aperture), 1)),
                centres_m=np.column_stack([a, np.zeros(len(a))]),
            )
        )
    return views


def port_on_model(
    view: PinholeCamera, water: list[BoardView], correction: Correction, spread: np.ndarray, port: FlatPort
) -> PortCalibration:
    """The port calibrated from ``water`` boards on the camera model ``correction`` (the glass and
    indices of ``port`` known), the model's ``spread`` (k, n) propagated into its covariance."""
    return calibrate_port(
        view,
        [corrected_view(v, correction, view) for v in water],
        thickness_m=port.thickness_m,
        n_water=port.n_water,
        n_glass=port.n_glass,
        model_views=[[corrected_view(v, moved(correction, f), view) for v in water] for f in spread],
    )
