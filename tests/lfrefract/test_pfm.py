"""Portable Float Map files (lfrefract.formats.pfm): the HCI benchmark's disparity-map format.

Row order and byte order are checked against bytes built by hand here and against OpenCV's own PFM
reader and writer, which return and take the top row first and colour as B, G, R.
"""

from __future__ import annotations

import re
import struct
from pathlib import Path

import cv2
import numpy as np
import pytest

from lfrefract.errors import FileFormatError, ParameterError
from lfrefract.formats.pfm import read_pfm, write_pfm

SPECIAL = np.array([0.0, -0.0, 1.5, np.inf, -np.inf, np.nan, 1e-45, -3.4e38, 65504.0, 1e-8], dtype=np.float32)
# Non-canonical NaN payloads (quiet, negative, signalling) survive a little-endian round trip too.
PAYLOADS = np.array([0x7FC00001, 0xFFC12345, 0x7F800001], dtype=np.uint32).view(np.float32)


def bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float32).view(np.uint32)


def special_image(shape) -> np.ndarray:
    rng = np.random.default_rng(5)
    img = rng.normal(scale=3.0, size=shape).astype(np.float32)
    flat = img.reshape(-1)
    values = np.concatenate([SPECIAL, PAYLOADS])
    flat[: len(values)] = values
    return img


def entries(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.iterdir())


# 2 rows x 3 columns, top row first as in memory: the file stores the bottom row (10, 11, 12) first.
TOP_FIRST = np.array([[0.0, 1.0, 2.0], [10.0, 11.0, 12.0]], dtype=np.float32)
FILE_ORDER = (10.0, 11.0, 12.0, 0.0, 1.0, 2.0)


# =============================================================================== round trip
@pytest.mark.parametrize("shape", [(7, 11), (5, 9, 3), (1, 1), (1, 13, 3), (13, 1)])
def test_round_trip_is_bit_exact(tmp_path, shape):
    img = special_image(shape) if np.prod(shape) >= 13 else np.full(shape, np.nan, dtype=np.float32)
    path = write_pfm(tmp_path / "sub" / "gt_disp_lowres.pfm", img)
    assert path == tmp_path / "sub" / "gt_disp_lowres.pfm"
    back = read_pfm(path)
    assert back.dtype == np.float32
    assert back.shape == shape
    assert back.flags.c_contiguous
    assert back.flags.writeable
    np.testing.assert_array_equal(bits(back), bits(img))
    assert entries(tmp_path / "sub") == ["gt_disp_lowres.pfm"]


def test_other_real_types_are_stored_as_float32(tmp_path):
    f64 = np.array([[1.0 / 3.0, 1e30, -2.5], [np.nan, np.inf, -np.inf]])
    np.testing.assert_array_equal(bits(read_pfm(write_pfm(tmp_path / "a.pfm", f64))), bits(f64.astype(np.float32)))
    ints = np.arange(12, dtype=np.int32).reshape(3, 4)
    np.testing.assert_array_equal(read_pfm(write_pfm(tmp_path / "b.pfm", ints)), ints.astype(np.float32))
    # A non-contiguous view is written as the image it shows.
    view = np.arange(30, dtype=np.float32).reshape(5, 6)[::2, ::-1]
    np.testing.assert_array_equal(read_pfm(write_pfm(tmp_path / "c.pfm", view)), view)


def test_written_bytes(tmp_path):
    """Header 'Pf', width then height, scale -1 (little-endian), then the bottom row first."""
    path = write_pfm(tmp_path / "g.pfm", TOP_FIRST)
    assert path.read_bytes() == b"Pf\n3 2\n-1\n" + struct.pack("<6f", *FILE_ORDER)
    colour = np.zeros((1, 2, 3), dtype=np.float32)
    colour[0, 0] = (1.0, 2.0, 3.0)  # R, G, B of the left pixel
    colour[0, 1] = (4.0, 5.0, 6.0)
    path = write_pfm(tmp_path / "c.pfm", colour)
    assert path.read_bytes() == b"PF\n2 1\n-1\n" + struct.pack("<6f", 1.0, 2.0, 3.0, 4.0, 5.0, 6.0)


# =============================================================================== hand-made files
def test_reads_a_hand_made_little_endian_file(tmp_path):
    path = tmp_path / "hand.pfm"
    path.write_bytes(b"Pf\n3 2\n-1.000000\n" + struct.pack("<6f", *FILE_ORDER))
    back = read_pfm(path)
    np.testing.assert_array_equal(back, TOP_FIRST)
    assert back.dtype == np.float32


