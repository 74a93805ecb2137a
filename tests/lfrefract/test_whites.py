"""White images for Lytro captures (lfrefract.formats.whites): finding, choosing, bad pixels, developing.

The white images are the camera model's (tests/lfrefract/test_calibration_mla.py draws them), turned
into 10-bit counts and written as the Illum ships its whites (.raw with a .txt of JSON).
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from scipy import ndimage

from lfrefract import cli as core_cli
from lfrefract.errors import FileFormatError, ParameterError
from lfrefract.formats.capture import read_capture
from lfrefract.formats.lytro import LytroSettings, write_f01_raw, write_illum_raw, write_lfr
from lfrefract.formats.mosaic import RawMosaic
from lfrefract.formats.whites import (
    FlatField,
    WhiteImage,
    bad_pixels,
    develop,
    find_white_images,
    flat_field,
    read_lytro_file,
    select_white_image,
    white_problem,
)
from tests.lfrefract.test_calibration_mla import small_camera, synthetic_white

BLACK, WHITE_LEVEL = 64, 1023


def white_mosaic(scale: float = 700.0, bits: int = 10, pattern: str = "GRBG") -> RawMosaic:
    counts = np.rint(BLACK + scale * synthetic_white(small_camera())).astype(np.uint16)
    top = 2**bits - 1
    return RawMosaic(counts=counts, cfa_pattern=pattern, black_level_dn=BLACK, white_level_dn=top, bit_depth=bits)


def write_white(folder, name, mosaic, *, zoom, focus):
    settings = LytroSettings(zoom_step=zoom, focus_step=focus)
    if mosaic.bit_depth == 12:
        return write_f01_raw(folder / f"{name}.raw", mosaic, small_camera(), settings=settings)[0]
    return write_illum_raw(folder / f"{name}.raw", mosaic, small_camera(), settings=settings)[0]


def test_a_folder_of_whites_is_listed_and_the_nearest_setting_chosen(tmp_path):
    for k, (zoom, focus) in enumerate([(6000, 0), (6000, 300), (9000, 0), (9000, 120)]):
        write_white(tmp_path, f"MOD_{k:04d}", white_mosaic(), zoom=zoom, focus=focus)
    (tmp_path / "notes.txt").write_text("not a white image")
    whites = find_white_images(tmp_path)
    assert [(w.path.name, w.zoom_step, w.focus_step) for w in whites] == [
        ("MOD_0000.raw", 6000, 0),
        ("MOD_0001.raw", 6000, 300),
        ("MOD_0002.raw", 9000, 0),
        ("MOD_0003.raw", 9000, 120),
    ]
    assert select_white_image(whites, zoom_step=8800, focus_step=10).path.name == "MOD_0002.raw"
    # Zoom decides first: MOD_0003 (focus 120, 80 steps off) at the farther zoom loses to MOD_0001 (100 off).
    assert select_white_image(whites, zoom_step=6100, focus_step=200).path.name == "MOD_0001.raw"
    assert select_white_image(whites, zoom_step=9000, focus_step=119).path.name == "MOD_0003.raw"


def test_lytro_files_are_told_apart_by_their_metadata(tmp_path):
    illum = write_white(tmp_path, "illum", white_mosaic(), zoom=1, focus=2)
    f01 = write_white(tmp_path, "f01", white_mosaic(scale=2800.0, bits=12, pattern="BGGR"), zoom=3, focus=4)
    lfr = write_lfr(tmp_path / "w.lfr", white_mosaic(), small_camera(), settings=LytroSettings(zoom_step=5))
    assert read_lytro_file(illum).mosaic.bit_depth == 10
    assert read_lytro_file(f01).mosaic.cfa_pattern == "BGGR"
    assert WhiteImage.from_file(lfr).zoom_step == 5
    assert WhiteImage.from_file(f01).focus_step == 4


def test_bad_paths_are_named(tmp_path):
    with pytest.raises(FileFormatError, match="no such folder"):
        find_white_images(tmp_path / "missing")
    with pytest.raises(FileFormatError, match="not a folder"):
        find_white_images(write_white(tmp_path, "white", white_mosaic(), zoom=0, focus=0))
    (tmp_path / "white.raw").unlink()
    with pytest.raises(FileFormatError, match=r"holds no \.raw"):
        find_white_images(tmp_path)
    (tmp_path / "lonely.raw").write_bytes(b"\0" * 16)
    with pytest.raises(FileFormatError, match="has no metadata beside it"):
        read_lytro_file(tmp_path / "lonely.raw")
    with pytest.raises(FileFormatError, match="no such file"):
        read_lytro_file(tmp_path / "none.lfr")
    with pytest.raises(ParameterError, match="at least one"):
        select_white_image([], zoom_step=0, focus_step=0)


def test_dead_and_hot_pixels_of_a_white_are_found_and_nothing_else():
    white = white_mosaic()
    camera = small_camera()
    centres = np.rint(camera.micro_image_centres_px(camera.lens_indices_on_sensor())).astype(int)
    inner = centres[(centres[:, 0] > 4) & (centres[:, 0] < 195) & (centres[:, 1] > 4) & (centres[:, 1] < 145)]
    pick = inner[np.random.default_rng(0).choice(len(inner), 12, replace=False)]
    counts = white.counts.copy()
    counts[pick[:6, 1], pick[:6, 0]] = BLACK  # dead: reads black
    counts[pick[6:, 1], pick[6:, 0]] = WHITE_LEVEL  # hot: stuck at the white level
    broken = RawMosaic(
        counts=counts, cfa_pattern="GRBG", black_level_dn=BLACK, white_level_dn=WHITE_LEVEL, bit_depth=10
    )
    assert not bad_pixels(white).any()
    found = bad_pixels(broken)
    assert found.sum() == 12
    assert found[pick[:, 1], pick[:, 0]].all()


def test_develop_devignettes_by_the_white_and_marks_what_it_cannot_trust():
    white = white_mosaic()
    # A capture of a grey scene of half the white's radiance through the same lens: half the white.
    lit = white.counts.astype(np.float64) - BLACK
    counts = np.rint(BLACK + 0.5 * lit).astype(np.uint16)
    counts[70, 100] = WHITE_LEVEL  # one saturated pixel
    capture = RawMosaic(
        counts=counts, cfa_pattern="GRBG", black_level_dn=BLACK, white_level_dn=WHITE_LEVEL, bit_depth=10
    )
    developed = develop(capture, white)
    assert developed.image.shape == (150, 200, 3)
    assert developed.saturated.sum() == 1
    assert developed.unrecorded[69:72, 99:102].all()
    assert np.isnan(developed.image[70, 100]).all()
    # Inside the micro-images (the 3 x 3 neighbourhood that bilinear demosaicing mixes all lit) every
    # colour reads 0.5, the 1-DN rounding of the counts aside.
    core = ndimage.minimum_filter(lit, size=3) > 0.5 * lit.max()
    bright = np.isfinite(developed.image[..., 1]) & core
    np.testing.assert_allclose(developed.image[bright], 0.5, atol=0.01)
    # Without a white only the black level and the white level scale it: the micro-images' edges stay.
    plain = develop(capture)
    assert np.nanmax(plain.image) < 0.5
    assert np.nanstd(plain.image[bright]) > 10 * np.nanstd(developed.image[bright])
    with pytest.raises(ParameterError, match="does not match the capture"):
        develop(capture, white_mosaic(pattern="RGGB"))


def test_a_flat_field_develops_as_its_white_does():
    white_counts = white_mosaic().counts.copy()
    white_counts[40, 60] = WHITE_LEVEL  # a hot pixel of the white
    white = RawMosaic(
        counts=white_counts, cfa_pattern="GRBG", black_level_dn=BLACK, white_level_dn=WHITE_LEVEL, bit_depth=10
    )
    counts = np.rint(BLACK + 0.3 * (white_counts.astype(np.float64) - BLACK)).astype(np.uint16)
    capture = RawMosaic(
        counts=counts, cfa_pattern="GRBG", black_level_dn=BLACK, white_level_dn=WHITE_LEVEL, bit_depth=10
    )
    field = flat_field(white)
    assert isinstance(field, FlatField)
    assert field.shape == (150, 200)
    assert field.bad[40, 60]
    assert not field.lit_dn.flags.writeable  # shared by every capture it develops
    by_white, by_field = develop(capture, white), develop(capture, field)
    for name in ("image", "values", "bad", "lit", "unrecorded"):
        np.testing.assert_array_equal(getattr(by_field, name), getattr(by_white, name), err_msg=name)
    other = RawMosaic(counts=counts, cfa_pattern="RGGB", black_level_dn=BLACK, white_level_dn=WHITE_LEVEL, bit_depth=10)
    with pytest.raises(ParameterError, match="does not match the capture"):
        develop(other, field)
    with pytest.raises(ParameterError, match="white must be a RawMosaic or a FlatField"):
        develop(capture, white.counts)


def test_a_white_file_is_prepared_once_and_again_when_it_changes(tmp_path):
    path = write_white(tmp_path, "white", white_mosaic(), zoom=1, focus=2)
    white = WhiteImage.from_file(path)
    first = white.flat_field()
    assert white.flat_field() is first  # the next capture of a command reuses it
    np.testing.assert_array_equal(first.lit_dn, white_mosaic().counts.astype(np.float32) - BLACK)
    # Another white written to the same path (other size: a cache keyed on the path alone would keep the old one).
    write_white(tmp_path, "white", white_mosaic(scale=350.0, bits=12, pattern="BGGR"), zoom=1, focus=2)
    again = WhiteImage.from_file(path).flat_field()
    assert again is not first
    assert again.cfa_pattern == "BGGR"
    np.testing.assert_array_equal(again.lit_dn, white_mosaic(scale=350.0).counts.astype(np.float32) - BLACK)


def test_a_same_size_white_copied_in_with_the_same_mtime_is_prepared_again(tmp_path):
    """Whites of one camera are all of one size: another one copied over the file with ``cp -p`` from a file of
    its modification time must not be developed with the flat field remembered for the first."""
    import os
    import subprocess
    import time

    path = write_white(tmp_path, "white", white_mosaic(), zoom=1, focus=2)
    first = WhiteImage.from_file(path).flat_field()
    (tmp_path / "other").mkdir()
    other = write_white(tmp_path / "other", "white", white_mosaic(scale=350.0), zoom=1, focus=2)
    stat = path.stat()
    assert other.stat().st_size == stat.st_size
    os.utime(other, ns=(stat.st_atime_ns, stat.st_mtime_ns))
    time.sleep(0.05)  # past the kernel's coarse clock tick (a few ms) of the file's last change
    subprocess.run(["cp", "-p", str(other), str(path)], check=True)
    assert (path.stat().st_size, path.stat().st_mtime_ns) == (stat.st_size, stat.st_mtime_ns)
    again = WhiteImage.from_file(path).flat_field()
    assert again is not first
    np.testing.assert_array_equal(again.lit_dn, white_mosaic(scale=350.0).counts.astype(np.float32) - BLACK)


def test_read_capture_takes_lytro_files_and_their_white(tmp_path):
    camera = small_camera()
    white_path = write_white(tmp_path, "white", white_mosaic(), zoom=6000, focus=0)
    lit = white_mosaic().counts.astype(np.float64) - BLACK
    counts = np.rint(BLACK + 0.25 * lit).astype(np.uint16)
    capture_mosaic = RawMosaic(
        counts=counts, cfa_pattern="GRBG", black_level_dn=BLACK, white_level_dn=WHITE_LEVEL, bit_depth=10
    )
    path = write_lfr(tmp_path / "capture.lfr", capture_mosaic, camera, settings=LytroSettings(zoom_step=6000))
    capture = read_capture(path, white=tmp_path)
    assert capture.camera == camera
    assert capture.raw.shape == (150, 200, 3)
    assert capture.sidecar["lytro"]["white"]["file"] == str(white_path)
    assert capture.sidecar_path is None
    # What the white does not light records nothing: a synthesis gives it no weight (nothing here is
    # saturated or bad, so that is all that is unrecorded).
    np.testing.assert_array_equal(capture.recorded, capture.developed.lit)
    assert (~capture.developed.lit).any()
    # A board command reads what the white does not light as unrecorded, not as black: at the
    # field's edge the main lens vignettes parts of micro-images, which the light-field corner fit
    # took for black squares (an Illum in-air board 17.5 deg off the axis: 9 of 24 corners located).
    # The pixels the white lights in part (a micro-image's rim here) are unrecorded too.
    developed = capture.developed
    lit = developed.fully_lit
    assert (~lit).any()
    assert (developed.lit & ~lit).any()
    for command in ("camera", "port", "approx"):
        for colour in ("demosaic", "cfa"):
            board = core_cli._board_raw(str(path), camera, str(tmp_path), colour, command=command)
            assert np.isnan(board[~lit]).all()
            assert np.isfinite(board[lit]).all()
    # With no --colour: calibrate port reads the grey mosaic, calibrate approx the demosaiced image.
    np.testing.assert_array_equal(
        core_cli._board_raw(str(path), camera, str(tmp_path), None, command="port"), developed.grey()
    )
    assert core_cli._board_raw(str(path), camera, str(tmp_path), None, command="approx").ndim == 3
    with pytest.raises(ParameterError, match="is a linear raw image already"):
        read_capture(tmp_path / "raw.exr", white=white_path)


def test_the_grey_mosaic_of_a_neutral_scene_agrees_across_colours_under_coloured_light():
    white = white_mosaic()
    lit = white.counts.astype(np.float64) - BLACK
    channels = white.channel_index()
    # A black and white pattern (one neutral reflectance per pixel) under light of another colour
    # than the white's: R, G and B reach the sensor at 0.7, 0.5 and 0.3 of the white image's.
    rng = np.random.default_rng(3)
    reflectance = np.where(rng.random(lit.shape) < 0.5, 0.1, 0.9)
    counts = np.rint(BLACK + np.array([0.7, 0.5, 0.3])[channels] * reflectance * lit).astype(np.uint16)
    capture = RawMosaic(
        counts=counts, cfa_pattern="GRBG", black_level_dn=BLACK, white_level_dn=WHITE_LEVEL, bit_depth=10
    )
    developed = develop(capture, white)
    grey = developed.grey()
    assert grey.shape == lit.shape
    assert grey.dtype == np.float32
    assert np.array_equal(np.isnan(grey), ~developed.fully_lit | developed.flagged)
    bright = ~np.isnan(grey) & (lit > 0.5 * lit.max())  # away from the 1-DN rounding of dim pixels
    # Each colour divided by its bright level (the 0.9 squares): the reflectance over 0.9, whatever the colour.
    np.testing.assert_allclose(grey[bright], reflectance[bright] / 0.9, atol=0.02)
    # The demosaiced image keeps the light's colour, and mixes the pattern's neighbours.
    assert abs(np.nanmean(developed.image[..., 0]) / np.nanmean(developed.image[..., 2]) - 0.7 / 0.3) < 0.2


def test_pixels_a_stop_vignettes_in_part_are_lit_but_not_fully_lit():
    """A vignetting edge across the field (a lens barrel's): the column on the edge keeps 40 % of its
    light, those beyond none. Its pixels can be devignetted but their rays are not the model's, so a
    fit on every raw pixel must not take them; a hot pixel marks none of its neighbours."""
    white = white_mosaic()
    whole = flat_field(white)
    lit = white.counts.astype(np.float64) - BLACK
    profile = np.ones(lit.shape[1])
    profile[100], profile[101:] = 0.4, 0.0
    counts = np.rint(BLACK + lit * profile).astype(np.uint16)
    counts[60, 40] = WHITE_LEVEL  # a hot pixel inside the lit field
    edge = flat_field(
        RawMosaic(counts=counts, cfa_pattern="GRBG", black_level_dn=BLACK, white_level_dn=WHITE_LEVEL, bit_depth=10)
    )
    on_edge = whole.fully_lit[:, 100] & edge.usable[:, 100]
    assert on_edge.sum() > 20  # lit enough to devignet ...
    assert not edge.fully_lit[:, 100][on_edge].any()  # ... but not fully
    assert edge.bad[60, 40]
    np.testing.assert_array_equal(edge.fully_lit[:, :95], whole.fully_lit[:, :95] & ~edge.bad[:, :95])
    assert not edge.fully_lit[:, 101:].any()
    capture = RawMosaic(
        counts=np.rint(BLACK + 0.3 * lit).astype(np.uint16),
        cfa_pattern="GRBG",
        black_level_dn=BLACK,
        white_level_dn=WHITE_LEVEL,
        bit_depth=10,
    )
    developed = develop(capture, edge)
    assert np.isfinite(developed.image[:, 100][on_edge]).all()  # a synthesis still has their values
    assert np.isnan(developed.grey()[:, 100][on_edge]).all()
    assert np.isnan(developed.measured()[:, 100][on_edge]).all()


def lytro_capture(tmp_path, fraction: float = 0.25, *, zoom: int = 6000, focus: int = 0):
    """A capture of a uniform scene at ``fraction`` of the white's light, as an LFR file."""
    lit = white_mosaic().counts.astype(np.float64) - BLACK
    counts = np.rint(BLACK + fraction * lit).astype(np.uint16)
    mosaic = RawMosaic(
        counts=counts, cfa_pattern="GRBG", black_level_dn=BLACK, white_level_dn=WHITE_LEVEL, bit_depth=10
    )
    return write_lfr(
        tmp_path / "capture.lfr", mosaic, small_camera(), settings=LytroSettings(zoom_step=zoom, focus_step=focus)
    )


def test_a_symlink_loop_is_named_wherever_a_lytro_path_is_taken(tmp_path, capsys):
    capture = lytro_capture(tmp_path)
    (tmp_path / "whites").mkdir()
    write_white(tmp_path / "whites", "white", white_mosaic(), zoom=6000, focus=0)
    for name in ("loop", "loop.raw", "loop.lfr"):
        (tmp_path / name).symlink_to(name)
    for white in ("loop", "loop.raw", "loop.lfr"):
        with pytest.raises(FileFormatError, match=rf"{white}'.* symbolic link loop"):
            read_capture(capture, white=tmp_path / white)
    with pytest.raises(FileFormatError, match=r"loop.lfr'.* symbolic link loop"):
        read_capture(tmp_path / "loop.lfr")
    with pytest.raises(FileFormatError, match=r"loop.raw'.* symbolic link loop"):
        read_lytro_file(tmp_path / "loop.raw")
    with pytest.raises(FileFormatError, match=r"loop'.* symbolic link loop"):
        find_white_images(tmp_path / "loop")
    # A loop among the white images is named, not skipped.
    (tmp_path / "whites" / "other.raw").symlink_to("other.raw")
    with pytest.raises(FileFormatError, match=r"other.raw'.* symbolic link loop"):
        find_white_images(tmp_path / "whites")
    port = tmp_path / "port.toml"
    port.write_text("[port]\nnormal = [0.0, 0.0, 1.0]\ndistance_m = 0.05\n")
    out = tmp_path / "o.exr"
    loop = str(tmp_path / "loop")
    status = core_cli.main(["synth", str(capture), "--white", loop, "--port", str(port), "--out", str(out)])
    err = capsys.readouterr().err
    assert status == 2
    assert err.count("\n") == 1
    assert "symbolic link loop" in err
    assert loop in err
    assert not (tmp_path / "o.exr").exists()


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (lambda color: color.update(ccm=[0.0] * 9), r"image.color.ccm.*singular"),
        (lambda color: color.update(ccm="identity"), r"image.color.ccm.*9 numbers"),
        (lambda color: color["whiteBalanceGain"].pop("gb"), r"whiteBalanceGain' has no 'gb'"),
        (lambda color: color.update(whiteBalanceGain={"r": 1, "gr": 1, "gb": 1, "b": "x"}), r"whiteBalanceGain.b"),
    ],
)
def test_a_capture_with_a_malformed_colour_is_refused_not_developed_with_identity(tmp_path, edit, match):
    """An all-zero ccm gave an all-black image; a malformed ccm or gain was replaced by identity / 1."""
    path = write_white(tmp_path, "capture", white_mosaic(scale=200.0), zoom=0, focus=0)
    meta_path = path.with_suffix(".txt")
    meta = json.loads(meta_path.read_text())
    edit(meta["image"]["color"])
    meta_path.write_text(json.dumps(meta))
    with pytest.raises(FileFormatError, match=match):
        read_capture(path)


