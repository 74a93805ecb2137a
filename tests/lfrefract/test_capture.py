"""lfrefract.formats.capture: the one reader of captures (raw image + meta.json, or a bare raw image given a
camera and a port), its checks, the counts of unrecorded raw values, and warp maps that skip them."""

from __future__ import annotations

import dataclasses
import json
import re

import numpy as np
import pytest

from lfrefract import FlatPort, ParameterError, PinholeCamera, Pose, camera_preset, virtual_camera_for
from lfrefract.errors import FileFormatError
from lfrefract.formats.capture import (
    CAPTURE_KIND,
    DEPTH_NAME,
    IDEAL_NAME,
    LENSES_NAME,
    RAW_NAME,
    SIDECAR_NAME,
    Capture,
    CaptureTruth,
    UnrecordedValues,
    camera_model_from_option,
    capture_parameters,
    mask_warp_map,
    port_from_file,
    read_capture,
    read_ground_truth,
    read_sidecar,
    write_capture,
)
from lfrefract.formats.exr import write_exr
from lfrefract.formats.jsonio import read_json, write_json
from lfrefract.formats.outputs import MANIFEST_NAME, output_manifest
from lfrefract.synthesis.warp_map import SynthesisOptions, build_warp_map
from tests.tolerances import FLOAT32_WEIGHT_SUM

TINY = camera_preset("tiny")
PORT = FlatPort.from_degrees(distance_m=0.02, thickness_m=0.004, tilt_x_deg=10.0)
SHAPE = (TINY.sensor.height_px, TINY.sensor.width_px)


def raw_image(seed: int = 0) -> np.ndarray:
    return (0.4 + 0.2 * np.random.default_rng(seed).random((*SHAPE, 3))).astype(np.float32)


def capture_folder(folder, raw=None, **meta):
    data = {"kind": "lfsim.render", "camera": TINY.to_dict(), "port": PORT.to_dict(), "scene": {"any": "thing"}}
    data.update(meta)
    write_exr(folder / "raw.exr", raw_image() if raw is None else raw, role="raw")
    write_json(folder / "meta.json", data)
    return folder / "raw.exr"


# =============================================================================== reading
def test_a_capture_folder_gives_its_checked_parameters(tmp_path):
    ideal = PinholeCamera(focal_px=100.0, cx_px=40.0, cy_px=30.0, width_px=81, height_px=61)
    pose = Pose.from_euler_xyz_deg((0.0, 10.0, 0.0), (0.1, 0.0, 0.0))
    path = capture_folder(tmp_path, ideal=ideal.to_dict(), pose=pose.to_dict())
    capture = read_capture(path)
    assert capture.camera == TINY
    assert capture.port == PORT
    assert capture.ideal == ideal
    assert capture.output == ideal
    assert capture.pose == pose
    assert capture.sidecar_path == tmp_path / "meta.json"
    assert capture.sidecar["scene"] == {"any": "thing"}  # other keys are kept, not checked
    assert capture.raw.shape == (*SHAPE, 3)
    assert capture.channels == 3
    assert not capture.raw.flags.writeable
    assert capture.recorded is None
    assert capture.unrecorded == UnrecordedValues()
    assert capture.masked_summary() is None
    # Without ideal and pose: the default output geometry, no pose.
    bare = read_capture(capture_folder(tmp_path / "b", ideal=None))
    assert bare.ideal is None
    assert bare.pose is None
    assert bare.output == virtual_camera_for(TINY)


def test_a_bare_raw_image_needs_a_camera_and_takes_a_given_port(tmp_path):
    path = tmp_path / "raw.exr"
    write_exr(path, raw_image(), role="raw")
    with pytest.raises(FileFormatError, match=re.escape(f"{str(path)!r} has no meta.json beside it")):
        read_capture(path)
    capture = read_capture(path, camera=TINY, port=PORT)
    assert capture.sidecar is None
    assert capture.sidecar_path is None
    assert capture.port == PORT
    assert capture.camera_source == "the camera given"
    # A camera is optional where the caller says so (calibrate mla).
    assert read_capture(path, camera_required=False).camera is None
    with pytest.raises(FileFormatError, match=re.escape(f"no such file: {str(tmp_path / 'nope.exr')!r}")):
        read_capture(tmp_path / "nope.exr")


def test_given_parameters_replace_the_sidecars(tmp_path):
    other = FlatPort.from_degrees(distance_m=0.03, thickness_m=0.0, tilt_y_deg=5.0)
    path = capture_folder(tmp_path, camera=camera_preset("tiny-2x").to_dict())
    with pytest.raises(FileFormatError, match=re.escape("is 480 x 360 px, but the camera")):
        read_capture(path)
    capture = read_capture(path, camera=TINY, port=other)
    assert capture.camera == TINY
    assert capture.port == other


