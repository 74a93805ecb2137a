"""The camera model (:class:`lfrefract.optics.camera_model.CameraModel`): one value for a camera, its
ray model and that model's uncertainty, validated once, and read from a ``--camera`` value once."""

from __future__ import annotations

import re

import numpy as np
import pytest

from lfrefract import ParameterError, camera_preset
from lfrefract.calibration.uncertainty import spread_factors
from lfrefract.errors import FileFormatError
from lfrefract.formats import paramfile
from lfrefract.formats.capture import camera_model_from_option
from lfrefract.formats.jsonio import read_json, write_json
from lfrefract.optics.camera_model import CameraModel, as_camera_model
from lfrefract.optics.ray_correction import (
    PARAMETERS,
    CorrectionEstimate,
    PolynomialCorrection,
    RayCorrection,
    moved,
    polynomial_exponents,
)

TINY = camera_preset("tiny")
CORRECTION = RayCorrection(pupil_scale=0.99, k1=0.02, pupil_drift_m=1e-4)
COVARIANCE = np.diag([1e-6, 4e-6, 1e-4, 4e-4, 1e-8])
SPREAD = spread_factors(COVARIANCE)


def _calibration(path, **changes):
    """A camera calibration file (``lfrefract calibrate camera`` output) of the tiny camera."""
    estimate = CorrectionEstimate(correction=CORRECTION, covariance=COVARIANCE)
    data = {
        "kind": "lfrefract.calibrate.camera",
        "camera": TINY.to_dict(),
        "correction": CORRECTION.to_dict(),
        "correction_covariance": estimate.covariance_to_dict(),
        "correction_spread": {"rows": SPREAD.tolist(), "meaning": "directions"},
        **changes,
    }
    write_json(path, data)
    return path


def test_a_thin_lens_preset_has_no_correction_and_no_uncertainty():
    model = camera_model_from_option("tiny")
    assert model.camera == TINY
    assert model.correction is None
    assert model.ray_model == "thin-lens"
    assert model.covariance is None
    assert model.spread.shape == (0, 0)
    assert model.spread_corrections() == ()
    assert model.source == "tiny"
    assert model.main_lens is None
    with pytest.raises(ParameterError, match=re.escape("the camera model of 'tiny' is not a camera calibration")):
        model.estimate()


def test_a_calibration_files_model_round_trips(tmp_path):
    path = _calibration(tmp_path / "camera.json")
    model = camera_model_from_option(path)
    assert model.camera == TINY
    assert model.correction == CORRECTION
    assert model.ray_model == "radial"
    assert model.source == str(path)
    # JSON keeps every float64 bit: the covariance and the spread come back exactly.
    assert np.array_equal(model.covariance, COVARIANCE)
    assert np.array_equal(model.spread, SPREAD)
    assert model.estimate().correction == CORRECTION
    assert np.array_equal(model.estimate().covariance, COVARIANCE)
    # Each spread direction moves the correction as the port calibration's model_views did.
    for row, along in zip(SPREAD, model.spread_corrections(), strict=True):
        assert along == moved(CORRECTION, row)
    # The model's rays are the correction applied to the thin lens's.
    uv = np.array([[10.0, 12.0], [40.0, 30.0]])
    expected = CORRECTION.corrected(TINY.captured_rays(uv))
    np.testing.assert_array_equal(model.captured_rays(uv).directions_cam, expected.directions_cam)


def test_a_calibration_file_is_read_once(tmp_path, monkeypatch):
    path = _calibration(tmp_path / "camera.json")
    reads: list[str] = []
    real = paramfile.read_json

    def counting(file, *args, **kwargs):
        reads.append(str(file))
        return real(file, *args, **kwargs)

    monkeypatch.setattr(paramfile, "read_json", counting)  # the one JSON reader of parameter files
    model = camera_model_from_option(path)
    assert reads == [str(path)]
    assert model.correction == CORRECTION


def test_a_renders_meta_json_gives_its_recorded_lens_or_names_what_is_wrong_with_it(tmp_path):
    path = tmp_path / "meta.json"
    write_json(path, {"kind": "lfsim.render", "camera": TINY.to_dict(), "scene": {"lens": "thin"}})
    model = camera_model_from_option(path)
    assert (model.camera, model.correction, model.main_lens) == (TINY, None, None)
    # a lens table that is no prescription (a name alone) is not silently the thin lens
    write_json(path, {"kind": "lfsim.render", "camera": TINY.to_dict(), "scene": {"lens": {"name": "double-gauss"}}})
    with pytest.raises(FileFormatError, match=r"scene\.lens is no valid lens prescription"):
        camera_model_from_option(path)
    # the derived summary alone (no scene.lens) names the lens, for the refusal of a thin-lens model
    write_json(path, {"kind": "lfsim.render", "camera": TINY.to_dict(), "derived": {"main_lens": {"name": "dg"}}})
    assert camera_model_from_option(path).main_lens == "dg"


