"""Lytro files (lfrefract.formats.lytro): a third-party decoder (imageio) reads our LFR and RAW files to
our mosaic exactly, our readers round-trip them, and broken files are refused naming the file."""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path

import cv2
import imageio  # a test dependency: the third-party reader these files must satisfy
import numpy as np
import pytest

from lfrefract.errors import FileFormatError, ParameterError
from lfrefract.formats import lytro
from lfrefract.formats.lytro import (
    CFA_PATTERNS,
    LytroSettings,
    RawMosaic,
    camera_from_metadata,
    f01_metadata,
    illum_metadata,
    pack_10bit,
    pack_12bit,
    read_f01_raw,
    read_illum_raw,
    read_lfr,
    unpack_10bit,
    unpack_12bit,
    write_f01_raw,
    write_illum_raw,
    write_lfr,
)
from lfrefract.optics.camera import MicrolensArray
from lfrefract.optics.presets import camera_preset

# imageio's raw readers open the metadata file beside a .raw without closing it (json.load(open(...))):
# the ResourceWarning it raises when the handle is collected is theirs.
IMAGEIO_LEAKS_A_HANDLE = pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")


def full_scale_mosaic(shape, bits, black, pattern, seed) -> RawMosaic:
    """Random digital numbers over the whole range, the extremes included."""
    rng = np.random.default_rng(seed)
    top = 2**bits - 1
    counts = rng.integers(0, top + 1, size=shape, dtype=np.uint16)
    counts.reshape(-1)[:4] = (0, top, 1, top - 1)
    return RawMosaic(counts=counts, bit_depth=bits, black_level_dn=black, white_level_dn=top, cfa_pattern=pattern)


def tilted_tiny():
    """The tiny test camera with a rotated, offset MLA, so every geometric field is non-trivial."""
    cam = camera_preset("tiny")
    mla = dataclasses.replace(cam.mla, rotation_rad=0.0123, offset_m=(3.5e-6, -2.25e-6))
    return dataclasses.replace(cam, mla=mla)


# =============================================================================== imageio reads ours
def test_imageio_reads_our_illum_lfr_exactly(tmp_path):
    """imageio's lytro-lfr reader (fixed to the Illum's 7728 x 5368 sensor) returns float64 counts / 1023:
    exactly our mosaic's, with our metadata, private metadata and a JPEG thumbnail of the stated size."""
    cam = camera_preset("illum")
    mosaic = full_scale_mosaic((5368, 7728), 10, 64, "GRBG", seed=1)
    settings = LytroSettings(zoom_step=-297, focus_step=309, white_balance_gain=(1.38, 1.0, 1.0, 1.15))
    path = write_lfr(tmp_path / "capture.lfr", mosaic, cam, settings=settings)

    image = imageio.v2.imread(path, format="lytro-lfr")
    assert image.dtype == np.float64
    assert image.shape == (5368, 7728)
    assert np.array_equal(image, mosaic.counts / 1023.0)
    assert np.array_equal(image, mosaic.full_scale())
    assert np.array_equal(np.rint(image * 1023.0).astype(np.uint16), mosaic.counts)
    meta = image.meta
    assert meta["metadata"] == illum_metadata(mosaic, cam, settings)
    assert meta["privateMetadata"]["camera"]["serialNumber"].startswith("B")
    thumb = meta["thumbnail"]
    assert thumb["image"].shape == (thumb["height"], thumb["width"], 3)
    assert max(thumb["width"], thumb["height"]) <= 640

    back = read_lfr(path)
    assert np.array_equal(back.mosaic.counts, mosaic.counts)
    assert (back.mosaic.bit_depth, back.mosaic.black_level_dn, back.mosaic.white_level_dn, back.mosaic.cfa_pattern) == (
        10,
        64,
        1023,
        "GRBG",
    )
    assert back.camera == cam
    assert back.metadata == meta["metadata"]
    assert back.private_metadata == meta["privateMetadata"]