def test_parameters_are_checked_before_the_raw_image_is_read(tmp_path):
    path = capture_folder(tmp_path, pose={"rotation": "none"})
    path.write_bytes(b"not an exr")
    with pytest.raises(FileFormatError, match=r"key 'pose': pose\.rotation must be a finite 3x3 matrix"):
        capture_parameters(path)
    capture_folder(tmp_path)
    path.write_bytes(b"not an exr")
    assert capture_parameters(path).camera == TINY  # and only read_capture reads the image
    with pytest.raises(FileFormatError, match="is not an OpenEXR file"):
        read_capture(path)


@pytest.mark.parametrize(
    ("meta", "message"),
    [
        ({"camera": "tiny"}, "key 'camera' must be a table (a JSON object), got 'tiny'"),
        ({"camera": None}, "key 'camera' must be a table (a JSON object), got None"),
        ({"port": 0.02}, "key 'port' must be a table (a JSON object), got 0.02"),
        ({"port": {"distance_m": -1.0}}, "key 'port': port.distance_m must be positive"),
        ({"ideal": [92, 69]}, "key 'ideal' must be a table (a JSON object), got [92, 69]"),
        ({"ideal": {"K": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "width_px": 1, "height_px": 10**6}}, "key 'ideal'"),
        ({"pose": "up"}, "key 'pose' must be a table (a JSON object), got 'up'"),
        ({"pose": {"rotation_xyz_deg": [0, 0]}}, "key 'pose': pose.rotation_xyz_deg must have 3 entries"),
    ],
)
def test_every_key_of_the_sidecar_is_checked_naming_file_and_key(tmp_path, meta, message):
    path = capture_folder(tmp_path, **meta)
    for read in (read_capture, capture_parameters, lambda p: read_sidecar(p.parent / "meta.json")):
        with pytest.raises(FileFormatError, match=re.escape(f"{str(tmp_path / 'meta.json')!r}: {message}")):
            read(path)


def test_null_port_ideal_and_pose_are_absent(tmp_path):
    sidecar = read_sidecar(capture_folder(tmp_path, port=None, ideal=None, pose=None).parent / "meta.json")
    assert (sidecar.port, sidecar.ideal, sidecar.pose) == (None, None, None)
    with pytest.raises(FileFormatError, match=re.escape("has no key 'camera'")):
        read_sidecar(write_json(tmp_path / "x" / "meta.json", {"port": PORT.to_dict()}))
    assert read_sidecar(tmp_path / "x" / "meta.json", camera_required=False).camera is None


def test_a_sidecar_that_is_a_directory_is_refused(tmp_path):
    write_exr(tmp_path / "raw.exr", raw_image(), role="raw")
    (tmp_path / "meta.json").mkdir()
    with pytest.raises(FileFormatError, match=re.escape("meta.json' (the sidecar beside")):
        read_capture(tmp_path / "raw.exr", camera=TINY)


def test_capture_fields_are_type_checked():
    with pytest.raises(ParameterError, match="port must be a FlatPort or None, got 'flat'"):
        Capture(raw_path="r.exr", raw=raw_image(), camera=TINY, port="flat")
    with pytest.raises(ParameterError, match=r"raw must be a float \(H, W\) or \(H, W, C\) image, got int64"):
        Capture(raw_path="r.exr", raw=np.zeros(SHAPE, dtype=np.int64), camera=TINY)
    with pytest.raises(ParameterError, match=r"nonfinite must be one of \['refuse', 'mask'\], got 'ignore'"):
        Capture(raw_path="r.exr", raw=raw_image(), camera=TINY, nonfinite="ignore")
    with pytest.raises(ParameterError, match="camera must be a LightFieldCamera, got 'tiny'"):
        read_capture("r.exr", camera="tiny")


# =============================================================================== unrecorded values
def test_unrecorded_values_are_counted_by_kind_and_pixel():
    raw = np.ones((4, 5, 3), dtype=np.float32)
    raw[0, 0] = [np.nan, np.nan, 1.0]  # one pixel, two NaN
    raw[1, 1, 2] = np.inf
    raw[2, 2, 0] = -np.inf
    raw[3, 3] = [-1.0, -1e-30, -0.0]  # -0.0 is not negative
    raw[3, 4, 1] = 0.0
    counts = UnrecordedValues.of(raw)
    assert counts == UnrecordedValues(nan=2, posinf=1, neginf=1, negative=2, pixels=4)
    assert counts.values == 6
    assert counts.describe() == "2 NaN, 1 +inf, 1 -inf and 2 negative pixel values (in 4 pixels)"
    assert UnrecordedValues.of(raw[..., 0]).describe() == "1 NaN, 1 -inf and 1 negative pixel values (in 3 pixels)"
    assert counts.to_dict() == {"nan": 2, "posinf": 1, "neginf": 1, "negative": 2, "pixels": 4, "values": 6}


