"""The lens-family test, without rendering (simulator.lens_family): every lens file of scenes/lenses/ and
the double Gauss, at the tiny-2x camera's pixel pitch and at the Illum's, each lens's true rays as the
truth (a degree-5 fit), ten boards seen along them in air and ten behind a port tilted 20 / 10 deg about
x / y with 0.05 px of corner noise (seed 0). The camera's ray model is calibrated (the polynomial
family, capacity by held-back boards), the port on it; then:

- the port's normal and distance errors lie within three of its stated standard deviations, on every
  lens at both pitches (what the issue asks of the stated uncertainty);
- at the Illum's pitch the issue's accuracy: rays within 0.05 mm and 1 mrad of the true ones at the
  port face, the normal within 0.1 deg and the distance within 1 mm;
- at tiny-2x, where ten boards of 189 x 141 px views leave the normal 0.04-0.18 deg uncertain, bounds of
  about twice the worst seen (the misses of the issue's targets are in docs/calibration.md).

No lens here was used while the calibration was written (the double Gauss was: it is the reference)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from lfrefract import camera_preset, virtual_camera_for
from lfrefract.calibration import calibrate_camera
from lfrefract.optics.port import FlatPort
from lfrefract.optics.ray_correction import POLYNOMIAL_CAPACITIES
from lfrefract.optics.real_lens import RealLensCamera
from simulator.config import main_lens
from simulator.lens_family import board_views, port_on_model, truth_model
from tests.tolerances import LENS_FAMILY_BOUNDS, LENS_FAMILY_FRAME_M, LENS_FAMILY_FRAME_SLOPE

LENS_DIR = Path(__file__).resolve().parents[2] / "scenes" / "lenses"
LENSES = ("double-gauss", *(str(p) for p in sorted(LENS_DIR.glob("*.toml"))))
CAMERAS = ("tiny-2x", "illum")
LENS = str(LENS_DIR / "heliar.toml")
SYMMETRIC = tuple(c for c in POLYNOMIAL_CAPACITIES if c.symmetric)
PORT = FlatPort.from_degrees(distance_m=0.03, thickness_m=0.005, tilt_x_deg=20.0, tilt_y_deg=10.0)
pytestmark = pytest.mark.minutes  # about 4 minutes: scheduled first

#: Raw pixels per truth-fit sample along each axis, by camera (the Illum's sensor has 58 times the pixels).
PIXEL_STEP = {"tiny-2x": 2, "illum": 8}


@pytest.fixture(
    scope="module",
    params=[(lens, camera) for camera in CAMERAS for lens in LENSES],
    ids=lambda p: f"{Path(p[0]).stem}-{p[1]}",
)
def chain(request):
    lens, camera_name = request.param
    camera, truth = truth_model(lens, camera=camera_name, pixel_step=PIXEL_STEP[camera_name], capacity=(5, 3))
    view = virtual_camera_for(camera)
    rng = np.random.default_rng(0)
    in_air = board_views(truth, camera, view, rng, n=10, depths=(0.15, 0.35), port=None, noise_px=0.05)
    # CI's size: the symmetric members only (a centred lens; the benchmark runs the whole ladder).
    calibration = calibrate_camera(camera, in_air, view=view, ray_model="polynomial", capacities=SYMMETRIC)
    water = board_views(truth, camera, view, rng, n=10, depths=(0.2, 0.5), port=PORT, noise_px=0.05)
    port = port_on_model(view, water, calibration.correction, calibration.spread, PORT)
    return camera_name, camera, truth, calibration, port


def test_the_calibrated_rays_come_near_the_true_ones_at_the_port_face(chain):
    camera_name, camera, truth, calibration, _ = chain
    rng = np.random.default_rng(1)
    radius = 0.3 * camera.aperture_radius_m  # where the boards were seen from
    a = rng.uniform(-radius, radius, (4000, 2))
    t = rng.uniform(-0.25, 0.25, (4000, 2))
    o0, s0 = truth.origins_and_slopes(a, t)
    o1, s1 = calibration.correction.origins_and_slopes(a, t)
    at_face = (o1 + PORT.distance_m * s1) - (o0 + PORT.distance_m * s0)
    d0, d1 = (np.column_stack([s, np.ones(len(s))]) for s in (s0, s1))
    cosine = np.sum(d0 * d1, axis=1) / np.linalg.norm(d0, axis=1) / np.linalg.norm(d1, axis=1)
    bounds = LENS_FAMILY_BOUNDS[camera_name]
    assert math.sqrt(np.mean(np.sum(at_face**2, axis=1))) < bounds.ray_m
    assert math.sqrt(np.mean(np.arccos(np.clip(cosine, -1.0, 1.0)) ** 2)) < bounds.ray_rad


def test_the_port_is_found_and_its_stated_uncertainty_covers_its_error(chain):
    camera_name, _, _, _, port = chain
    normal_error = math.degrees(math.acos(min(1.0, float(port.port.normal @ PORT.normal))))
    distance_error = abs(port.port.distance_m - PORT.distance_m)
    assert normal_error <= 3.0 * port.normal_std_deg
    assert distance_error <= 3.0 * port.distance_std_m
    bounds = LENS_FAMILY_BOUNDS[camera_name]
    assert normal_error < bounds.normal_deg
    assert distance_error < bounds.distance_m


def test_the_calibration_frame_is_the_true_rays_moved_to_the_entrance_pupil():
    """A calibration reports a lens's rays moved along the axis to where its paraxial chief rays cross
    it; the truth in that frame must be the same rays moved rigidly, not a fit with a coefficient
    dropped (which on the retrofocus design at tiny-2x, its entrance pupil 11 mm in front of the
    simulator's origin, left the rays 6.9 um from the true ones moved there; 0.16 um moved)."""
    lens = str(Path(LENS).with_name("retrofocus.toml"))
    _, simulated = truth_model(lens, camera="tiny-2x", pixel_step=8, capacity=(5, 3), calibration_frame=False)
    _, calibrated = truth_model(lens, camera="tiny-2x", pixel_step=8, capacity=(5, 3))
    nominal = camera_preset("tiny-2x")
    pupil_z = RealLensCamera(camera=nominal, lens=main_lens(lens, nominal)).calibration_origin_cam[2]
    assert pupil_z > 5e-3  # in front of the simulator's origin: a move that matters
    rng = np.random.default_rng(2)
    radius = 0.3 * nominal.aperture_radius_m  # where the boards were seen from
    a, t = rng.uniform(-radius, radius, (4000, 2)), rng.uniform(-0.2, 0.2, (4000, 2))
    o0, s0 = simulated.origins_and_slopes(a, t)
    o1, s1 = calibrated.origins_and_slopes(a, t)
    # at the port face, 30 mm in front of the pupil (the simulator's ray: at z = pupil_z + 30 mm)
    at_face = (o1 + PORT.distance_m * s1) - (o0 + (pupil_z + PORT.distance_m) * s0)
    assert math.sqrt(np.mean(np.sum(at_face**2, axis=1))) < LENS_FAMILY_FRAME_M
    np.testing.assert_allclose(s1, s0, atol=LENS_FAMILY_FRAME_SLOPE)  # a move leaves the slopes


@pytest.mark.parametrize(("lens", "seed"), [("heliar", 0), ("telephoto", 4)])
def test_a_port_fitted_with_the_radial_model_refined_states_an_uncertainty_that_covers_its_error(lens, seed):
    """``calibrate port --refine-camera``'s joint fit of the port and the radial model stated the
    Jacobian's covariance alone: over five lenses and five seeds (benchmarks/measure_port_uncertainty.py
    --ray-model radial --refine) two ports lay beyond three stated sigma, these (distance 3.11 sigma,
    normal 3.21 sigma). Its covariance is now, as the port's on a fixed model, the larger of that and
    the one clustered by capture (2.03 and 2.32 sigma)."""
    from lfrefract.calibration import calibrate_port_and_camera

    camera, truth = truth_model(str(LENS_DIR / f"{lens}.toml"))
    view = virtual_camera_for(camera)
    rng = np.random.default_rng(seed)
    in_air = board_views(truth, camera, view, rng, n=10, depths=(0.15, 0.35), port=None, noise_px=0.05)
    water = board_views(truth, camera, view, rng, n=10, depths=(0.2, 0.5), port=PORT, noise_px=0.05)
    prior = calibrate_camera(camera, in_air, view=view, ray_model="radial").estimate
    joint = calibrate_port_and_camera(
        view, water, prior=prior, thickness_m=PORT.thickness_m, n_water=PORT.n_water, n_glass=PORT.n_glass
    )
    assert joint.accepted  # the refined port is the one stated
    port = joint.port
    normal_error = math.degrees(math.acos(min(1.0, float(port.port.normal @ PORT.normal))))
    assert normal_error <= 3.0 * port.normal_std_deg, (normal_error, port.normal_std_deg)
    assert abs(port.port.distance_m - PORT.distance_m) <= 3.0 * port.distance_std_m
