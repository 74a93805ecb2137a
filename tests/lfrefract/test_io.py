"""File I/O: float EXR images, JSON sidecars with a schema version, atomic output directories."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from lfrefract import ParameterError
from lfrefract.errors import FileFormatError
from lfrefract.formats.exr import read_exr, write_exr
from lfrefract.formats.jsonio import SCHEMA_VERSION, read_json, write_json

SPECIAL = np.array([0.0, -0.0, 1.5, np.inf, -np.inf, np.nan, 1e-45, -3.4e38, 65504.0, 1e-8], dtype=np.float32)
# Non-canonical NaN payloads (quiet, negative, signalling) must survive too.
PAYLOADS = np.array([0x7FC00001, 0xFFC12345, 0x7F800001], dtype=np.uint32).view(np.float32)


def bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float32).view(np.uint32)


def special_image(shape) -> np.ndarray:
    rng = np.random.default_rng(3)
    img = rng.normal(scale=100.0, size=shape).astype(np.float32)
    flat = img.reshape(-1)
    values = np.concatenate([SPECIAL, PAYLOADS])
    flat[: len(values)] = values
    return img


def only_entry(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.iterdir())


# =============================================================================== EXR
@pytest.mark.parametrize("shape", [(7, 11), (5, 9, 3), (1, 1), (1, 13, 3)])
def test_exr_round_trip_is_bit_exact(tmp_path, shape):
    img = special_image(shape) if np.prod(shape) >= 13 else np.full(shape, np.inf, dtype=np.float32)
    path = write_exr(tmp_path / "sub" / "img.exr", img, role="depth")
    assert path == tmp_path / "sub" / "img.exr"
    back = read_exr(path, role="depth")
    assert back.dtype == np.float32
    assert back.shape == shape
    np.testing.assert_array_equal(bits(back), bits(img))
    # Reading without a role check gives the same image; nothing else is left in the directory.
    np.testing.assert_array_equal(bits(read_exr(path)), bits(img))
    assert only_entry(tmp_path / "sub") == ["img.exr"]


def test_exr_stores_float32_of_other_real_types(tmp_path):
    f64 = np.array([[1.0 / 3.0, 1e30, -2.5]])
    write_exr(tmp_path / "a.exr", f64, role="raw")
    np.testing.assert_array_equal(bits(read_exr(tmp_path / "a.exr")), bits(f64.astype(np.float32)))
    ints = np.arange(12, dtype=np.int32).reshape(3, 4)
    write_exr(tmp_path / "b.exr", ints, role="raw")
    np.testing.assert_array_equal(read_exr(tmp_path / "b.exr"), ints.astype(np.float32))


def test_exr_overwrites_atomically(tmp_path):
    path = tmp_path / "img.exr"
    write_exr(path, np.zeros((2, 2)), role="raw")
    write_exr(path, np.ones((3, 3)), role="ideal")
    np.testing.assert_array_equal(read_exr(path, role="ideal"), np.ones((3, 3), dtype=np.float32))
    assert only_entry(tmp_path) == ["img.exr"]


def test_exr_role_mismatch(tmp_path):
    path = write_exr(tmp_path / "d.exr", np.zeros((2, 3)), role="depth")
    with pytest.raises(FileFormatError, match=re.escape(f"{str(path)!r} holds a 'depth' image, expected 'ideal'")):
        read_exr(path, role="ideal")


def test_exr_missing_file(tmp_path):
    path = tmp_path / "nope.exr"
    with pytest.raises(FileFormatError, match=re.escape(f"no such file: {str(path)!r}")):
        read_exr(path)
    # A directory is not a file either, and is named as what it is.
    with pytest.raises(FileFormatError, match="is a directory, not a regular file"):
        read_exr(tmp_path)


def test_exr_not_an_exr_file(tmp_path):
    path = tmp_path / "fake.exr"
    path.write_bytes(b"P6\n2 2\n255\n" + bytes(12))
    with pytest.raises(FileFormatError, match=re.escape(f"{str(path)!r} is not an OpenEXR file")):
        read_exr(path)
    empty = tmp_path / "empty.exr"
    empty.write_bytes(b"")
    with pytest.raises(FileFormatError, match=re.escape(f"{str(empty)!r} is not an OpenEXR file")):
        read_exr(empty)


@pytest.mark.parametrize("keep", [40, 0.5])
def test_exr_truncated_file(tmp_path, keep):
    good = write_exr(tmp_path / "good.exr", special_image((16, 16)), role="raw").read_bytes()
    path = tmp_path / "cut.exr"
    path.write_bytes(good[: keep if isinstance(keep, int) else int(len(good) * keep)])
    with pytest.raises(FileFormatError, match=re.escape(repr(str(path)))):
        read_exr(path)


@pytest.mark.parametrize(
    ("image", "pattern"),
    [
        (np.zeros((4, 4, 4)), "image must have shape (H, W) or (H, W, 3), got (4, 4, 4)"),
        (np.zeros(5), "image must have shape (H, W) or (H, W, 3), got (5,)"),
        (np.zeros((2, 2), dtype=complex), "image must hold real numbers, got dtype complex128"),
        (np.array([["a", "b"]]), "image must hold real numbers, got dtype <U1"),
    ],
)
def test_exr_bad_images_write_nothing(tmp_path, image, pattern):
    with pytest.raises(ParameterError, match=re.escape(pattern)):
        write_exr(tmp_path / "bad.exr", image, role="raw")
    assert only_entry(tmp_path) == []


# =============================================================================== JSON
def test_json_round_trip_with_schema_version(tmp_path):
    data = {
        "camera": {"name": "tiny", "focal_length_m": 6e-3, "offset_m": (1e-6, -2e-6)},
        "K": np.array([[120.0, 0.0, 45.5], [0.0, 120.0, 34.0], [0.0, 0.0, 1.0]]),
        "count": np.int64(7),
        "flag": np.bool_(True),
        "scale": np.float32(0.5),
        "where": tmp_path / "x.exr",
        "depth_far": float("inf"),
    }
    path = write_json(tmp_path / "meta" / "side.json", data)
    back = read_json(path)
    assert back["schema_version"] == SCHEMA_VERSION
    assert back["camera"] == {"name": "tiny", "focal_length_m": 6e-3, "offset_m": [1e-6, -2e-6]}
    assert back["K"] == [[120.0, 0.0, 45.5], [0.0, 120.0, 34.0], [0.0, 0.0, 1.0]]
    assert back["count"] == 7
    assert back["flag"] is True
    assert back["scale"] == 0.5
    assert back["where"] == str(tmp_path / "x.exr")
    # Non-finite numbers are written as strings so the file stays standard JSON.
    assert back["depth_far"] == "inf"

    def no_constants(name):
        raise AssertionError(f"non-standard JSON constant {name}")

    json.loads(path.read_text(), parse_constant=no_constants)
    assert only_entry(tmp_path / "meta") == ["side.json"]


def test_json_wrong_or_missing_schema_version(tmp_path):
    newer = tmp_path / "newer.json"
    newer.write_text(json.dumps({"schema_version": SCHEMA_VERSION + 1, "x": 1}))
    with pytest.raises(FileFormatError, match=re.escape(f"{str(newer)!r} has schema_version {SCHEMA_VERSION + 1}")):
        read_json(newer)
    bare = tmp_path / "bare.json"
    bare.write_text(json.dumps({"x": 1}))
    with pytest.raises(FileFormatError, match=re.escape(f"{str(bare)!r} has schema_version None")):
        read_json(bare)
    as_text = tmp_path / "text.json"
    as_text.write_text(json.dumps({"schema_version": str(SCHEMA_VERSION)}))
    with pytest.raises(FileFormatError, match="has schema_version '1'"):
        read_json(as_text)
    listing = tmp_path / "list.json"
    listing.write_text("[1, 2]")
    with pytest.raises(FileFormatError, match="has schema_version None"):
        read_json(listing)


def test_json_missing_and_malformed(tmp_path):
    with pytest.raises(FileFormatError, match=re.escape(f"no such file: {str(tmp_path / 'a.json')!r}")):
        read_json(tmp_path / "a.json")
    broken = tmp_path / "broken.json"
    broken.write_text('{"schema_version": 1,')
    with pytest.raises(FileFormatError, match=re.escape(f"{str(broken)!r} is not valid JSON")):
        read_json(broken)


@pytest.mark.parametrize(
    ("encoding", "reason"),
    [
        ("utf-16", "not UTF-8 text"),  # with a byte-order mark: 0xFF is never UTF-8
        ("utf-16-le", "not UTF-8 text"),  # no BOM: the 'e acute' is 0xE9 0x00
        ("utf-32", "not UTF-8 text"),
        ("latin-1", "not UTF-8 text"),  # the 'e acute' of the name is one byte 0xE9
        ("utf-8-sig", "not valid JSON"),  # a UTF-8 byte-order mark: RFC 8259 forbids it
    ],
)
def test_json_that_is_not_utf8_is_a_file_format_error(tmp_path, encoding, reason):
    # Issue 12: a UTF-16 meta.json (or a calibration output re-saved by an editor) gave a
    # UnicodeDecodeError traceback. The message names the file.
    path = tmp_path / "meta.json"
    path.write_bytes(
        json.dumps({"schema_version": SCHEMA_VERSION, "name": "Ren\u00e9"}, ensure_ascii=False).encode(encoding)
    )
    with pytest.raises(FileFormatError, match=re.escape(f"{str(path)!r} is {reason}")):
        read_json(path)


def test_json_nested_too_deeply_is_a_file_format_error(tmp_path):
    path = tmp_path / "deep.json"
    path.write_text('{"schema_version": 1, "x": ' + "[" * 100_000 + "]" * 100_000 + "}")
    with pytest.raises(FileFormatError, match=re.escape(f"{str(path)!r} is nested too deeply")):
        read_json(path)


def test_json_unserialisable_value_writes_nothing(tmp_path):
    with pytest.raises(TypeError, match="cannot write object to JSON"):
        write_json(tmp_path / "x.json", {"thing": object()})
    assert only_entry(tmp_path) == []


def test_flat_port_round_trip_in_the_refractive_colmap_layout(tmp_path):
    from lfrefract import FlatPort
    from lfrefract.formats.flatport import read_flat_port, write_flat_port

    port = FlatPort.from_degrees(distance_m=0.0592, thickness_m=0.005, tilt_x_deg=26.6, tilt_y_deg=-3.0, n_water=1.34)
    path = write_flat_port(tmp_path / "port.txt", port)
    lines = path.read_text().splitlines()
    assert lines[0] == "# Nx Ny Nz int_dist int_thick na ng nw"
    values = [float(v) for v in lines[1].split()]
    np.testing.assert_allclose(values[:3], port.normal, atol=1e-15)
    assert values[3:] == [0.0592, 0.005, 1.0, 1.5, 1.34]
    back = read_flat_port(path)
    np.testing.assert_allclose(back.normal, port.normal, atol=1e-15)
    assert (back.distance_m, back.thickness_m, back.n_water) == (0.0592, 0.005, 1.34)
    (tmp_path / "long.txt").write_text("0 0 2 0.02 0.005 1 1.5 1.333\n")
    with pytest.raises(FileFormatError, match="is not a unit vector"):
        read_flat_port(tmp_path / "long.txt")
    (tmp_path / "bad.txt").write_text("0 0 1 0.02\n")
    with pytest.raises(FileFormatError, match="is not a flat port"):
        read_flat_port(tmp_path / "bad.txt")
    with pytest.raises(ParameterError, match="port must be a FlatPort"):
        write_flat_port(tmp_path / "x.txt", {"distance_m": 0.02})
    assert not (tmp_path / "x.txt").exists()
