"""The built-in ``depth-aware`` method of the experiments' registry, on a rig of tiny cameras, without rendering.

The rig is made by hand (tests/simulator/test_experiment_methods.py has no rig that is not rendered):
two tiny cameras behind one port, each with its warp map, and captures whose raw images are the
textured plane of tests/lfrefract/test_methods_depth_aware.py.
"""

from __future__ import annotations

import numpy as np
import pytest

from lfrefract import FlatPort, camera_preset
from lfrefract.methods import build_projector
from lfrefract.optics.pose import Pose
from lfrefract.synthesis.warp_map import build_warp_map
from simulator.experiments.methods import (
    BUILTIN_METHODS,
    CentralImages,
    MethodCamera,
    MethodRig,
    method_factories,
    method_names,
)
from tests.lfrefract.test_methods_depth_aware import plane_raw


class PlaneShot:
    """A capture of the textured plane: the same raw image for every camera (no ground truth)."""

    def __init__(self, raw: np.ndarray) -> None:
        self._raw = raw

    def raw(self, camera: str) -> np.ndarray:
        return self._raw

    def ideal(self, camera: str) -> np.ndarray:
        raise AssertionError("a method may not look at the ground truth")

    def depth(self, camera: str) -> np.ndarray:
        raise AssertionError("a method may not look at the ground truth")


def _no_calibration(camera: str, depth_m: float):
    raise AssertionError("depth-aware needs no calibration views")


@pytest.fixture(scope="module")
def rig() -> MethodRig:
    camera = camera_preset("tiny")
    port = FlatPort.from_degrees(tilt_x_deg=15.0, tilt_y_deg=5.0, distance_m=0.012, thickness_m=0.004)
    warp = build_warp_map(camera, port)
    cameras = tuple(
        MethodCamera(name=name, camera=camera, port=port, pose=Pose(position_m=(x, 0.0, 0.0)), warp=warp)
        for name, x in (("left", 0.0), ("right", 0.06))
    )
    return MethodRig(cameras=cameras, calibration_depths_m=(0.3, 0.6), calibration=_no_calibration)


def test_depth_aware_is_built_in_between_the_proposed_methods_and_ideal():
    assert tuple(BUILTIN_METHODS) == (
        "approx far",
        "approx near",
        "proposed",
        "proposed+distortion",
        "depth-aware",
        "ideal",
    )
    names = method_names()
    assert names[: len(BUILTIN_METHODS)] == tuple(BUILTIN_METHODS)
    assert method_factories()["depth-aware"] is BUILTIN_METHODS["depth-aware"]


def test_depth_aware_factory_makes_central_images(rig):
    images = method_factories()["depth-aware"](rig)
    assert isinstance(images, CentralImages)
    assert set(images.outputs) == {"left", "right"}
    first = rig.cameras[0]
    assert images.outputs["left"] == first.warp.output
    raw = plane_raw(first.camera, first.port)
    image = images.project("left", PlaneShot(raw))
    output = first.warp.output
    assert image.dtype == np.float32
    assert image.shape == (output.height_px, output.width_px, 3)
    assert np.isfinite(image).any()
    assert np.isnan(image).any()  # the tilted port leaves part of the image without rays
    # It is the lfrefract method on the rig's warp map (the rig's paper-k map, not one of its own).
    projector = build_projector("depth-aware", first.camera, first.port, warp=first.warp)
    assert np.array_equal(image, projector.apply(raw), equal_nan=True)
    assert np.array_equal(images.project("right", PlaneShot(raw)), image, equal_nan=True)
