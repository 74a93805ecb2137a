"""The small geometric helpers the synthesis kernels share with the numpy code (issue 13)."""

from __future__ import annotations

import dataclasses

import numba
import numpy as np
import pytest

from lfrefract import camera_preset
from lfrefract.synthesis._kernels import (
    angle_from_chord,
    angle_from_chord_jit,
    sensor_to_plane_scale,
    sensor_to_plane_scale_jit,
)

TINY = camera_preset("tiny")


def test_angle_from_chord_is_the_angle_and_the_same_compiled():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(500, 3))
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b = rng.normal(size=(500, 3))
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    chord = np.linalg.norm(a - b, axis=1)
    angle = np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.sum(a * b, axis=1))
    np.testing.assert_allclose(angle_from_chord(chord), angle, rtol=1e-12, atol=1e-12)
    assert angle_from_chord(2.0 + 1e-12) == np.pi  # rounding past the antipode: clamped, not NaN
    # The kernels' twin is the expression they inlined before (bit for bit, so the warp maps did not
    # change), and numpy's within rounding (numpy's and the C library's arcsin may differ in the last bit).
    inlined = numba.njit(lambda c: 2.0 * np.arcsin(min(1.0, 0.5 * c)))
    for c in (*chord[:50], 0.0, 1e-9, 2.0, 2.5):
        assert angle_from_chord_jit(c) == inlined(c)
        assert angle_from_chord_jit(c) == pytest.approx(angle_from_chord(c), rel=1e-15, abs=0.0)


@pytest.mark.parametrize("f_prime_over_f", [0.95, 1.0, 1.05])
def test_sensor_to_plane_scale_is_the_traced_chief_ray_spread(f_prime_over_f):
    # Two neighbouring pixels under one microlens: their chief rays (through the microlens centre and
    # the thin main lens) meet the plane z apart by |beta| x pixel pitch.
    camera = dataclasses.replace(TINY, lens_to_mla_m=f_prime_over_f * TINY.focal_length_m)
    centre = camera.micro_image_centres_px(np.array([[0, 0]]))[0]
    uv = np.stack([centre, centre + np.array([1.0, 0.0])])
    rays = camera.captured_rays(uv)
    assert rays.lens_indices[0].tolist() == rays.lens_indices[1].tolist()
    f, f_prime, f_mla = camera.focal_length_m, camera.lens_to_mla_m, camera.mla.focal_length_m
    for z_m in (0.005, 0.012, 0.3):
        o, d = rays.origins_cam, rays.directions_cam
        hit = o + d * ((z_m - o[:, 2]) / d[:, 2])[:, None]
        spread = np.linalg.norm(hit[1] - hit[0]) / camera.sensor.pixel_pitch_m
        beta = sensor_to_plane_scale(z_m, f, f_prime, f_mla)
        assert spread == pytest.approx(abs(beta), rel=1e-9)
        assert sensor_to_plane_scale_jit(z_m, f, f_prime, f_mla) == beta


def test_sensor_to_plane_scale_vanishes_on_the_plane_conjugate_to_the_mla():
    f, f_mla = TINY.focal_length_m, TINY.mla.focal_length_m
    f_prime = 1.05 * f
    z_conjugate = 1.0 / (1.0 / f - 1.0 / f_prime)  # thin lens: 1 / z + 1 / f' = 1 / f
    assert abs(sensor_to_plane_scale(z_conjugate, f, f_prime, f_mla)) < 1e-9 * f_prime / f_mla
    assert sensor_to_plane_scale(0.5 * z_conjugate, f, f_prime, f_mla) > 0.0
    # With the MLA in the focal plane no plane is conjugate: the scale is f' / f_mla at every depth.
    z = np.array([0.0, 0.01, 1.0, 100.0])
    np.testing.assert_allclose(sensor_to_plane_scale(z, f, f, f_mla), f / f_mla, rtol=1e-10)
