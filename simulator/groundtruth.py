"""Ground truth traced by the project, not read from Mitsuba's AOVs (which stop at the glass).

* The ideal image: the same scene without the port, seen by the virtual pinhole camera
  (centre of projection at the main-lens centre, OpenCV intrinsics K), lit identically, at its
  own samples per pixel (``render.ideal_spp``, default
  :data:`simulator.config.DEFAULT_IDEAL_SPP`), which is independent of the raw image's. In turbid
  water the pinhole stands in the water: its rays are attenuated (and the view veiled) over the
  whole distance from the main-lens centre, where the raw image's rays cross water only beyond
  the port's water face.
* Its depth map: camera-frame z of the first surface along each pixel-centre ray, metres,
  +inf where the ray hits nothing. It is geometric: turbid water does not change it.
* The microlenses: lattice indices, image-plane centres (metres) and micro-image centres
  (raw pixels) of every lens whose micro-image centre lies on the sensor.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import ModuleType

import numpy as np

from lfrefract import LightFieldCamera, PinholeCamera, Pose
from lfrefract.optics.lens import LensPrescription
from lfrefract.optics.real_lens import RealLensCamera
from simulator.config import SceneConfig
from simulator.render import IDEAL_STREAM, render_bands
from simulator.scene import water_medium
from simulator.sensor import pinhole_sensor_dict

__all__ = ["GroundTruth", "compute", "depth_map", "lens_table"]


@dataclass(frozen=True)
class GroundTruth:
    """Ideal image (H, W, 3) float32, depth (H, W) float32 metres, lens table of arrays."""

    ideal: np.ndarray
    depth_m: np.ndarray
    lenses: dict[str, np.ndarray]


def lens_table(camera: LightFieldCamera, lens: LensPrescription | None = None) -> dict[str, np.ndarray]:
    """Microlens ground truth for every lens whose micro-image centre is on the sensor.

    Returns
    -------
    dict
        ``lens_index`` (M, 2) int64 lattice indices (i, j); ``lens_centre_m`` (M, 2) image-plane
        centres on the MLA, metres; ``micro_image_centre_px`` (M, 2) raw-pixel (u, v) centres of
        the micro-images (the main lens's exit pupil centre imaged through each lens centre: the
        thin lens's centre, or with a real ``lens`` the paraxial exit pupil,
        :meth:`lfrefract.optics.real_lens.RealLensCamera.micro_image_centres_px`).
    """
    idx = camera.lens_indices_on_sensor()
    optics = camera if lens is None else RealLensCamera(camera=camera, lens=lens)
    return {
        "lens_index": idx,
        "lens_centre_m": camera.mla.centres_m(idx),
        "micro_image_centre_px": optics.micro_image_centres_px(idx),
    }


def depth_map(mi: ModuleType, scene, pinhole: PinholeCamera, pose: Pose) -> np.ndarray:
    """Camera-frame z (metres) of the first surface along every pixel-centre ray; +inf on a miss.

    Parameters
    ----------
    mi : module
        Mitsuba with a variant set.
    scene : mitsuba.Scene
        The scene without the port.
    pinhole : PinholeCamera
    pose : Pose
        Camera-to-world pose.

    Returns
    -------
    ndarray, float32, shape (pinhole.height_px, pinhole.width_px)
    """
    d_cam = pinhole.pixel_directions()
    d_world = d_cam @ np.asarray(pose.rotation).T
    origin = np.broadcast_to(np.asarray(pose.position_m), d_world.shape)
    ray = mi.Ray3f(mi.Point3f(origin.T.astype(np.float32)), mi.Vector3f(d_world.T.astype(np.float32)))
    si = scene.ray_intersect(ray)
    t = np.asarray(si.t, dtype=np.float64)
    valid = np.asarray(si.is_valid(), dtype=bool)
    z = np.where(valid, t * d_cam[:, 2], np.inf)
    return z.reshape(pinhole.height_px, pinhole.width_px).astype(np.float32)


def compute(
    mi: ModuleType,
    scene,
    config: SceneConfig,
    pinhole: PinholeCamera,
    *,
    seed: int,
    spp: int | None = None,
    progress: bool = True,
) -> GroundTruth:
    """Render the ideal image and trace the depth map and lens table for ``config``.

    Parameters
    ----------
    mi : module
        Mitsuba with a variant set.
    scene : mitsuba.Scene
        ``config``'s scene built without the port (:func:`simulator.scene.build_scene` with
        ``port_geometry=False``).
    config : SceneConfig
    pinhole : PinholeCamera
        Geometry of the ideal image.
    seed : int
        Job seed of the ideal render (its stream is :data:`simulator.render.IDEAL_STREAM`).
    spp : int, optional
        Samples per pixel of the ideal render; default ``config.render.ideal_spp`` (the raw
        image's ``config.render.spp`` is not used).
    progress : bool
        Show a progress bar.
    """
    if spp is None:
        spp = config.render.ideal_spp
    medium = water_medium(config.water)
    ideal = render_bands(
        mi,
        scene,
        lambda crop: pinhole_sensor_dict(mi, pinhole, config.pose, spp=spp, crop=crop, medium=medium),
        pinhole.width_px,
        pinhole.height_px,
        spp=spp,
        seed=seed,
        progress=progress,
        label="ideal",
        stream=IDEAL_STREAM,
    )
    return GroundTruth(
        ideal=ideal, depth_m=depth_map(mi, scene, pinhole, config.pose), lenses=lens_table(config.camera, config.lens)
    )