def test_develop_names_a_colour_matrix_that_is_not_finite():
    with pytest.raises(ParameterError, match=r"color_matrix must hold finite numbers.*nan"):
        develop(white_mosaic(), color_matrix=np.where(np.eye(3) > 0, np.nan, 0.0))


def test_malformed_lens_steps_are_named(tmp_path):
    path = write_white(tmp_path, "capture", white_mosaic(scale=200.0), zoom=0, focus=0)
    meta_path = path.with_suffix(".txt")
    meta = json.loads(meta_path.read_text())
    meta["devices"]["lens"]["zoomStep"] = "6000"
    meta_path.write_text(json.dumps(meta))
    with pytest.raises(FileFormatError, match=r"devices.lens.zoomStep' must be an integer, got '6000'"):
        read_capture(path)


def board_mosaic(square_px: int = 25) -> RawMosaic:
    """A board capture through the small camera: squares of 0.1 and 1 of the white's light (3 micro-images a side)."""
    lit = white_mosaic().counts.astype(np.float64) - BLACK
    rows, cols = np.mgrid[: lit.shape[0], : lit.shape[1]]
    board = np.where(((rows // square_px) + (cols // square_px)) % 2, 0.1, 1.0)
    counts = np.rint(BLACK + board * lit).astype(np.uint16)
    return RawMosaic(counts=counts, cfa_pattern="GRBG", black_level_dn=BLACK, white_level_dn=WHITE_LEVEL, bit_depth=10)


def test_a_capture_in_the_white_folder_is_passed_over_and_the_white_used_is_said(tmp_path, capsys):
    """A board capture at the capture's lens steps, sorting first, was taken as the white (mean 0.81, not 0.15)."""
    capture = lytro_capture(tmp_path, 0.15)
    whites = tmp_path / "whites"
    whites.mkdir()
    board = write_white(whites, "0000-board", board_mosaic(), zoom=6000, focus=0)
    white = write_white(whites, "white", white_mosaic(), zoom=6000, focus=0)
    developed = read_capture(capture, white=whites)
    used = developed.sidecar["lytro"]["white"]
    assert used["file"] == str(white)
    assert [item["file"] for item in used["passed_over"]] == [str(board)]
    assert "not uniform" in used["passed_over"][0]["reason"]
    inside = developed.developed.fully_lit
    np.testing.assert_allclose(np.nanmean(developed.raw[inside]), 0.15, rtol=0.05)
    # The command says which white it used, and which it passed over.
    assert core_cli.main(["naive", str(capture), "--white", str(whites), "--out", str(tmp_path / "n.exr")]) == 0
    err = capsys.readouterr().err
    assert f"white image {white} (zoom step 6000, focus step 0; the capture's 6000, 0;" in err
    assert f"white {board} not used: it is no white image: its light is not uniform" in err
    # Alone, the board is refused.
    (whites / "white.raw").unlink()
    with pytest.raises(FileFormatError, match=r"holds no white image for this capture: .*0000-board.raw.*not uniform"):
        read_capture(capture, white=whites)
    with pytest.raises(FileFormatError, match=r"0000-board.raw' is no white image: its light is not uniform"):
        read_capture(capture, white=board)


def _filled(level: int) -> RawMosaic:
    counts = np.full(white_mosaic().shape, level, dtype=np.uint16)
    return RawMosaic(counts=counts, cfa_pattern="GRBG", black_level_dn=BLACK, white_level_dn=WHITE_LEVEL, bit_depth=10)


@pytest.mark.parametrize(
    ("mosaic", "match"),
    [
        (_filled(BLACK), r"w.raw' is no white image: it holds no light"),  # it blamed the capture
        (_filled(WHITE_LEVEL), r"w.raw' is no white image: 100.0 % of its pixels are saturated"),  # all NaN, exit 0
        (_filled(300), r"w.raw' is no white image: it shows no micro-images"),
    ],
)
def test_a_white_file_that_is_no_white_image_is_refused_naming_it(tmp_path, mosaic, match):
    capture = lytro_capture(tmp_path)
    white = write_white(tmp_path, "w", mosaic, zoom=6000, focus=0)
    with pytest.raises(FileFormatError, match=match):
        read_capture(capture, white=white)


def test_a_white_whose_micro_images_lie_elsewhere_is_refused_and_far_steps_are_said(tmp_path, capsys):
    capture = lytro_capture(tmp_path)
    camera = small_camera()
    # Another focus: the exit pupil (the thin lens) nearer the MLA moves the outer micro-images by 1.7 px.
    other = dataclasses.replace(camera, lens_to_mla_m=4e-3, f_number=3.0)
    far = write_illum_raw(
        tmp_path / "far.raw", white_mosaic(), other, settings=LytroSettings(zoom_step=6000, focus_step=900)
    )[0]
    with pytest.raises(
        FileFormatError, match=r"far.raw' does not fit the capture: .* up to 1.\d\d px .*focus step 900"
    ):
        read_capture(capture, white=far)
    # The same optics at a zoom step far from the capture's: taken (its micro-images are the capture's), and said.
    steps = write_white(tmp_path, "steps", white_mosaic(), zoom=99999, focus=0)
    assert core_cli.main(["naive", str(capture), "--white", str(steps), "--out", str(tmp_path / "n.exr")]) == 0
    err = capsys.readouterr().err
    assert "(zoom step 99999, focus step 0; the capture's 6000, 0; its micro-image centres within 0.00 px" in err


def test_an_exr_given_as_the_white_is_told_what_a_white_is(tmp_path):
    """A render's raw.exr with its meta.json beside it was asked for a .json/.txt."""
    capture = lytro_capture(tmp_path)
    (tmp_path / "white").mkdir()
    (tmp_path / "white" / "raw.exr").write_bytes(b"\0" * 64)
    (tmp_path / "white" / "meta.json").write_text("{}")
    with pytest.raises(FileFormatError, match=r"raw.exr' is no Lytro file: a white image is a .raw with its .json"):
        read_capture(capture, white=tmp_path / "white" / "raw.exr")


@pytest.mark.parametrize(("recorded", "colour", "warned"), [("demosaic", None, True), ("demosaic", "demosaic", False)])
def test_calibrate_port_warns_of_boards_read_otherwise_than_its_camera_calibration_read_its_own(
    tmp_path, capsys, recorded, colour, warned
):
    """A polynomial ray model fitted to in-air corners read from the demosaiced image does not fit
    underwater corners read from the grey mosaic (on double-Gauss renders the port absorbed the
    difference: 0.75 deg off against 0.02 deg read alike): ``calibrate port`` says so at its first
    board, naming the camera file's reading and its own."""
    from lfrefract.formats.jsonio import write_json
    from lfrefract.optics.ray_correction import PolynomialCorrection, polynomial_exponents

    capture = lytro_capture(tmp_path, 0.5)
    (tmp_path / "other").mkdir()
    other = lytro_capture(tmp_path / "other", 0.3)
    whites = tmp_path / "whites"
    whites.mkdir()
    write_white(whites, "white", white_mosaic(), zoom=6000, focus=0)
    camera_file = tmp_path / "camera.json"
    data = {
        "kind": "lfrefract.calibrate.camera",
        "camera": small_camera().to_dict(),
        "correction": PolynomialCorrection(
            degree=3,
            aperture_degree=3,
            aperture_norm_m=1e-3,
            slope_norm=0.3,
            coefficients=np.zeros((len(polynomial_exponents(3, 3)), 4)),
        ).to_dict(),
        "board_colour": recorded,
    }
    write_json(camera_file, data)
    out = tmp_path / "port.json"
    argv = ["calibrate", "port", str(capture), str(other), "--camera", str(camera_file), "--white", str(whites)]
    argv += ["--squares", "7", "5", "--square-size-m", "0.01", "--thickness-m", "0.004", "--n-glass", "1.5"]
    argv += ["--n-water", "1.333", "--out", str(out), *(["--colour", colour] if colour else [])]
    assert core_cli.main(argv) == 2  # a uniform grey: no board located
    err = capsys.readouterr().err
    assert "the board was located in 0 of 2 captures" in err
    assert not out.exists()
    said = (
        f"{camera_file}'s ray model was fitted to board captures read as 'demosaic', these are read as 'cfa' by default"
    )
    assert (said in err) == warned
    assert err.count("warning:") == int(warned)  # once, at the first board
    # A camera file that does not say how its boards were read: said too.
    del data["board_colour"]
    write_json(camera_file, data)
    assert core_cli.main(argv) == 2
    err = capsys.readouterr().err
    assert f"warning: {camera_file} does not say how its board captures were read" in err


def _shaded(shade) -> RawMosaic:
    """The drawn white times ``shade(rows, cols)`` (its light's fraction at each pixel)."""
    lit = white_mosaic().counts.astype(np.float64) - BLACK
    rows, cols = np.mgrid[: lit.shape[0], : lit.shape[1]].astype(np.float64)
    counts = np.rint(BLACK + shade(rows, cols) * lit).astype(np.uint16)
    return RawMosaic(counts=counts, cfa_pattern="GRBG", black_level_dn=BLACK, white_level_dn=WHITE_LEVEL, bit_depth=10)


def test_a_white_through_a_lens_whose_image_circle_is_smaller_than_the_sensor_is_one():
    """A Petzval and a near-telecentric design at tiny-2x light a disk of the sensor whose edge falls off
    within one or two micro-images: their whites were refused as not uniform (23 % and 26 % of the lit
    field under half a micro-image within 1.5 pitches, 20 % allowed), so the data-only chain could not
    start. The rule now compares a micro-image with those at its distance from the light's centre."""
    camera = small_camera()
    height, width = white_mosaic().shape
    pitch = camera.micro_image_pitch_px
    centre = (0.5 * height + 0.7 * pitch, 0.5 * width - 0.4 * pitch)  # the axis a little off the sensor's centre
    radius = 0.42 * min(height, width)

    def image_circle(rows, cols):
        r = np.hypot(rows - centre[0], cols - centre[1])
        return np.clip((radius - r) / (1.5 * pitch), 0.0, 1.0) * (1.0 - 0.3 * (r / radius) ** 2)

    mosaic = _shaded(image_circle)
    assert white_problem(mosaic, flat_field(mosaic), micro_image_pitch_px=pitch) is None


def test_a_capture_of_a_low_contrast_scene_is_no_white():
    """A textured plane through the tiny camera read as a white (18 % of its lit field uneven, 20 %
    allowed): a capture in the white folder would have been taken as the white, and every capture
    devignetted by the scene's texture. Its texture is not rotationally symmetric about the light's
    centre, a lens's fall-off is."""
    camera = small_camera()
    pitch = camera.micro_image_pitch_px

    def texture(rows, cols):
        return 0.775 + 0.225 * np.sin(rows / (2.3 * pitch)) * np.cos(cols / (3.1 * pitch))  # 0.55-1

    mosaic = _shaded(texture)
    problem = white_problem(mosaic, flat_field(mosaic), micro_image_pitch_px=pitch)
    assert problem is not None
    assert "not uniform" in problem, problem