@IMAGEIO_LEAKS_A_HANDLE
def test_imageio_reads_our_f01_raw_exactly(tmp_path):
    """imageio's lytro-f01-raw reader (fixed to 3280 x 3280) returns counts / 4095 and the JSON beside it."""
    cam = camera_preset("f01")
    mosaic = full_scale_mosaic((3280, 3280), 12, 168, "BGGR", seed=2)
    raw_path, meta_path = write_f01_raw(tmp_path / "IMG_0001__frame.raw", mosaic, cam)
    assert meta_path == tmp_path / "IMG_0001__frame.json"
    assert raw_path.stat().st_size == 3280 * 3280 * 3 // 2

    image = imageio.v2.imread(raw_path, format="lytro-f01-raw")
    assert image.dtype == np.float64
    assert np.array_equal(image, mosaic.counts / 4095.0)
    assert np.array_equal(np.rint(image * 4095.0).astype(np.uint16), mosaic.counts)
    assert image.meta == f01_metadata(mosaic, cam)
    assert image.meta["camera"]["serialNumber"].startswith("A")

    back = read_f01_raw(raw_path)
    assert np.array_equal(back.mosaic.counts, mosaic.counts)
    assert (back.mosaic.black_level_dn, back.mosaic.white_level_dn, back.mosaic.cfa_pattern) == (168, 4095, "BGGR")
    assert back.camera == dataclasses.replace(cam, name="lytro-metadata")


@IMAGEIO_LEAKS_A_HANDLE
def test_imageio_reads_our_illum_raw_white_image(tmp_path):
    """The Illum's bare RAW + TXT (how its factory white images ship): imageio's lytro-illum-raw reads it."""
    cam = camera_preset("illum")
    mosaic = full_scale_mosaic((5368, 7728), 10, 64, "GRBG", seed=3)
    raw_path, meta_path = write_illum_raw(tmp_path / "white.raw", mosaic, cam)
    assert meta_path.suffix == ".txt"
    image = imageio.v2.imread(raw_path, format="lytro-illum-raw")
    assert np.array_equal(image, mosaic.counts / 1023.0)
    assert image.meta == illum_metadata(mosaic, cam)
    back = read_illum_raw(raw_path)
    assert np.array_equal(back.mosaic.counts, mosaic.counts)


# =============================================================================== packing
def test_10bit_packing_bytes_by_hand():
    # 8 high bits of each pixel, then the 2 low bits of pixel k in bits 2k..2k+1 of the fifth byte.
    packed = pack_10bit(np.array([[1023, 0, 1, 2, 4, 5, 1022, 512]], dtype=np.uint16))
    assert packed == bytes([255, 0, 0, 0, 3 | 1 << 4 | 2 << 6, 1, 1, 255, 128, 0 | 1 << 2 | 2 << 4 | 0 << 6])
    assert np.array_equal(unpack_10bit(packed, (1, 8)), [[1023, 0, 1, 2, 4, 5, 1022, 512]])


def test_12bit_packing_bytes_by_hand():
    packed = pack_12bit(np.array([[0xABC, 0x123], [0xFFF, 0x000]], dtype=np.uint16))
    assert packed == bytes([0xAB, 0xC1, 0x23, 0xFF, 0xF0, 0x00])
    assert np.array_equal(unpack_12bit(packed, (2, 2)), [[0xABC, 0x123], [0xFFF, 0]])


@pytest.mark.parametrize("bits", [10, 12])
def test_packing_round_trips_every_value(bits):
    values = np.arange(2**bits, dtype=np.uint16).reshape(-1, 8)
    pack, unpack = (pack_10bit, unpack_10bit) if bits == 10 else (pack_12bit, unpack_12bit)
    packed = pack(values)
    assert len(packed) == values.size * bits // 8
    assert np.array_equal(unpack(packed, values.shape), values)


def test_packing_refuses_values_it_cannot_hold():
    with pytest.raises(ParameterError, match="1023"):
        pack_10bit(np.array([[1024, 0, 0, 0]], dtype=np.uint16))
    with pytest.raises(ParameterError, match="divisible by 4"):
        pack_10bit(np.zeros((1, 6), dtype=np.uint16))
    with pytest.raises(ParameterError, match="even"):
        pack_12bit(np.zeros((1, 3), dtype=np.uint16))


# =============================================================================== our round trips
@pytest.mark.parametrize("pattern", CFA_PATTERNS)
def test_lfr_round_trip_of_a_small_camera(tmp_path, pattern):
    cam = tilted_tiny()
    mosaic = full_scale_mosaic((360, 480), 10, 32, pattern, seed=4)
    path = write_lfr(tmp_path / "c.lfr", mosaic, cam)
    back = read_lfr(path)
    assert np.array_equal(back.mosaic.counts, mosaic.counts)
    assert back.mosaic.cfa_pattern == pattern
    assert back.camera == cam
    # The metadata alone describes the same camera (the name aside): rotation, offset, gap, pupil.
    assert camera_from_metadata(back.metadata) == dataclasses.replace(cam, name="lytro-metadata")
    assert (
        back.metadata["image"]["mosaic"]["upperLeftPixel"]
        == {"GRBG": "gr", "RGGB": "r", "GBRG": "gb", "BGGR": "b"}[pattern]
    )