@pytest.mark.parametrize("scale", [b"1", b"1.0", b"+1.000000"])
def test_reads_big_endian_files(tmp_path, scale):
    path = tmp_path / "big.pfm"
    path.write_bytes(b"Pf\n3 2\n" + scale + b"\n" + struct.pack(">6f", *FILE_ORDER))
    back = read_pfm(path)
    np.testing.assert_array_equal(back, TOP_FIRST)
    assert back.dtype == np.float32
    assert back.dtype.byteorder in ("=", "<")  # native, whatever the file's order
    # Colour, big-endian, with NaN and inf: bottom row (one pixel) first, then the top row.
    path.write_bytes(b"PF\n1 2\n1\n" + struct.pack(">6f", 7.0, np.nan, 9.0, -np.inf, 2.0, 3.0))
    colour = read_pfm(path)
    assert colour.shape == (2, 1, 3)
    np.testing.assert_array_equal(colour[0, 0], [-np.inf, 2.0, 3.0])
    np.testing.assert_array_equal(colour[1, 0], [7.0, np.nan, 9.0])


def test_header_fields_may_be_separated_by_any_whitespace(tmp_path):
    """The format asks for one whitespace character after each header line, not necessarily a newline."""
    path = tmp_path / "spaces.pfm"
    path.write_bytes(b"Pf 3 2 -1 " + struct.pack("<6f", *FILE_ORDER))
    np.testing.assert_array_equal(read_pfm(path), TOP_FIRST)
    # Samples whose first byte is itself whitespace (0x20, 0x0a) are not taken for header.
    first = np.array([[struct.unpack("<f", b"\x20\x0a\x20\x3f")[0]]], dtype=np.float32)
    write_pfm(path, first)
    np.testing.assert_array_equal(bits(read_pfm(path)), bits(first))


# =============================================================================== OpenCV
def test_agrees_with_opencv_reader(tmp_path):
    """OpenCV reads PFM top row first, colour as B, G, R."""
    grey = special_image((6, 7))
    path = write_pfm(tmp_path / "g.pfm", grey)
    theirs = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert theirs.dtype == np.float32
    assert theirs.shape == (6, 7)
    np.testing.assert_array_equal(bits(theirs), bits(grey))
    rng = np.random.default_rng(8)
    colour = rng.normal(size=(4, 5, 3)).astype(np.float32)
    colour[0, 0] = (1.0, 2.0, 3.0)
    path = write_pfm(tmp_path / "c.pfm", colour)
    theirs = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert theirs.shape == (4, 5, 3)
    np.testing.assert_array_equal(theirs[0, 0], [3.0, 2.0, 1.0])
    np.testing.assert_array_equal(theirs[..., ::-1], colour)


def test_reads_what_opencv_writes(tmp_path):
    grey = np.arange(20, dtype=np.float32).reshape(4, 5) - 7.5
    grey[1, 2] = np.nan
    assert cv2.imwrite(str(tmp_path / "g.pfm"), grey)
    np.testing.assert_array_equal(read_pfm(tmp_path / "g.pfm"), grey)
    bgr = np.arange(36, dtype=np.float32).reshape(3, 4, 3)
    assert cv2.imwrite(str(tmp_path / "c.pfm"), bgr)
    np.testing.assert_array_equal(read_pfm(tmp_path / "c.pfm"), bgr[..., ::-1])


# =============================================================================== bad files
def test_missing_file_and_directory(tmp_path):
    path = tmp_path / "nope.pfm"
    with pytest.raises(FileFormatError, match=re.escape(f"no such file: {str(path)!r}")):
        read_pfm(path)
    with pytest.raises(FileFormatError, match=re.escape(f"{str(tmp_path)!r} is a directory, not a regular file")):
        read_pfm(tmp_path)


GOOD = b"Pf\n3 2\n-1\n" + struct.pack("<6f", *FILE_ORDER)