def test_unrecorded_values_are_refused_or_masked(tmp_path):
    raw = raw_image()
    raw[10, 20, 1] = np.nan
    raw[30, 40] = -1.0
    path = capture_folder(tmp_path, raw=raw)
    message = f"{str(path)!r} has 1 NaN and 3 negative pixel values (in 2 pixels); pass --nonfinite mask"
    with pytest.raises(FileFormatError, match=re.escape(message)):
        read_capture(path)
    capture = read_capture(path, nonfinite="mask")
    expected = np.ones(SHAPE, dtype=bool)
    expected[10, 20] = expected[30, 40] = False
    np.testing.assert_array_equal(capture.recorded, expected)
    assert not capture.recorded.flags.writeable
    assert np.isnan(capture.raw[10, 20, 1])  # the image is kept as read
    assert capture.masked_summary()["values"] == 4
    assert capture.masked_summary()["pixels"] == 2
    with pytest.raises(ParameterError, match="nonfinite must be one of"):
        read_capture(path, nonfinite="zero")


# =============================================================================== warp maps without them
@pytest.fixture(scope="module")
def warp():
    return build_warp_map(TINY, PORT, options=SynthesisOptions(k=8, supersample=2))


def test_a_masked_warp_map_renormalises_each_row_over_its_recorded_rays(warp):
    rng = np.random.default_rng(5)
    recorded = rng.random(SHAPE) >= 0.03
    masked = mask_warp_map(warp, recorded)
    assert not np.isin(masked.indices, np.flatnonzero(~recorded)).any()
    assert recorded.ravel()[warp.indices].sum() == len(masked.indices)  # every recorded entry is kept
    n = len(warp.indptr) - 1

    def per_row(indptr, values):
        return np.bincount(np.repeat(np.arange(n), np.diff(indptr)), weights=values, minlength=n)

    sums = per_row(masked.indptr, masked.weights.astype(np.float64))[np.diff(masked.indptr) > 0]
    np.testing.assert_allclose(sums, 1.0, atol=FLOAT32_WEIGHT_SUM)
    # Rows that lost nothing are unchanged; their weights are the same to round-off.
    lost = per_row(warp.indptr, (~recorded.ravel()[warp.indices]).astype(float))
    for p in np.flatnonzero((lost == 0) & (np.diff(warp.indptr) > 0))[::97]:
        a, b = slice(warp.indptr[p], warp.indptr[p + 1]), slice(masked.indptr[p], masked.indptr[p + 1])
        np.testing.assert_array_equal(masked.indices[b], warp.indices[a])
        np.testing.assert_allclose(masked.weights[b], warp.weights[a], rtol=FLOAT32_WEIGHT_SUM)
    # A uniform raw image stays uniform (times the gain) wherever a row keeps a ray.
    image = masked.apply(np.where(recorded, 1.0, np.nan).astype(np.float32))
    filled = masked.filled
    np.testing.assert_allclose(image[filled], masked.gain.reshape(filled.shape)[filled], rtol=FLOAT32_WEIGHT_SUM)
    assert (image[~filled] == 0).all()
    assert masked.meta["unrecorded_raw_pixels"] == int((~recorded).sum())
    assert masked.key == warp.key


def test_a_warp_map_with_everything_masked_fills_nothing(warp):
    masked = mask_warp_map(warp, np.zeros(SHAPE, dtype=bool))
    assert len(masked.indices) == 0
    assert not masked.filled.any()
    assert not masked.exact.any()  # the camera recorded none of the necessary rays
    assert (masked.coverage == 0).all()
    assert mask_warp_map(warp, None) is warp
    with pytest.raises(ParameterError, match=r"recorded must be a bool array of shape \(360, 480\)"):
        mask_warp_map(warp, np.zeros((2, 2), dtype=bool))