@pytest.mark.parametrize("pattern", CFA_PATTERNS)
def test_thumbnail_shows_the_colour_that_was_lit(tmp_path, pattern):
    """Only the red sites lit: the thumbnail is red, whatever the pattern (a wrong site map makes it green or blue)."""
    cam = camera_preset("tiny")
    row, col = divmod(pattern.index("R"), 2)
    counts = np.full((360, 480), 32, dtype=np.uint16)
    counts[row::2, col::2] = 1023
    path = write_lfr(
        tmp_path / "red.lfr",
        RawMosaic(counts=counts, bit_depth=10, black_level_dn=32, white_level_dn=1023, cfa_pattern=pattern),
        cam,
    )
    bgr = cv2.imdecode(np.frombuffer(read_lfr(path).thumbnail_jpeg, dtype=np.uint8), cv2.IMREAD_COLOR)
    b, g, r = (float(bgr[..., k].mean()) for k in range(3))
    assert r > 240
    assert max(g, b) < 15


def test_exit_pupil_and_steps_are_recorded(tmp_path):
    cam = camera_preset("tiny")
    settings = LytroSettings(
        exit_pupil_offset_m=0.0973, zoom_step=-5, focus_step=7, color_matrix=(2, -1, 0, 0, 2, -1, -1, 0, 2)
    )
    meta = illum_metadata(full_scale_mosaic((360, 480), 10, 64, "GRBG", 5), cam, settings)
    lens = meta["devices"]["lens"]
    assert lens["exitPupilOffset"]["z"] == 0.0973
    assert (lens["zoomStep"], lens["focusStep"]) == (-5, 7)
    assert meta["image"]["color"]["ccm"] == [2.0, -1.0, 0.0, 0.0, 2.0, -1.0, -1.0, 0.0, 2.0]
    assert meta["devices"]["mla"]["sensorOffset"]["z"] == cam.mla.focal_length_m
    assert meta["devices"]["sensor"]["pixelPitch"] == cam.sensor.pixel_pitch_m
    # PlenoptiCam scales its highlight clipping by 2 ** -modulationExposureBias: it must be a number.
    assert meta["image"]["modulationExposureBias"] == 0.0


def test_a_capture_through_a_real_lens_reads_as_its_white_image_does(tmp_path):
    """A real main lens's exit pupil lies elsewhere than the thin lens's (the retrofocus design's at
    18.4 mm for a 12 mm focal length): the LFR then carries no thin-lens camera section, which would
    put the micro-images elsewhere than its metadata (the white's 3.4 px away at the tiny-2x sensor's
    edge), and reads back the camera the metadata describes, the white image's."""
    cam = camera_preset("tiny")
    mosaic = full_scale_mosaic((cam.sensor.height_px, cam.sensor.width_px), 10, 64, "GRBG", 3)
    real = LytroSettings(exit_pupil_offset_m=1.5 * cam.lens_to_mla_m)
    capture = read_lfr(write_lfr(tmp_path / "capture.lfr", mosaic, cam, settings=real))
    white = read_illum_raw(write_illum_raw(tmp_path / "white.raw", mosaic, cam, settings=real)[0])
    assert capture.camera == white.camera
    assert capture.camera.lens_to_mla_m == 1.5 * cam.lens_to_mla_m
    assert "cameraRef" not in json.loads(_toc_bytes(tmp_path / "capture.lfr"))["lfrefract"]
    # still eleven content sections, the count imageio's reader walks
    sections = parse_sections((tmp_path / "capture.lfr").read_bytes())
    assert sum(magic == lytro.LFC_MAGIC for magic, _, _ in sections) == 11
    # through the thin lens itself the exact camera travels with the file
    thin = read_lfr(write_lfr(tmp_path / "thin.lfr", mosaic, cam, settings=LytroSettings()))
    assert thin.camera == cam


def _toc_bytes(path: Path) -> bytes:
    return next(body for magic, _, body in parse_sections(path.read_bytes()) if magic == lytro.LFM_MAGIC)


def test_square_mla_is_recorded_as_square(tmp_path):
    cam = camera_preset("tiny")
    square = dataclasses.replace(cam, mla=MicrolensArray(grid="square", pitch_m=100e-6, focal_length_m=200e-6))
    back = read_lfr(write_lfr(tmp_path / "sq.lfr", full_scale_mosaic((360, 480), 10, 64, "GRBG", 6), square))
    assert back.metadata["devices"]["mla"]["tiling"] == "squareUniformRowMajor"
    assert camera_from_metadata(back.metadata).mla.grid == "square"