@pytest.mark.parametrize(
    ("content", "what"),
    [
        (b"", "is empty, not a PFM file"),
        (b"P6\n3 2\n255\n" + bytes(18), "is not a PFM file (it starts with b'P6\\n3 2\\n2', not 'PF' or 'Pf')"),
        (b"PFX\n3 2\n-1\n" + bytes(72), "is not a PFM file"),
        (b"Pf\n3 2\n", "incomplete or malformed PFM header"),
        (b"Pf\n3\n2\n-1\n" + bytes(24), "incomplete or malformed PFM header"),
        (b"Pf\n0 2\n-1\n", "the PFM width must be a positive integer, got b'0'"),
        (b"Pf\n3 -2\n-1\n" + bytes(24), "the PFM height must be a positive integer, got b'-2'"),
        (b"Pf\n3 2.5\n-1\n" + bytes(24), "the PFM height must be a positive integer, got b'2.5'"),
        (b"Pf\n3 2\nabc\n" + bytes(24), "the PFM scale must be a number, got b'abc'"),
        (b"Pf\n3 2\n0\n" + bytes(24), "the PFM scale must be a finite non-zero number, got b'0'"),
        (b"Pf\n3 2\nnan\n" + bytes(24), "the PFM scale must be a finite non-zero number, got b'nan'"),
        (b"Pf\n3 2\n-2.0\n" + bytes(24), "has PFM scale -2.0; only +1 and -1 are read"),
        (GOOD[:-1], "holds 23 bytes of samples, but its header describes a 3 x 2 greyscale PFM of 24 bytes"),
        (GOOD[:12], "(truncated)"),
        (GOOD + b"\0", "holds 25 bytes of samples, but its header describes a 3 x 2 greyscale PFM of 24 bytes"),
        (b"PF\n3 2\n-1\n" + struct.pack("<6f", *FILE_ORDER), "a 3 x 2 colour PFM of 72 bytes (truncated)"),
        (b"Pf\n3 2\r\n-1\r\n" + struct.pack("<6f", *FILE_ORDER), "(trailing data)"),
        (b"Pf\n999999999 999999999\n-1\n", "PFM of 3999999992000000004 bytes (truncated)"),
    ],
)
def test_bad_files_name_the_file(tmp_path, content, what):
    path = tmp_path / "bad.pfm"
    path.write_bytes(content)
    with pytest.raises(FileFormatError, match=re.escape(f"{str(path)!r}")) as info:
        read_pfm(path)
    assert what in str(info.value)


# =============================================================================== bad arrays
REAL = "image must hold real numbers (floating point or integer), got dtype"


@pytest.mark.parametrize(
    ("image", "pattern"),
    [
        (np.zeros((2, 2), dtype=complex), f"{REAL} complex128"),
        (np.zeros((4, 4, 4)), "image must have shape (H, W) or (H, W, 3), got (4, 4, 4)"),
        (np.zeros((4, 4, 1)), "image must have shape (H, W) or (H, W, 3), got (4, 4, 1)"),
        (np.zeros(5), "image must have shape (H, W) or (H, W, 3), got (5,)"),
        (np.zeros((0, 3)), "image must have at least one row and one column, got shape (0, 3)"),
        (np.zeros((2, 0, 3)), "image must have at least one row and one column, got shape (2, 0, 3)"),
        (
            np.zeros((2, 2), dtype=complex),
            "image must hold real numbers (floating point or integer), got dtype complex128",
        ),
        (np.zeros((2, 2), dtype=bool), "image must hold real numbers (floating point or integer), got dtype bool"),
        (np.array([["a", "b"]]), "image must hold real numbers (floating point or integer), got dtype <U1"),
        (np.array([[1.0, -1e39]]), "image holds finite values beyond float32's range, e.g. 1e+39"),
    ],
)
def test_bad_images_write_nothing(tmp_path, image, pattern):
    with pytest.raises(ParameterError, match=re.escape(pattern)):
        write_pfm(tmp_path / "bad.pfm", image)
    assert entries(tmp_path) == []


def test_a_failed_write_leaves_the_earlier_file(tmp_path, monkeypatch):
    path = write_pfm(tmp_path / "d.pfm", TOP_FIRST)
    with pytest.raises(ParameterError):
        write_pfm(path, np.zeros((3, 3, 2)))
    np.testing.assert_array_equal(read_pfm(path), TOP_FIRST)

    # A disk that fills up after the header: the partial file never takes the name, and is removed.
    real_open = Path.open

    class FullDisk:
        def __init__(self, fh):
            self.fh, self.writes = fh, 0

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.fh.close()

        def write(self, data):
            self.writes += 1
            if self.writes > 1:
                raise OSError(28, "No space left on device")
            return self.fh.write(data)

    monkeypatch.setattr(Path, "open", lambda self, *a, **k: FullDisk(real_open(self, *a, **k)))
    with pytest.raises(OSError, match="No space left on device"):
        write_pfm(path, np.ones((4, 5, 3)))
    monkeypatch.undo()
    np.testing.assert_array_equal(read_pfm(path), TOP_FIRST)
    assert entries(tmp_path) == ["d.pfm"]
    # A good write replaces it whole.
    write_pfm(path, np.ones((4, 5, 3)))
    np.testing.assert_array_equal(read_pfm(path), np.ones((4, 5, 3), dtype=np.float32))
    assert entries(tmp_path) == ["d.pfm"]


def test_writing_onto_a_directory_is_refused(tmp_path):
    (tmp_path / "out.pfm").mkdir()
    with pytest.raises(IsADirectoryError, match=re.escape(repr(str(tmp_path / "out.pfm")))):
        write_pfm(tmp_path / "out.pfm", TOP_FIRST)
    assert entries(tmp_path / "out.pfm") == []
