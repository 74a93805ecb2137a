"""Which terms the calibrated ray model lacks: fits to a camera's true rays (an oracle, not a calibration).

The ray correction's five parameters (``lfrefract.optics.ray_correction``: pupil scale, slope
scale, k1, k2, pupil drift) are fitted by least squares directly to the true rays of the pipeline
experiment's left camera (``simulator.experiments.pipeline``: its rig at ``--scale``, the default
real lens), with the frame's shift along z free (the model's gauge), and
again with candidate terms added one at a time and all together:

* ``defocus``: slopes gain ``c a / R`` (``a`` the thin-lens aperture point, ``R`` 4 mm): the real
  lens's rays of one microlens are not parallel (its focal plane is not the MLA's);
* ``spherical``: slopes gain ``c a |a|^2 / R^3`` (spherical aberration of the main lens);
* ``pupil_field``: the pupil scale becomes ``m (1 + q |t|^2)`` (the entrance pupil's size changes
  with the field: pupil distortion);
* ``k3``: a third radial term ``k3 t |t|^6`` of the slopes.

For each fit it prints the rays' RMS distance from the true ones where they cross the planes z = 25
mm (about a port's air-side face) and z = 250 mm (about a calibration board), and at 250 mm the
*per-field bias*: the error averaged over each microlens's pixels (with the MLA in the main lens's
focal plane a microlens's rays share one direction, so this is the error left once the aperture is
averaged over, what a chessboard corner seen by many pixels keeps), RMS over the microlenses in three
bands of the field (the larger of |x| and |y| from the view's centre, as a fraction of its width and
height: the inner ring of calibration boards lies within about 0.35, the outer ring reaches 0.5).
Pixels: every one (``tiny``), or 16 x 16 tiles every 160 px (``illum``: 0.41 M rays).

    python benchmarks/measure_ray_model_terms.py [--scale illum|tiny]
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import sys
from collections.abc import Callable

import numpy as np
from scipy.optimize import least_squares

from lfrefract.optics.pinhole import virtual_camera_for
from lfrefract.optics.ray_correction import PARAMETERS, corrected_slopes
from lfrefract.optics.real_lens import RealLensCamera
from simulator.experiments import ExperimentOptions
from simulator.experiments.pipeline import DEFAULT_LENS, experiment_rig, setup_for_pipeline

#: The model's five parameters (``PARAMETERS``), then the z gauge, then one per term.
FIVE = len(PARAMETERS)
#: Planes (camera-frame z, metres) where the fit compares the rays.
FIT_PLANES_M = (0.025, 0.3)
#: The aperture radius the aperture terms are scaled by, metres.
APERTURE_SCALE_M = 0.004
#: Bands of the field (fraction of the view from its centre) the per-field bias is reported in.
FIELD_BANDS = ((0.0, 0.25), (0.25, 0.35), (0.35, 0.6))
#: Candidate terms: (slopes t' (N, 2), thin slopes t, aperture points a / R, coefficient) -> t'.
SLOPE_TERMS: dict[str, Callable[[np.ndarray, np.ndarray, np.ndarray, float], np.ndarray]] = {
    "defocus": lambda s, t, a, c: s + 0.01 * c * a,
    "spherical": lambda s, t, a, c: s + 0.01 * c * a * np.sum(a * a, axis=1, keepdims=True),
    "k3": lambda s, t, a, c: s + c * t * np.sum(t * t, axis=1, keepdims=True) ** 3,
}
TERMS = (*SLOPE_TERMS, "pupil_field")


@dataclasses.dataclass(frozen=True)
class _Rays:
    """Thin-lens aperture points and slopes of the sampled pixels, their true rays, and each one's
    microlens (as an index into its microlenses) and field position."""

    aperture_m: np.ndarray
    slopes: np.ndarray
    true_origins_m: np.ndarray
    true_directions: np.ndarray
    lens: np.ndarray
    field: np.ndarray


def _sample(scale: str) -> _Rays:
    setup = setup_for_pipeline(scale)
    rig = experiment_rig(setup.rig, dataclasses.replace(ExperimentOptions(scale=scale), lens=DEFAULT_LENS))
    scene = rig.cameras[0].scene
    camera = scene.camera
    vv, uu = np.mgrid[0 : camera.sensor.height_px, 0 : camera.sensor.width_px]
    keep = np.ones_like(uu, dtype=bool) if scale == "tiny" else ((uu // 16) % 10 == 0) & ((vv // 16) % 10 == 0)
    uv = np.stack([uu[keep], vv[keep]], axis=1).astype(np.float64)
    true = RealLensCamera(camera=camera, lens=scene.lens).chief_rays(uv)
    thin = camera.captured_rays(uv)
    ok = true.in_aperture & thin.in_aperture & np.all(np.isfinite(true.directions_cam), axis=1)
    view = virtual_camera_for(camera)
    d = true.directions_cam[ok]
    seen = view.project(true.origins_cam[ok] + d * (0.25 / d[:, 2:3]))
    field = np.maximum(
        np.abs(seen[:, 0] - view.cx_px) / view.width_px, np.abs(seen[:, 1] - view.cy_px) / view.height_px
    )
    lens = np.unique(np.asarray(thin.lens_indices)[ok].reshape(int(ok.sum()), -1), axis=0, return_inverse=True)[1]
    return _Rays(
        aperture_m=thin.origins_cam[ok, :2],
        slopes=thin.directions_cam[ok, :2] / thin.directions_cam[ok, 2:3],
        true_origins_m=true.origins_cam[ok],
        true_directions=d,
        lens=lens.ravel(),
        field=field,
    )


def _crossing(origins: np.ndarray, directions: np.ndarray, z_m: float) -> np.ndarray:
    return origins[:, :2] + (z_m - origins[:, 2:3]) * directions[:, :2] / directions[:, 2:3]


def _model(p: np.ndarray, terms: tuple[str, ...], rays: _Rays) -> tuple[np.ndarray, np.ndarray]:
    """The rays of parameters ``p``: the five of the correction, the z gauge, then one per term."""
    coefficients = dict(zip(terms, p[FIVE + 1 :], strict=True))
    t, a = rays.slopes, rays.aperture_m / APERTURE_SCALE_M
    slopes = corrected_slopes(p, t)
    for name, term in SLOPE_TERMS.items():
        if name in coefficients:
            slopes = term(slopes, t, a, coefficients[name])
    pupil = p[0] * (1.0 + coefficients.get("pupil_field", 0.0) * np.sum(t * t, axis=1, keepdims=True))
    shift = p[4] * np.sum(slopes * slopes, axis=1, keepdims=True) * slopes
    origins = np.column_stack([pupil * rays.aperture_m - shift, np.full(len(t), p[5])])
    return origins, np.column_stack([slopes, np.ones(len(t))])


def _fit(terms: tuple[str, ...], rays: _Rays) -> dict:
    def residuals(p: np.ndarray) -> np.ndarray:
        origins, directions = _model(p, terms, rays)
        return np.concatenate(
            [
                (_crossing(origins, directions, z) - _crossing(rays.true_origins_m, rays.true_directions, z)).ravel()
                for z in FIT_PLANES_M
            ]
        )

    start = np.r_[1.0, 1.0, 0.0, 0.0, 0.0, 0.0, np.zeros(len(terms))]
    scales = np.r_[0.01, 0.01, 0.1, 0.1, 1e-3, 1e-3, np.full(len(terms), 0.1)]
    p = least_squares(residuals, start, x_scale=scales).x
    origins, directions = _model(p, terms, rays)

    def error_mm(z_m: float) -> np.ndarray:
        true = _crossing(rays.true_origins_m, rays.true_directions, z_m)
        return 1e3 * (_crossing(origins, directions, z_m) - true)

    near, far = error_mm(0.025), error_mm(0.25)
    count = np.bincount(rays.lens)
    bias = np.stack([np.bincount(rays.lens, far[:, i]) / count for i in range(2)], axis=1)
    lens_field = np.bincount(rays.lens, rays.field) / count
    bands = []
    for low, high in FIELD_BANDS:
        inside = (count >= 3) & (lens_field >= low) & (lens_field < high)
        bands.append(float(np.sqrt(np.mean(np.sum(bias[inside] ** 2, axis=1)))))
    return {
        "near_mm": float(np.sqrt(np.mean(np.sum(near**2, axis=1)))),
        "far_mm": float(np.sqrt(np.mean(np.sum(far**2, axis=1)))),
        "bands_mm": bands,
        "p": p,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scale", choices=["tiny", "illum"], default="illum")
    args = parser.parse_args()
    rays = _sample(args.scale)
    bands = " | ".join(f"bias {low:g}-{high:g}, mm" for low, high in FIELD_BANDS)
    lenses = int(rays.lens.max()) + 1
    print(f"{args.scale}, left camera, {DEFAULT_LENS}: {len(rays.lens):,} rays over {lenses:,} microlenses")
    print(f"| terms | at 25 mm, mm | at 250 mm, mm | {bands} | pupil scale, slope scale, k1, k2, drift mm | terms' |")
    print("|---|---:|---:|" + "---:|" * len(FIELD_BANDS) + "---|---|")
    for terms in itertools.chain([()], ((t,) for t in TERMS), [TERMS]):
        r = _fit(terms, rays)
        p = r["p"]
        five = f"{p[0]:.4f}, {p[1]:.4f}, {p[2]:.3f}, {p[3]:.3f}, {1e3 * p[4]:.2f}"
        extra = ", ".join(f"{name} {value:.3f}" for name, value in zip(terms, p[6:], strict=True))
        print(
            f"| {' + '.join(terms) or 'the five'} | {r['near_mm']:.4f} | {r['far_mm']:.4f} | "
            + " | ".join(f"{b:.4f}" for b in r["bands_mm"])
            + f" | {five} | {extra} |"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