# =============================================================================== the container, independently
LFP = b"\x89LFP\r\n\x1a\n\x00\x00\x00\x01"
LFC = b"\x89LFC\r\n\x1a\n\x00\x00\x00\x00"
LFM = b"\x89LFM\r\n\x1a\n\x00\x00\x00\x00"


def parse_sections(data: bytes) -> list[tuple[bytes, str, bytes]]:
    """An independent reading of the layout: 96-byte section headers, data, zeros to 16-byte boundaries."""
    assert data[:16] == LFP + b"\0\0\0\0"
    pos, out = 16, []
    while pos < len(data):
        magic, size = data[pos : pos + 12], int.from_bytes(data[pos + 12 : pos + 16], "big")
        name = data[pos + 16 : pos + 61].decode("ascii")
        assert data[pos + 61 : pos + 96] == b"\0" * 35
        body = data[pos + 96 : pos + 96 + size]
        out.append((magic, name, body))
        pos += 96 + size
        pos += (-pos) % 16
    assert pos == len(data)
    return out


def assemble(sections: list[tuple[bytes, bytes]]) -> bytes:
    """An LFR file from (magic, data) pairs, each named by its SHA-1."""
    parts = [LFP, b"\0\0\0\0"]
    for magic, body in sections:
        parts += [magic, len(body).to_bytes(4, "big"), b"sha1-" + hashlib.sha1(body).hexdigest().encode()]
        parts += [b"\0" * 35, body, b"\0" * ((-len(body)) % 16)]
    return b"".join(parts)


def small_lfr(tmp_path) -> tuple[Path, RawMosaic]:
    mosaic = full_scale_mosaic((360, 480), 10, 64, "GRBG", seed=7)
    return write_lfr(tmp_path / "small.lfr", mosaic, camera_preset("tiny")), mosaic


def test_layout_is_eleven_named_sections_then_the_table_of_contents(tmp_path):
    path, mosaic = small_lfr(tmp_path)
    sections = parse_sections(path.read_bytes())
    assert [m for m, _, _ in sections] == [LFC] * 11 + [LFM]
    for _, name, body in sections:
        assert name == "sha1-" + hashlib.sha1(body).hexdigest()
    toc = json.loads(sections[-1][2])
    by_name = {name: body for _, name, body in sections}
    frame = toc["frames"][0]["frame"]
    assert by_name[frame["imageRef"]] == pack_10bit(mosaic.counts)
    assert json.loads(by_name[frame["metadataRef"]])["image"]["pixelPacking"] == {
        "bitsPerPixel": 10,
        "endianness": "little",
    }
    assert by_name[toc["thumbnails"][0]["imageRef"]][:2] == b"\xff\xd8"  # a JPEG
    named = {frame[k] for k in frame} | {toc["thumbnails"][0]["imageRef"], toc["lfrefract"]["cameraRef"]}
    assert named | set(toc["lfrefract"]["reservedRefs"]) == {name for m, name, _ in sections if m == LFC}


def test_reader_takes_the_table_of_contents_anywhere(tmp_path):
    """Lytro's first camera puts the table of contents first; the reader finds it wherever it is."""
    path, mosaic = small_lfr(tmp_path)
    sections = parse_sections(path.read_bytes())
    reordered = tmp_path / "toc-first.lfr"
    reordered.write_bytes(assemble([(m, b) for m, _, b in [sections[-1], *sections[:-1]]]))
    assert np.array_equal(read_lfr(reordered).mosaic.counts, mosaic.counts)


# =============================================================================== broken files
def refused(path: Path, match: str) -> None:
    with pytest.raises(FileFormatError, match=match) as info:
        read_lfr(path)
    assert str(path) in str(info.value)


def test_missing_and_foreign_files_are_refused(tmp_path):
    refused(tmp_path / "nothing.lfr", "no such file")
    foreign = tmp_path / "foreign.lfr"
    foreign.write_bytes(b"\x89PNG\r\n\x1a\n" + b"\0" * 200)
    refused(foreign, "not a Lytro")
    empty = tmp_path / "empty.lfr"
    empty.write_bytes(b"")
    refused(empty, "not a Lytro")


def test_truncated_files_are_refused(tmp_path):
    path, _ = small_lfr(tmp_path)
    data = path.read_bytes()
    sections = parse_sections(data)
    image_end = data.index(sections[2][2]) + len(sections[2][2])
    for cut, match in [(image_end - 1000, "truncated"), (len(data) - 100, "truncated"), (40, "truncated")]:
        short = tmp_path / f"cut{cut}.lfr"
        short.write_bytes(data[:cut])
        refused(short, match)
    # Cut exactly after the last data section: every section whole, the table of contents gone.
    whole = tmp_path / "no-toc.lfr"
    whole.write_bytes(assemble([(m, b) for m, _, b in sections[:-1]]))
    refused(whole, "table-of-contents")


