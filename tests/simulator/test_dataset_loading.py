"""A dataset as training code uses it: written in 16-bit PNG with the user's umask, loaded lazily,
picklable, served to worker processes started by spawn, with the set and swept keys as columns."""

from __future__ import annotations

import multiprocessing
import os
import pickle
import stat

import numpy as np
import pytest

from lfrefract.formats.jsonio import read_json
from simulator.dataset import ArrayDataset, Dataset, expand, parse_spec, run_dataset

SPEC = {
    "sweep": {
        "name": "learning",
        "seed": 3,
        "scene": "default",
        "spp": 1,
        "ideal_spp": 2,
        "image_format": "png16",
        "outputs": ["refraction_free"],
        "synthesis": {"k": 4},
    },
    "grid": {"port.tilt_x_deg": [0.0, 25.0]},
    "set": {"camera.preset": "tiny", "port.thickness_m": 0.004},
}
UMASK = 0o002


@pytest.fixture(scope="module")
def png_run(tmp_path_factory):
    """The two-sample sweep above, rendered in one local worker under umask 002."""
    out = tmp_path_factory.mktemp("learning") / "data"
    old = os.umask(UMASK)
    try:
        report = run_dataset(parse_spec(SPEC), out, workers=1, progress=False)
    finally:
        os.umask(old)
    assert report.ok
    return out


def test_files_and_folders_follow_the_umask(png_run):
    paths = [png_run, *png_run.rglob("*")]
    assert len(paths) > 20
    for path in paths:
        mode = stat.S_IMODE(path.stat().st_mode)
        assert mode == (0o777 if path.is_dir() else 0o666) & ~UMASK, (path, oct(mode))


def test_png_samples_load_with_set_and_swept_keys(png_run):
    data = Dataset(png_run)
    assert data.image_format == "png16"
    assert dict(data.set_values) == {"camera.preset": "tiny", "port.thickness_m": 0.004}
    table = data.params_table()
    assert table["port.tilt_x_deg"] == [0.0, 25.0]
    assert table["camera.preset"] == ["tiny", "tiny"]
    assert table["port.thickness_m"] == [0.004, 0.004]
    assert dict(data.rejections) == {"draws_refused": 0, "samples_redrawn": 0, "by_reason": {}}
    sample = data[1]
    assert sample.image_names == ("raw", "ideal", "depth_m", "refraction_free", "coverage", "filled")
    assert all(f.endswith(".png") for f in sample.files if f.split(".")[0] in ("raw", "ideal", "depth"))
    assert read_json(sample.path / "meta.json")["files"]["raw"] == "raw.png"
    raw, depth, image, filled = sample.raw, sample.depth_m, sample.refraction_free, sample.filled
    assert raw.dtype == depth.dtype == image.dtype == np.float32
    assert raw.shape == (360, 480, 3)
    assert np.all(depth[np.isfinite(depth)] > 0.3)  # the nearest object of the default scene is at 0.34 m
    assert np.array_equal(filled == 0, np.all(np.isnan(image), axis=2))
    assert sample.normal_cam is None  # not asked for


def test_array_dataset_pickles_and_serves_spawned_workers(png_run):
    names = ("raw", "ideal", "depth_m", "filled")
    served = Dataset(png_run).select(*names)
    assert isinstance(served, ArrayDataset)
    assert len(served) == 2
    item = served[0]
    assert set(item) == {"id", "index", *names}
    copy = pickle.loads(pickle.dumps(served))
    assert copy[1]["id"] == "s000001"
    # As a PyTorch DataLoader with workers does it: the dataset pickled into processes started by spawn.
    with multiprocessing.get_context("spawn").Pool(2) as pool:
        items = pool.map(served.__getitem__, range(len(served)))
    for index, got in enumerate(items):
        want = served[index]
        assert got["id"] == want["id"]
        for name in names:
            assert np.array_equal(got[name], want[name], equal_nan=True)
    with pytest.raises(KeyError, match="normal_cam"):
        Dataset(png_run).select("normal_cam")[0]


#: The sweep above with every ground-truth label, as .npz.
LABEL_SPEC = {
    "sweep": {k: v for k, v in SPEC["sweep"].items() if k != "synthesis"}
    | {"image_format": "npz", "outputs": ["labels", "raw_truth"]},
    "grid": SPEC["grid"],
    "set": SPEC["set"],
}


@pytest.fixture(scope="module")
def label_run(tmp_path_factory):
    """Two samples of :data:`LABEL_SPEC`."""
    out = tmp_path_factory.mktemp("labels") / "data"
    assert run_dataset(parse_spec(LABEL_SPEC), out, workers=1, progress=False).ok
    return out


def test_labels_are_the_ground_truth_of_the_sample_scene(label_run):
    """The files hold what simulator.groundtruth traces for the sample's own scene (its tests check
    those functions against analytic geometry)."""
    from lfrefract import PinholeCamera
    from simulator import backend, groundtruth
    from simulator.scene import build_scene

    sample = Dataset(label_run)[1]
    assert sample.image_names == ("raw", "ideal", "depth_m", "normal_cam", "instance_id", "raw_depth_m", "lens_index")
    config = expand(parse_spec(LABEL_SPEC))[1].config
    mi = backend.load_mitsuba()
    scene = build_scene(mi, config, port_geometry=False)
    labels = groundtruth.surface_labels(mi, scene, config, PinholeCamera.from_dict(sample.meta["ideal"]))
    assert np.array_equal(sample.normal_cam, labels.normal_cam, equal_nan=True)
    assert np.array_equal(sample.instance_id, labels.instance_id)
    assert np.array_equal(sample.depth_m, labels.depth_m)  # the render's depth is the labels' depth
    assert sample.instance_id.dtype == np.uint16
    assert set(np.unique(sample.instance_id)) == {1, 2, 3, 4}  # the backdrop fills the rest of the view
    assert sample.info["instances"] == groundtruth.instance_table(config)
    truth = groundtruth.raw_pixel_truth(mi, scene, config)
    assert np.array_equal(sample.raw_depth_m, truth.depth_m, equal_nan=True)
    assert np.array_equal(sample.lens_index, truth.lens_row)
    assert sample.info["images"]["lens_index"]["no_value"] == -1
    assert sample.lens_index.max() < len(sample.lenses["lens_index"])
