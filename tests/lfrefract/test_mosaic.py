"""The one mosaic type (lfrefract.formats.mosaic): levels, channels and the mosaic.npz file."""

from __future__ import annotations

import numpy as np
import pytest

from lfrefract.errors import FileFormatError, ParameterError
from lfrefract.formats.mosaic import CFA_PATTERNS, RawMosaic, cfa_channels, read_mosaic_npz, write_mosaic_npz


def a_mosaic(pattern: str = "GRBG") -> RawMosaic:
    counts = np.random.default_rng(3).integers(0, 1024, size=(6, 8))
    return RawMosaic(counts=counts, cfa_pattern=pattern, black_level_dn=64, white_level_dn=1000, bit_depth=10)


def test_levels_scale_the_counts_two_ways():
    mosaic = a_mosaic()
    assert np.array_equal(mosaic.normalised(), (mosaic.counts - 64.0) / 936.0)
    assert np.array_equal(mosaic.full_scale(), mosaic.counts / 1023.0)
    assert np.array_equal(mosaic.saturated, mosaic.counts >= 1000)
    assert not mosaic.counts.flags.writeable


@pytest.mark.parametrize("pattern", CFA_PATTERNS)
def test_channels_follow_the_pattern_letters(pattern):
    channels = cfa_channels(pattern, (3, 5))
    for k, letter in enumerate(pattern):
        row, col = divmod(k, 2)
        assert np.all(channels[row::2, col::2] == "RGB".index(letter))


@pytest.mark.parametrize("pattern", CFA_PATTERNS)
def test_npz_round_trip_is_exact(tmp_path, pattern):
    mosaic = a_mosaic(pattern)
    path = write_mosaic_npz(tmp_path / "mosaic.npz", mosaic)
    back = read_mosaic_npz(path)
    assert np.array_equal(back.counts, mosaic.counts)
    assert back.counts.dtype == np.uint16
    assert (back.cfa_pattern, back.black_level_dn, back.white_level_dn, back.bit_depth) == (pattern, 64, 1000, 10)
    with np.load(path) as plain:  # numpy alone reads it
        assert str(plain["cfa_pattern"]) == pattern


def test_bad_npz_files_are_named(tmp_path):
    with pytest.raises(FileFormatError, match="no such file"):
        read_mosaic_npz(tmp_path / "missing.npz")
    (tmp_path / "text.npz").write_text("not a zip")
    with pytest.raises(FileFormatError, match=r"text\.npz"):
        read_mosaic_npz(tmp_path / "text.npz")
    np.savez(tmp_path / "other.npz", counts=np.zeros((2, 2), np.uint16))
    with pytest.raises(FileFormatError, match="lacks"):
        read_mosaic_npz(tmp_path / "other.npz")
    values = dict(counts=np.full((2, 2), 2000, np.uint16), cfa_pattern=np.array("GRBG"))
    values |= dict(black_level_dn=np.array(0), white_level_dn=np.array(1023), bit_depth=np.array(10))
    np.savez(tmp_path / "range.npz", **values)
    with pytest.raises(FileFormatError, match=r"range\.npz.*\[0, 1023\]"):
        read_mosaic_npz(tmp_path / "range.npz")


def test_writer_refuses_what_is_no_mosaic(tmp_path):
    with pytest.raises(ParameterError, match="RawMosaic"):
        write_mosaic_npz(tmp_path / "m.npz", np.zeros((2, 2), np.uint16))
    assert not (tmp_path / "m.npz").exists()