def test_a_section_whose_data_does_not_match_its_sha1_is_refused(tmp_path):
    path, _ = small_lfr(tmp_path)
    data = bytearray(path.read_bytes())
    image = parse_sections(bytes(data))[2][2]
    data[bytes(data).index(image) + 12345] ^= 0x40
    broken = tmp_path / "flipped.lfr"
    broken.write_bytes(bytes(data))
    refused(broken, "its data is sha1-")


def test_wrong_magic_inside_is_refused(tmp_path):
    path, _ = small_lfr(tmp_path)
    data = bytearray(path.read_bytes())
    data[16:28] = b"\x89LFX\r\n\x1a\n\x00\x00\x00\x00"
    broken = tmp_path / "magic.lfr"
    broken.write_bytes(bytes(data))
    refused(broken, "neither LFC nor LFM")


def test_an_image_section_of_the_wrong_size_is_refused(tmp_path):
    """Well-formed sections, but the image is 5 bytes short of what the metadata's size needs."""
    path, _ = small_lfr(tmp_path)
    sections = parse_sections(path.read_bytes())
    toc = json.loads(sections[-1][2])
    image_name = toc["frames"][0]["frame"]["imageRef"]
    short_image = next(b for _, n, b in sections if n == image_name)[:-5]
    toc["frames"][0]["frame"]["imageRef"] = "sha1-" + hashlib.sha1(short_image).hexdigest()
    rebuilt = [(m, short_image if n == image_name else b) for m, n, b in sections[:-1]]
    broken = tmp_path / "short-image.lfr"
    broken.write_bytes(assemble([*rebuilt, (LFM, json.dumps(toc).encode())]))
    refused(broken, "wrong image size")


def test_raw_files_of_the_wrong_size_or_without_metadata_are_refused(tmp_path):
    cam = camera_preset("tiny")
    raw_path, meta_path = write_f01_raw(tmp_path / "f.raw", full_scale_mosaic((360, 480), 12, 168, "BGGR", 8), cam)
    raw_path.write_bytes(raw_path.read_bytes()[:-3])
    with pytest.raises(FileFormatError, match="wrong size") as info:
        read_f01_raw(raw_path)
    assert str(raw_path) in str(info.value)
    meta_path.unlink()
    with pytest.raises(FileFormatError, match="no metadata"):
        read_f01_raw(raw_path)
    with pytest.raises(FileFormatError, match="no such file"):
        read_illum_raw(tmp_path / "none.raw", metadata_suffix=".txt")


# =============================================================================== writing
def test_writes_are_atomic_and_leave_nothing_behind(tmp_path):
    path, mosaic = small_lfr(tmp_path)
    before = path.read_bytes()
    with pytest.raises(ParameterError, match="bit_depth"):
        write_lfr(
            path,
            RawMosaic(counts=mosaic.counts, bit_depth=12, black_level_dn=64, white_level_dn=4095, cfa_pattern="GRBG"),
            camera_preset("tiny"),
        )
    assert path.read_bytes() == before
    write_lfr(path, mosaic, camera_preset("tiny"), settings=LytroSettings(serial_number="B123"))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["small.lfr"]
    assert read_lfr(path).private_metadata["camera"]["serialNumber"] == "B123"
    with pytest.raises(IsADirectoryError):
        write_lfr(tmp_path, mosaic, camera_preset("tiny"))


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"counts": np.zeros((4, 4))}, "integer array"),
        ({"counts": np.full((4, 4), 1024)}, r"\[0, 1023\]"),
        ({"counts": np.full((4, 4), -1)}, r"\[0, 1023\]"),
        ({"counts": np.zeros(16, dtype=np.uint16)}, "2-D"),
        ({"black_level_dn": 1023}, "below white_level"),
        ({"white_level_dn": 1024}, "white_level"),
        ({"cfa_pattern": "RGBG"}, "cfa_pattern"),
        ({"counts": np.zeros((1, 4), dtype=np.uint16)}, "2 x 2"),
        ({"bit_depth": 17}, "bit_depth"),
    ],
)
def test_mosaic_parameters_are_validated(kwargs, match):
    args = {"counts": np.zeros((4, 4), dtype=np.uint16), "bit_depth": 10, "black_level_dn": 64, "white_level_dn": 1023}
    args |= {"cfa_pattern": "GRBG"} | kwargs
    with pytest.raises(ParameterError, match=match):
        RawMosaic(**args)


