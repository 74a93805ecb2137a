"""A sample's images in each dataset format: exact where the format is, within half a code step in
16-bit PNG, the codes read back by OpenCV itself, non-finite values kept, bad input refused."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from lfrefract import ParameterError
from lfrefract.errors import FileFormatError
from lfrefract.formats.exr import write_exr
from simulator.dataset.images import (
    IMAGE_FORMATS,
    PNG_DATA_CODES,
    PNG_SPECIAL_CODES,
    exr_entry,
    read_image,
    write_image,
)
from tests.tolerances import PNG16_DECODE_FLOAT32_RELATIVE


def _float_image(rng: np.random.Generator, channels: int | None) -> np.ndarray:
    shape = (6, 9) if channels is None else (6, 9, channels)
    image = rng.uniform(-2.0, 5.0, shape).astype(np.float32)
    image.flat[3], image.flat[7], image.flat[11] = np.nan, np.inf, -np.inf
    return image


@pytest.mark.parametrize("image_format", IMAGE_FORMATS)
@pytest.mark.parametrize("channels", [None, 3])
def test_float_images_round_trip(tmp_path, image_format, channels):
    image = _float_image(np.random.default_rng(1), channels)
    entry = write_image(tmp_path, "x", image, image_format=image_format, role="normal")
    back = read_image(tmp_path, entry)
    assert back.dtype == np.float32
    assert back.shape == image.shape
    assert entry["file"] == "x." + {"exr": "exr", "npz": "npz", "png16": "png"}[image_format]
    finite = np.isfinite(image)
    assert np.array_equal(np.isnan(back), np.isnan(image))
    assert np.array_equal(np.isinf(back) & (back > 0), np.isinf(image) & (image > 0))
    assert np.array_equal(np.isinf(back) & (back < 0), np.isinf(image) & (image < 0))
    if image_format == "png16":
        # Half a code step: the finite range over the data codes, over 2.
        step = (image[finite].max() - image[finite].min()) / (PNG_DATA_CODES - 1)
        assert entry["scale"] == pytest.approx(step)
        rounding = PNG16_DECODE_FLOAT32_RELATIVE * np.abs(image[finite])
        assert np.all(np.abs(back[finite] - image[finite]) <= 0.5 * step + rounding)
    else:
        assert np.array_equal(back[finite], image[finite])


def test_png16_codes_are_what_opencv_reads(tmp_path):
    """An independent reader (OpenCV) sees the documented codes, colour in RGB order on disk."""
    image = np.zeros((2, 3, 3), dtype=np.float32)
    image[0, 0] = (0.0, 1.0, 2.0)  # the range: offset 0, 2 over the data codes
    image[1, 2] = (np.nan, np.inf, 2.0)
    entry = write_image(tmp_path, "c", image, image_format="png16", role="ideal")
    codes = cv2.imread(str(tmp_path / "c.png"), cv2.IMREAD_UNCHANGED)
    assert codes.dtype == np.uint16
    rgb = codes[..., ::-1]  # OpenCV gives BGR
    assert entry["offset"] == 0.0
    assert tuple(rgb[0, 0]) == (0, round(1.0 / entry["scale"]), PNG_DATA_CODES - 1)
    assert tuple(rgb[1, 2]) == (PNG_SPECIAL_CODES["nan"], PNG_SPECIAL_CODES["+inf"], PNG_DATA_CODES - 1)


@pytest.mark.parametrize("image_format", IMAGE_FORMATS)
def test_integer_labels_round_trip_exactly(tmp_path, image_format):
    ids = np.random.default_rng(2).integers(0, 7, (5, 8)).astype(np.uint16)
    entry = write_image(tmp_path, "ids", ids, image_format=image_format, role="instance_id", no_value=0)
    back = read_image(tmp_path, entry)
    assert back.dtype == np.uint16
    assert np.array_equal(back, ids)
    assert entry["no_value"] == 0


def test_integers_wider_than_16_bits_are_written_as_npz_and_recorded(tmp_path):
    lens = np.arange(-1, 70_000, dtype=np.int32).reshape(1, -1)  # -1: no lens; an Illum has 234 000
    entry = write_image(tmp_path, "lens", lens, image_format="png16", role="lens_index", no_value=-1)
    assert (entry["format"], entry["file"], entry["png16_too_wide"]) == ("npz", "lens.npz", [-1, 69_999])
    assert np.array_equal(read_image(tmp_path, entry), lens)
    narrow = write_image(tmp_path, "narrow", lens[:, :1000], image_format="png16", role="lens_index", no_value=-1)
    assert narrow["format"] == "png16"
    assert np.array_equal(read_image(tmp_path, narrow), lens[:, :1000])


def test_entry_of_an_exr_written_by_the_render(tmp_path):
    write_exr(tmp_path / "raw.exr", np.ones((4, 5, 3), np.float32), role="raw")
    entry = exr_entry(tmp_path / "raw.exr", role="raw")
    assert entry == {"role": "raw", "dtype": "float32", "shape": [4, 5, 3], "file": "raw.exr", "format": "exr"}
    assert read_image(tmp_path, entry).shape == (4, 5, 3)


@pytest.mark.parametrize(
    ("image", "message"),
    [
        (np.zeros((3, 4), dtype=bool), "real numbers"),
        (np.zeros((3, 4, 2), dtype=np.float32), r"shape \(H, W\) or \(H, W, 3\)"),
        (np.full((2, 2), 2**24, dtype=np.int64), "2\\*\\*24"),
    ],
)
def test_bad_images_are_refused_and_nothing_is_written(tmp_path, image, message):
    with pytest.raises(ParameterError, match=message):
        write_image(tmp_path, "bad", image, image_format="npz", role="x")
    assert list(tmp_path.iterdir()) == []


def test_unknown_format_and_damaged_files(tmp_path):
    with pytest.raises(ParameterError, match="image_format"):
        write_image(tmp_path, "x", np.zeros((2, 2)), image_format="tiff", role="x")
    entry = write_image(tmp_path, "x", np.zeros((2, 2), np.float32), image_format="png16", role="x")
    (tmp_path / "x.png").write_bytes(b"not a png")
    with pytest.raises(FileFormatError, match="16-bit PNG"):
        read_image(tmp_path, entry)
    with pytest.raises(FileFormatError, match="shape"):
        read_image(
            tmp_path, write_image(tmp_path, "y", np.zeros((2, 2)), image_format="npz", role="y") | {"shape": [3]}
        )