# =============================================================================== option files
def test_camera_options_are_presets_or_camera_files(tmp_path):
    assert camera_model_from_option("tiny").camera == TINY
    wide = dataclasses.replace(TINY, name="wide", f_number=2.5)
    write_json(tmp_path / "cam.json", {"camera": wide.to_dict(), "other": 1})
    assert camera_model_from_option(tmp_path / "cam.json").camera == wide
    write_json(tmp_path / "no.json", {"port": PORT.to_dict()})
    with pytest.raises(FileFormatError, match=re.escape("no.json' has no key 'camera': it is not a camera file")):
        camera_model_from_option(tmp_path / "no.json")
    (tmp_path / "utf16.json").write_bytes(json.dumps({"schema_version": 1}).encode("utf-16"))
    with pytest.raises(FileFormatError, match=re.escape("utf16.json' is not UTF-8 text")):
        camera_model_from_option(tmp_path / "utf16.json")
    with pytest.raises(ParameterError, match=r"--camera must be a preset \(f01, illum, tiny, tiny-2x\) or a JSON"):
        camera_model_from_option("tiny3")


def test_port_files_need_a_port_table(tmp_path):
    write_json(tmp_path / "p.json", {"port": PORT.to_dict()})
    assert port_from_file(tmp_path / "p.json") == PORT
    write_json(tmp_path / "null.json", {"port": None})
    with pytest.raises(
        FileFormatError, match=re.escape("null.json': key 'port' must be a table (a JSON object), got None")
    ):
        port_from_file(tmp_path / "null.json")
    write_json(tmp_path / "bad.json", {"port": {"distance_m": "near"}})
    with pytest.raises(
        FileFormatError, match=re.escape("bad.json': key 'port': port.distance_m must be a real number")
    ):
        port_from_file(tmp_path / "bad.json")


# =============================================================================== writing
def truth_for(ideal: PinholeCamera) -> CaptureTruth:
    rng = np.random.default_rng(3)
    depth = np.full((ideal.height_px, ideal.width_px), 1.5, dtype=np.float32)
    depth[0, :4] = np.inf  # no surface there
    lenses = {"lens_index": np.arange(8, dtype=np.int64).reshape(4, 2), "lens_centre_m": rng.random((4, 2))}
    return CaptureTruth(ideal=rng.random((*depth.shape, 3)).astype(np.float32), depth_m=depth, lenses=lenses)


def test_a_written_capture_reads_back_as_it_was_given(tmp_path):
    ideal = PinholeCamera(focal_px=90.0, cx_px=20.0, cy_px=15.0, width_px=41, height_px=31)
    pose = Pose.from_euler_xyz_deg((5.0, 0.0, 0.0), (0.0, 0.1, 0.0))
    raw, truth = raw_image(1), truth_for(ideal)
    out = tmp_path / "cap"
    assert (
        write_capture(
            out,
            raw=raw,
            camera=TINY,
            port=PORT,
            ideal=ideal,
            pose=pose,
            ground_truth=truth,
            metadata={"scene": {"a": 1}},
        )
        == out
    )
    assert sorted(p.name for p in out.iterdir()) == sorted(
        [MANIFEST_NAME, RAW_NAME, IDEAL_NAME, DEPTH_NAME, LENSES_NAME, SIDECAR_NAME]
    )
    assert output_manifest(out)["kind"] == CAPTURE_KIND
    capture = read_capture(out)  # the folder, or its raw image
    assert capture.raw_path == out / RAW_NAME
    assert (capture.camera, capture.port, capture.ideal, capture.pose) == (TINY, PORT, ideal, pose)
    np.testing.assert_array_equal(capture.raw, raw)
    meta = read_json(out / SIDECAR_NAME)
    assert list(meta)[:7] == ["schema_version", "kind", "files", "camera", "pose", "port", "ideal"]
    assert meta["files"] == {"raw": RAW_NAME, "ideal": IDEAL_NAME, "depth": DEPTH_NAME, "lenses": LENSES_NAME}
    assert meta["scene"] == {"a": 1}
    back = read_ground_truth(out)
    np.testing.assert_array_equal(back.ideal, truth.ideal)
    np.testing.assert_array_equal(back.depth_m, truth.depth_m)  # +inf kept
    assert sorted(back.lenses) == sorted(truth.lenses)
    np.testing.assert_array_equal(back.lenses["lens_centre_m"], truth.lenses["lens_centre_m"])


def test_a_capture_without_ground_truth_or_port_writes_nulls_and_only_its_raw_image(tmp_path):
    out = write_capture(tmp_path / "cap", raw=raw_image()[..., 0], camera=TINY, kind="my.capture")
    assert sorted(p.name for p in out.iterdir()) == sorted([MANIFEST_NAME, RAW_NAME, SIDECAR_NAME])
    meta = read_json(out / SIDECAR_NAME)
    assert (meta["kind"], meta["files"], meta["port"], meta["pose"], meta["ideal"]) == (
        "my.capture",
        {"raw": RAW_NAME},
        None,
        None,
        None,
    )
    capture = read_capture(out / RAW_NAME)
    assert capture.port is None
    assert capture.output == virtual_camera_for(TINY)
    assert capture.channels == 1
    with pytest.raises(FileFormatError, match=re.escape(repr(str(out / IDEAL_NAME)))):
        read_ground_truth(out)