def test_writers_check_the_mosaic_against_the_camera(tmp_path):
    tiny = camera_preset("tiny")
    with pytest.raises(ParameterError, match="does not match"):
        write_lfr(tmp_path / "a.lfr", full_scale_mosaic((360, 484), 10, 64, "GRBG", 9), tiny)
    with pytest.raises(ParameterError, match="12-bit"):
        write_f01_raw(tmp_path / "a.raw", full_scale_mosaic((360, 480), 10, 64, "GRBG", 9), tiny)
    odd = dataclasses.replace(tiny, sensor=dataclasses.replace(tiny.sensor, width_px=482))
    with pytest.raises(ParameterError, match="multiple"):
        write_lfr(tmp_path / "a.lfr", full_scale_mosaic((360, 482), 10, 64, "GRBG", 9), odd)
    assert not any(tmp_path.iterdir())


def test_settings_are_validated():
    with pytest.raises(ParameterError, match="color_matrix"):
        LytroSettings(color_matrix=(1.0, 0.0))
    with pytest.raises(ParameterError, match=r"white_balance_gain\[2\]"):
        LytroSettings(white_balance_gain=(1.0, 1.0, 0.0, 1.0))
    with pytest.raises(ParameterError, match="exit_pupil_offset_m"):
        LytroSettings(exit_pupil_offset_m=float("nan"))
    with pytest.raises(ParameterError, match="serial_number"):
        LytroSettings(serial_number="B\n1")
    assert LytroSettings(serial_number="x").serial_for("B") == "B-x"


def test_module_names_what_it_exports():
    assert sorted(lytro.__all__) == lytro.__all__
    assert all(hasattr(lytro, name) for name in lytro.__all__)


def test_packing_refuses_what_a_cast_would_change():
    """Floats were rounded and negatives wrapped by the cast to uint16 before the range check."""
    for pack, bits in ((pack_10bit, 10), (pack_12bit, 12)):
        with pytest.raises(ParameterError, match=rf"{bits}-bit packing needs integer counts, got dtype float64"):
            pack(np.array([[1.9, 2.5, 3.7, 0.2]]))
        with pytest.raises(
            ParameterError, match=rf"{bits}-bit packing needs values in \[0, {2**bits - 1}\], got \[-1, "
        ):
            pack(np.array([[-1, 2, 3, 4]], dtype=np.int32))


def test_a_long_narrow_sensor_gets_a_thumbnail(tmp_path):
    """A sensor more than 640 micro-image tiles long and 1 tile high failed to reshape its thumbnail."""
    cam = camera_preset("tiny")
    cam = dataclasses.replace(cam, sensor=dataclasses.replace(cam.sensor, width_px=2600, height_px=2))
    mosaic = full_scale_mosaic((2, 2600), 10, 64, "GRBG", seed=5)
    back = read_lfr(write_lfr(tmp_path / "narrow.lfr", mosaic, cam))
    assert np.array_equal(back.mosaic.counts, mosaic.counts)


@pytest.mark.parametrize("reader", ["f01", "illum"])
def test_raw_metadata_with_an_impossible_size_is_refused(tmp_path, reader):
    """A width or height of -2 in a bare RAW's metadata escaped as numpy's reshape error."""
    cam = camera_preset("tiny")
    if reader == "f01":
        raw_path, meta_path = write_f01_raw(tmp_path / "f.raw", full_scale_mosaic((360, 480), 12, 168, "BGGR", 8), cam)
        read = read_f01_raw
    else:
        raw_path, meta_path = write_illum_raw(tmp_path / "i.raw", full_scale_mosaic((360, 480), 10, 64, "GRBG", 8), cam)
        read = read_illum_raw
    meta = json.loads(meta_path.read_text())
    meta["image"]["width"] = meta["image"]["height"] = -2
    meta_path.write_text(json.dumps(meta))
    with pytest.raises(FileFormatError, match=r"-2 x -2 pixels: its size must be positive"):
        read(raw_path)


def test_mosaics_take_keywords_only():
    """Positional levels could be swapped unnoticed (black for white): the fields are keyword-only."""
    counts = np.zeros((2, 2), dtype=np.uint16)
    with pytest.raises(TypeError):
        RawMosaic(counts, 10, 32, 1023, "GRBG")