def test_a_polynomial_model_has_its_spread_but_no_radial_estimate(tmp_path):
    exponents = polynomial_exponents(2, 1)
    correction = PolynomialCorrection(
        degree=2, aperture_degree=1, aperture_norm_m=1e-3, slope_norm=0.3, coefficients=np.zeros((len(exponents), 4))
    )
    n = correction.vector().size
    path = tmp_path / "camera.json"
    write_json(
        path,
        {
            "kind": "lfrefract.calibrate.camera",
            "camera": TINY.to_dict(),
            "correction": correction.to_dict(),
            "correction_spread": {"rows": np.eye(n)[:2].tolist()},
        },
    )
    model = camera_model_from_option(path)
    assert model.ray_model == "polynomial"
    assert model.covariance is None
    assert model.spread.shape == (2, n)
    with pytest.raises(ParameterError, match="radial model only"):
        model.estimate()


def test_a_calibration_without_a_spread_has_none(tmp_path):
    path = _calibration(tmp_path / "camera.json")
    data = read_json(path)
    del data["correction_spread"], data["schema_version"]
    write_json(path, data)
    assert camera_model_from_option(path).spread.shape == (0, len(PARAMETERS))


@pytest.mark.parametrize(
    ("spread", "says"),
    [
        ([[1.0, 2.0]], "correction_spread.rows must be rows of 5 numbers"),
        ([[1.0, 2.0, 3.0, 4.0, "x"]], "correction_spread.rows must hold numbers only"),
        ([[1.0, 2.0, 3.0, 4.0, float("inf")]], "correction_spread.rows must be finite"),
    ],
)
def test_a_bad_spread_in_a_file_names_the_file_and_the_key(tmp_path, spread, says):
    path = _calibration(tmp_path / "camera.json", correction_spread={"rows": spread})
    with pytest.raises(ValueError, match=re.escape(f"{str(path)!r}: {says}")):
        camera_model_from_option(path)


@pytest.mark.parametrize(
    ("fields", "says"),
    [
        ({"camera": "tiny"}, "camera must be a LightFieldCamera, got str"),
        (
            {"correction": {"k1": 0.1}},
            "correction must be a RayCorrection, a PolynomialCorrection, a TracedLens or None",
        ),
        ({"covariance": np.eye(5)}, "covariance is that of the radial model's parameters, but the ray model is thin"),
        ({"correction": CORRECTION, "covariance": np.eye(4)}, "covariance must be a finite 5 x 5 matrix, got shape"),
        ({"correction": CORRECTION, "covariance": -np.eye(5)}, "covariance must be positive definite"),
        ({"correction": CORRECTION, "spread": np.ones((2, 4))}, "spread must be rows of 5 finite numbers"),
        ({"correction": CORRECTION, "spread": [[np.nan] * 5]}, "spread must be rows of 5 finite numbers"),
        ({"spread": np.ones((1, 5))}, "spread must be rows of 0 finite numbers (the thin-lens model's"),
        ({"correction": CORRECTION, "spread": [["a"] * 5]}, "spread must be rows of 5 numbers, got"),
        ({"source": 3}, "source must be a string or None, got 3"),
        ({"main_lens": b"x"}, "main_lens must be a string or None"),
    ],
)
def test_validation_names_the_field_and_the_value(fields, says):
    with pytest.raises(ParameterError, match=re.escape(says)):
        CameraModel(**{"camera": TINY, **fields})


def test_a_model_is_read_only_and_changes_by_copy():
    model = CameraModel(camera=TINY, correction=CORRECTION, covariance=COVARIANCE, spread=SPREAD)
    with pytest.raises(ValueError, match="read-only"):
        model.spread[0, 0] = 1.0
    with pytest.raises(ValueError, match="read-only"):
        model.covariance[0, 0] = 1.0
    thin = model.with_correction(None)
    assert (thin.ray_model, thin.covariance, thin.spread.shape) == ("thin-lens", None, (0, 0))
    other = camera_preset("tiny-2x")
    assert model.with_camera(other).camera == other
    assert model.with_camera(other).correction == CORRECTION
    assert as_camera_model(model) is model
    assert as_camera_model(TINY).ray_model == "thin-lens"
    with pytest.raises(ParameterError, match="camera must be a LightFieldCamera or a CameraModel, got str"):
        as_camera_model("tiny")


def test_a_calibrations_board_reading_is_read_and_checked(tmp_path):
    """How a calibration's Lytro boards were read travels with its model (``calibrate port`` compares
    it with its own boards'); a value other than the two readings is refused naming the file and key."""
    model = camera_model_from_option(_calibration(tmp_path / "cfa.json", board_colour="cfa"))
    assert model.board_colour == "cfa"
    assert camera_model_from_option(_calibration(tmp_path / "old.json")).board_colour is None
    bad = _calibration(tmp_path / "bad.json", board_colour="grey")
    message = f"{str(bad)!r}: board_colour must be one of ('cfa', 'demosaic')"
    with pytest.raises(FileFormatError, match=re.escape(message)):
        camera_model_from_option(bad)
    with pytest.raises(ParameterError, match="board_colour must be one of"):
        CameraModel(camera=TINY, board_colour="grey")