def test_writing_a_capture_replaces_only_an_earlier_capture_when_told(tmp_path):
    out = write_capture(tmp_path / "cap", raw=raw_image(0), camera=TINY)
    with pytest.raises(FileExistsError, match="--overwrite"):
        write_capture(out, raw=raw_image(1), camera=TINY)
    np.testing.assert_array_equal(read_capture(out).raw, raw_image(0))
    with pytest.raises(FileExistsError, match="kind"):
        write_capture(out, raw=raw_image(1), camera=TINY, kind="other.kind", overwrite=True)
    write_capture(out, raw=raw_image(1), camera=TINY, overwrite=True)
    np.testing.assert_array_equal(read_capture(out).raw, raw_image(1))


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"raw": np.zeros((3, 4), np.float32)}, "4 x 3 px, but the camera has a"),
        ({"raw": np.zeros((*SHAPE, 3), np.int32)}, "raw must be a float"),
        ({"raw": np.zeros((*SHAPE, 4), np.float32)}, "raw must be a float"),
        ({"camera": "tiny"}, "camera must be a LightFieldCamera"),
        ({"port": {"distance_m": 0.02}}, "port must be a FlatPort"),
        ({"metadata": {"camera": {}}}, "metadata may not set ['camera']"),
        ({"metadata": {"schema_version": 2}}, "metadata may not set ['schema_version']"),
        ({"metadata": [("scene", 1)]}, "metadata must be a mapping of str keys"),
        ({"ground_truth": "truth"}, "ground_truth needs ideal"),
        ({"kind": ""}, "kind must be a non-empty string"),
    ],
)
def test_bad_captures_are_refused_before_anything_is_written(tmp_path, change, message):
    args = {"raw": raw_image(), "camera": TINY, **change}
    if change.get("ground_truth") == "truth":
        args["ground_truth"] = truth_for(virtual_camera_for(TINY))
    with pytest.raises(ParameterError, match=re.escape(message)):
        write_capture(tmp_path / "cap", **args)
    assert list(tmp_path.iterdir()) == []


def test_ground_truth_must_match_its_ideal_geometry():
    ideal = PinholeCamera(focal_px=90.0, cx_px=20.0, cy_px=15.0, width_px=41, height_px=31)
    with pytest.raises(ParameterError, match="must be of one size"):
        CaptureTruth(ideal=np.zeros((31, 41, 3), np.float32), depth_m=np.zeros((31, 40), np.float32))
    other = dataclasses.replace(ideal, width_px=40, cx_px=19.5)
    with pytest.raises(ParameterError, match="ideal is 40 x 31 px"):
        write_capture("unused", raw=raw_image(), camera=TINY, ideal=other, ground_truth=truth_for(ideal))


def _capture_with_truth(tmp_path):
    ideal = PinholeCamera(focal_px=90.0, cx_px=20.0, cy_px=15.0, width_px=41, height_px=31)
    return write_capture(tmp_path / "cap", raw=raw_image(0), camera=TINY, ideal=ideal, ground_truth=truth_for(ideal))


def _npy(path):
    with path.open("wb") as fh:
        np.save(fh, np.zeros(3))


@pytest.mark.parametrize(
    "content",
    [
        pytest.param(_npy, id="a single .npy array"),
        pytest.param(lambda path: path.write_bytes(b"PK\x03\x04 truncated"), id="a truncated zip"),
        pytest.param(lambda path: path.write_bytes(b""), id="empty"),
    ],
)
def test_a_broken_lens_table_is_a_file_format_error_naming_it(tmp_path, content):
    """A lenses.npz that is not an archive of arrays was a TypeError or BadZipFile (a traceback)."""
    out = _capture_with_truth(tmp_path)
    (out / LENSES_NAME).unlink()
    content(out / LENSES_NAME)
    with pytest.raises(FileFormatError, match=re.escape(repr(str(out / LENSES_NAME)))):
        read_ground_truth(out)


def test_ground_truth_images_must_have_the_sidecars_size(tmp_path):
    out = _capture_with_truth(tmp_path)
    small = np.ones((4, 5, 3), np.float32)
    (out / IDEAL_NAME).unlink()
    write_exr(out / IDEAL_NAME, small, role="ideal")
    with pytest.raises(FileFormatError, match=r"5 x 4 px, but the sidecar's ideal image is"):
        read_ground_truth(out)