# =============================================================================== metadata checked
def edited_raw(tmp_path, reader: str, edit) -> Path:
    """A tiny Illum (or F01) RAW whose metadata ``edit(meta)`` changed in place."""
    cam = camera_preset("tiny")
    if reader == "f01":
        raw_path, meta_path = write_f01_raw(tmp_path / "f.raw", full_scale_mosaic((360, 480), 12, 168, "BGGR", 8), cam)
    else:
        raw_path, meta_path = write_illum_raw(tmp_path / "i.raw", full_scale_mosaic((360, 480), 10, 64, "GRBG", 8), cam)
    meta = json.loads(meta_path.read_text())
    edit(meta)
    meta_path.write_text(json.dumps(meta))
    return raw_path


def _swap_size(meta):
    meta["image"]["width"], meta["image"]["height"] = meta["image"]["height"], meta["image"]["width"]


def _set(path: str, value):
    def edit(meta):
        *parents, last = path.split(".")
        node = meta
        for key in parents:
            node = node[key]
        node[last] = value

    return edit


@pytest.mark.parametrize(
    ("reader", "edit", "match"),
    [
        # Width and height swapped: the same byte count, read as a sheared image.
        ("illum", _swap_size, r"image.width.*360.*devices.sensor.pixelWidth.*480"),
        (
            "illum",
            _set("devices.sensor.bitsPerPixel", 12),
            r"bitsPerPixel' is 10 but 'devices.sensor.bitsPerPixel' is 12",
        ),
        ("illum", _set("devices.sensor.mosaic.upperLeftPixel", "b"), r"devices.sensor.mosaic.*image.mosaic"),
        ("f01", _set("devices.sensor.mosaic.upperLeftPixel", "r"), r"devices.sensor.mosaic.*image.rawDetails.mosaic"),
        ("illum", _set("image.pixelFormat.rightShift", 2), r"image.pixelFormat.rightShift.*2"),
        ("f01", _set("image.rawDetails.pixelFormat.rightShift", "x"), r"rightShift.*'x'"),
        ("illum", _set("devices.sensor.pixelWidth", "480"), r"devices.sensor.pixelWidth.*integer.*'480'"),
    ],
)
def test_metadata_that_contradicts_itself_is_refused_naming_the_keys(tmp_path, reader, edit, match):
    path = edited_raw(tmp_path, reader, edit)
    read = read_f01_raw if reader == "f01" else read_illum_raw
    with pytest.raises(FileFormatError, match=match):
        read(path)


def test_an_lfr_whose_camera_section_contradicts_its_image_is_refused(tmp_path):
    cam = camera_preset("tiny")
    other = dataclasses.replace(cam, sensor=dataclasses.replace(cam.sensor, width_px=360, height_px=480))
    mosaic = full_scale_mosaic((360, 480), 10, 64, "GRBG", 8)
    path = write_lfr(tmp_path / "c.lfr", mosaic, cam)
    data = bytearray(path.read_bytes())
    old = json.dumps({"lfrefractCamera": cam.to_dict()}, indent=2).encode()
    new = json.dumps({"lfrefractCamera": other.to_dict()}, indent=2).encode()
    sections = parse_sections(bytes(data))
    rebuilt = [(magic, new if body == old else body) for magic, _, body in sections]
    assert any(body == old for _, _, body in sections)
    toc = json.loads(rebuilt[-1][1])
    toc["lfrefract"]["cameraRef"] = lytro._sha1_name(new)
    rebuilt[-1] = (rebuilt[-1][0], json.dumps(toc).encode())
    path.write_bytes(assemble(rebuilt))
    with pytest.raises(FileFormatError, match=r"lfrefractCamera.*360 x 480.*480 x 360"):
        read_lfr(path)


@pytest.mark.parametrize(
    ("key", "value", "match"),
    [
        ("ccm", [0.0] * 9, r"image.color.ccm.*singular"),
        ("ccm", [1, 0, 0, 0, 1, 0, 0, 0, float("nan")], r"image.color.ccm.*finite.*nan"),
        ("ccm", [1, 0, 0, 0, 1, 0, 0, 0], r"image.color.ccm.*9 numbers"),
        ("ccm", "identity", r"image.color.ccm.*9 numbers.*'identity'"),
        ("ccm", [-1, 0, 0, 0, 1, 0, 0, 0, 1], r"image.color.ccm.*row 0.*no light"),
        ("ccm", [1e300, 0, 0, 0, 1, 0, 0, 0, 1], r"image.color.ccm.*entry beyond"),
        ("whiteBalanceGain", {"r": 1.0, "gr": 1.0, "gb": 1.0}, r"image.color.whiteBalanceGain.*'b'"),
        ("whiteBalanceGain", {"r": "2", "gr": 1.0, "gb": 1.0, "b": 1.0}, r"whiteBalanceGain.r.*'2'"),
        ("whiteBalanceGain", {"r": 0.0, "gr": 1.0, "gb": 1.0, "b": 1.0}, r"whiteBalanceGain.r.*0"),
        ("whiteBalanceGain", [1, 1, 1, 1], r"image.color.whiteBalanceGain.*table"),
    ],
)
def test_a_malformed_colour_is_refused_naming_the_key(tmp_path, key, value, match):
    """A malformed ccm or gain was replaced by identity / 1, an all-zero ccm gave a black image."""
    path = edited_raw(tmp_path, "illum", _set(f"image.color.{key}", value))
    with pytest.raises(FileFormatError, match=match):
        lytro.colour_from_metadata(read_illum_raw(path).metadata, where=repr(str(path)))


