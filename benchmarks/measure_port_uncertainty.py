"""Does the port calibration's stated uncertainty cover its error? A synthetic study over lenses and seeds.

Each lens (a preset name or a lens file), scaled and stopped to the ``tiny-2x`` camera, is the truth:
its true rays (``RealLensCamera.chief_rays`` of every 2nd raw pixel, with the micro-image lattice the
lens gives, as an MLA calibration from a white image would measure it) fitted by a polynomial ray model
of capacity (7, 3) without the frame's directions (``PolynomialCorrection``; 0.002 mm from the true
rays on the presets), so that truth and calibration share one frame. For each seed:

1. ten in-air boards (7 x 5 corners, 0.15-0.35 m, spanning 0.4-0.6 of the view) are seen from five
   aperture points (the centre and four at 0.3 of the aperture radius), each corner along the thin-lens
   slope whose true ray passes it, with ``--noise-px`` Gaussian noise in the pinhole view;
2. the camera is calibrated from them (``calibrate_camera``, ``--ray-model``);
3. ten boards in the water (0.2-0.5 m) behind a port of the given tilts are seen the same way through
   the port, and the port is calibrated on the calibrated model, with its spread propagated
   (``calibrate_port(model_views=...)``);
4. the port's normal and distance errors are divided by the stated standard deviations.

Prints one row per run and, per lens, the share of runs with both errors within 3 stated sigma.

    python benchmarks/measure_port_uncertainty.py [--lenses double-gauss scenes/lenses/tessar.toml] [--seeds 5]
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time

import numpy as np
from scipy.spatial.transform import Rotation

from lfrefract import camera_preset, virtual_camera_for
from lfrefract.calibration import calibrate_camera, calibrate_port
from lfrefract.calibration.camera import corrected_view
from lfrefract.calibration.port import BoardView
from lfrefract.optics.port import FlatPort
from lfrefract.optics.ray_correction import PolynomialCorrection, frame_directions, moved, polynomial_exponents
from lfrefract.optics.real_lens import RealLensCamera
from simulator.config import main_lens

CAMERA_NAME = "tiny-2x"
#: Where the four outer aperture points lie, as a fraction of the aperture radius: inside the pupil
#: of the designs that vignette their axial beam at the camera's f-number (working at about twice it).
APERTURE_FRACTION = 0.3
#: The board: inner corners and their spacing relative to the board's distance.
PATTERN = (7, 5)


def truth_model(lens_name: str):
    """The thin-lens camera with the lens's micro-image lattice, and the lens's rays as a (7, 3) model."""
    nominal = camera_preset(CAMERA_NAME)
    real = RealLensCamera(camera=nominal, lens=main_lens(lens_name, nominal))
    scale = real.micro_image_scale / nominal.micro_image_scale
    camera = dataclasses.replace(nominal, mla=dataclasses.replace(nominal.mla, pitch_m=nominal.mla.pitch_m * scale))
    vv, uu = np.mgrid[0 : nominal.sensor.height_px : 2, 0 : nominal.sensor.width_px : 2]
    uv = np.stack([uu.ravel(), vv.ravel()], axis=1).astype(float)
    thin, true = camera.captured_rays(uv), real.chief_rays(uv)
    ok = thin.in_aperture & true.in_aperture & np.all(np.isfinite(true.directions_cam), axis=1)
    a = thin.origins_cam[ok, :2]
    t = thin.directions_cam[ok, :2] / thin.directions_cam[ok, 2:3]
    slopes = true.directions_cam[ok, :2] / true.directions_cam[ok, 2:3]
    origins = true.origins_cam[ok, :2] - true.origins_cam[ok, 2:3] * slopes
    half_diagonal = 0.5 * math.hypot(camera.sensor.width_px, camera.sensor.height_px) * camera.sensor.pixel_pitch_m
    template = PolynomialCorrection(
        degree=7,
        aperture_degree=3,
        aperture_norm_m=camera.aperture_radius_m,
        slope_norm=half_diagonal / camera.lens_to_mla_m,
        coefficients=np.zeros((len(polynomial_exponents(7, 3)), 4)),
    )
    phi = template.monomials(a, t)
    norms = np.array([template.aperture_norm_m] * 2 + [template.slope_norm] * 2)
    target = np.column_stack([origins - a, slopes - t]) / norms
    coefficients = np.linalg.lstsq(phi, target, rcond=None)[0]  # normalised (M, 4)
    fixed = frame_directions(template.exponents)
    flat = coefficients.ravel() - fixed.T @ (fixed @ coefficients.ravel())
    return camera, dataclasses.replace(template, coefficients=flat.reshape(-1, 4) * norms)


def _slopes_seeing(truth, a, corners, port: FlatPort | None) -> np.ndarray:
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


def board_views(truth, camera, view, rng, *, n: int, depths, port: FlatPort | None, noise_px: float):
    """``n`` boards at random poses in the view, seen from five aperture points."""
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
        t = _slopes_seeing(truth, a, points, port)
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


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--lenses", nargs="*", default=["double-gauss"])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--noise-px", type=float, default=0.05)
    parser.add_argument(
        "--ray-model",
        choices=("radial", "polynomial", "truth"),
        default="polynomial",
        help="the camera model the port is calibrated on; truth: the true rays (no camera calibration, no spread)",
    )
    parser.add_argument("--tilt-deg", type=float, nargs=2, default=(20.0, 10.0))
    parser.add_argument("--distance-m", type=float, default=0.03)
    parser.add_argument("--thickness-m", type=float, default=0.005)
    args = parser.parse_args()
    port = FlatPort.from_degrees(
        distance_m=args.distance_m,
        thickness_m=args.thickness_m,
        tilt_x_deg=args.tilt_deg[0],
        tilt_y_deg=args.tilt_deg[1],
    )
    print("| lens | seed | model | normal error, deg (z) | distance error, mm (z) | camera-model share |")
    print("| --- | ---: | --- | ---: | ---: | ---: |")
    for name in args.lenses:
        camera, truth = truth_model(name)
        view = virtual_camera_for(camera)
        covered = []
        for seed in range(args.seeds):
            start = time.perf_counter()
            rng = np.random.default_rng(seed)
            in_air = board_views(truth, camera, view, rng, n=10, depths=(0.15, 0.35), port=None, noise_px=args.noise_px)
            water = board_views(truth, camera, view, rng, n=10, depths=(0.2, 0.5), port=port, noise_px=args.noise_px)
            if args.ray_model == "truth":
                correction, spread = truth, np.zeros((0, truth.vector().size))
            else:
                calibration = calibrate_camera(camera, in_air, view=view, ray_model=args.ray_model)
                correction, spread = calibration.correction, calibration.spread
            model_views = [[corrected_view(v, moved(correction, f), view) for v in water] for f in spread]
            result = calibrate_port(
                view,
                [corrected_view(v, correction, view) for v in water],
                thickness_m=port.thickness_m,
                n_water=port.n_water,
                n_glass=port.n_glass,
                model_views=model_views,
            )
            normal_error = math.degrees(math.acos(min(1.0, float(result.port.normal @ port.normal))))
            distance_error = result.port.distance_m - port.distance_m
            z_normal = normal_error / result.normal_std_deg
            z_distance = abs(distance_error) / result.distance_std_m
            share = result.covariance_parts["camera_model"][2, 2] / result.covariance[2, 2]
            covered.append(z_normal <= 3.0 and z_distance <= 3.0)
            label = "truth" if args.ray_model == "truth" else getattr(correction, "name", "radial")
            print(
                f"| {name} | {seed} | {label} | {normal_error:.4f} ({z_normal:.2f}) | {distance_error * 1e3:+.4f} "
                f"({z_distance:.2f}) | {share:.0%} | {time.perf_counter() - start:.0f} s |",
                flush=True,
            )
        print(f"| {name} | all | | within 3 sigma: {sum(covered)} of {len(covered)} | | |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