def test_colour_keys_are_read_and_their_absence_named(tmp_path):
    ccm = [1.5, -0.3, -0.2, -0.1, 1.3, -0.2, 0.0, -0.4, 1.4]
    settings = LytroSettings(color_matrix=ccm, white_balance_gain=(2.0, 1.0, 1.2, 1.5))
    cam = camera_preset("tiny")
    for write in (write_illum_raw, write_f01_raw):
        bits = 10 if write is write_illum_raw else 12
        _, meta_path = write(
            tmp_path / f"{bits}.raw", full_scale_mosaic((360, 480), bits, 64, "GRBG", 8), cam, settings=settings
        )
        metadata = json.loads(meta_path.read_text())
        matrix, gains = lytro.colour_from_metadata(metadata, where="m")
        np.testing.assert_array_equal(matrix, np.reshape(ccm, (3, 3)))
        assert gains == (2.0, 1.1, 1.5)
        del metadata["image"]["color"]
        with pytest.raises(FileFormatError, match=r"m: the metadata has no 'image.color"):
            lytro.colour_from_metadata(metadata, where="m")


@pytest.mark.parametrize("matrix", [(0.0,) * 9, (1, 0, 0, 0, 1, 0, 0, 0, -1)])
def test_settings_refuse_a_colour_matrix_that_loses_light(matrix):
    with pytest.raises(ParameterError, match="color_matrix"):
        LytroSettings(color_matrix=matrix)


def test_a_short_or_extended_lfr_says_what_is_wrong(tmp_path):
    """10 bytes of the magic were 'not a Lytro file', trailing garbage 'truncated'."""
    path, _ = small_lfr(tmp_path)
    data = path.read_bytes()
    (tmp_path / "ten.lfr").write_bytes(data[:10])
    refused(tmp_path / "ten.lfr", r"truncated: 10 bytes, too short for the 16-byte LFP header")
    (tmp_path / "tail.lfr").write_bytes(data + b"garbage!" * 5)
    refused(tmp_path / "tail.lfr", rf"40 bytes after the last section \(from byte {len(data)}\) are no section")
    (tmp_path / "cut.lfr").write_bytes(data + lytro.LFC_MAGIC + b"\0\0")
    refused(tmp_path / "cut.lfr", r"truncated: 14 bytes .* too few for a 96-byte section header")


def test_a_lens_whose_exit_pupil_is_smaller_than_its_entrance_pupil_is_read_not_refused(tmp_path):
    """The telephoto design of scenes/lenses/ at tiny-2x: exit pupil 8.8 mm from the MLA, f = 12 mm,
    f/2.2; read as a thin lens at the exit pupil with the entrance pupil's size its image-side
    f-number would be 1.62, below the microlenses' 2 (refused before, though the simulator rendered
    the camera's white). The camera read fills the microlenses exactly; a non-positive f-number is
    still refused naming the key."""
    cam = camera_preset("tiny-2x")
    mosaic = full_scale_mosaic((cam.sensor.height_px, cam.sensor.width_px), 10, 64, "GRBG", 4)
    settings = LytroSettings(exit_pupil_offset_m=8.8e-3)
    white = read_illum_raw(write_illum_raw(tmp_path / "white.raw", mosaic, cam, settings=settings)[0])
    assert white.camera.lens_to_mla_m == 8.8e-3
    assert white.camera.image_side_f_number == pytest.approx(cam.mla.f_number, rel=1e-12)
    assert white.camera.f_number == pytest.approx(cam.mla.f_number * cam.focal_length_m / 8.8e-3, rel=1e-12)
    metadata = dict(white.metadata)
    metadata["devices"] = json.loads(json.dumps(metadata["devices"]))
    metadata["devices"]["lens"]["fNumber"] = -2.0
    with pytest.raises(FileFormatError, match="f_number"):
        camera_from_metadata(metadata)
