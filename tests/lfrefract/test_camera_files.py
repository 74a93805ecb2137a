"""Camera files and the ray models they carry: a file's content decides what it is, and every
contradiction between its ``kind`` and its content, and every problem of a key, is an error naming
the file, the key and the value (``--camera``, ``--port``, ``--mla``)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from lfrefract import FlatPort, ParameterError, camera_preset
from lfrefract.errors import FileFormatError
from lfrefract.formats.capture import (
    camera_model_from_option,
    check_port_ray_model,
    mla_from_file,
    port_from_file,
    read_sidecar,
)
from lfrefract.formats.jsonio import read_json, write_json
from lfrefract.formats.paramfile import read_camera_file
from lfrefract.optics.camera_model import CameraModel
from lfrefract.optics.ray_correction import PARAMETERS, CorrectionEstimate, RayCorrection

TINY = camera_preset("tiny")
CORRECTION = RayCorrection(pupil_scale=0.99, k1=0.02)
PORT = FlatPort(distance_m=0.02)


def calibration(path: Path, **changes) -> Path:
    """A camera calibration (``lfrefract calibrate camera`` output) of the tiny camera, with
    ``changes`` to its top-level keys (a value None removes the key)."""
    estimate = CorrectionEstimate(correction=CORRECTION, covariance=np.eye(len(PARAMETERS)) * 1e-6)
    data = {
        "kind": "lfrefract.calibrate.camera",
        "camera": TINY.to_dict(),
        "correction": CORRECTION.to_dict(),
        "correction_covariance": estimate.covariance_to_dict(),
        **changes,
    }
    write_json(path, {k: v for k, v in data.items() if v is not None or k not in changes})
    return path


def test_a_camera_calibration_gives_its_camera_and_correction_under_any_suffix(tmp_path):
    for name in ("camera.json", "camera.cal", "camera"):  # a camera file of any suffix but .toml is JSON
        path = calibration(tmp_path / name)
        model = camera_model_from_option(path)
        assert model.camera == TINY
        assert model.correction == CORRECTION
        assert model.estimate().correction == CORRECTION


@pytest.mark.parametrize("kind", ["lfrefract.camera", "lfsim.render", "lfrefract.calibrate.mla", "my.camera", None])
def test_a_correction_in_a_file_of_another_kind_is_refused(tmp_path, kind):
    # The kind edited: every --camera reader read the thin lens, the output bit-identical to it.
    path = calibration(tmp_path / "camera.json", kind=kind)  # None: no kind
    said = re.escape(f"{str(path)!r}: key 'kind' is {kind!r}")
    for read in (camera_model_from_option, read_camera_file):
        with pytest.raises(FileFormatError, match=said) as info:
            read(path)
        assert "'correction'" in str(info.value)
        assert "'lfrefract.calibrate.camera'" in str(info.value)


def test_a_covariance_in_a_file_of_another_kind_is_refused(tmp_path):
    path = calibration(tmp_path / "camera.json", kind="lfrefract.camera", correction=None)
    with pytest.raises(FileFormatError, match=re.escape("key 'kind' is 'lfrefract.camera'")) as info:
        camera_model_from_option(path)
    assert "'correction_covariance'" in str(info.value)


def test_a_camera_calibration_without_its_correction_is_refused(tmp_path):
    path = calibration(tmp_path / "camera.json", correction=None)
    with pytest.raises(FileFormatError, match=re.escape(f"{str(path)!r} is a camera calibration")) as info:
        camera_model_from_option(path)
    assert "no 'correction'" in str(info.value)


@pytest.mark.parametrize(
    ("data", "says"),
    [
        # A plain camera file holds its camera only.
        ({"kind": "lfrefract.camera", "mla": {}}, "key 'kind' is 'lfrefract.camera', but the file holds a 'mla' table"),
        # An MLA calibration holds its mla.
        ({"kind": "lfrefract.calibrate.mla"}, "is an MLA calibration (key 'kind' is 'lfrefract.calibrate.mla') but"),
        # A real main lens (RealLensCamera.to_dict): the camera table alone is its thin-lens twin.
        ({"kind": "lfsim.render", "lens": {"name": "double-gauss"}}, "holds a 'lens' table"),
        ({"lens": {"name": "double-gauss"}}, "holds a 'lens' table"),
    ],
)
def test_a_table_the_kind_does_not_hold_or_lacks_is_refused(tmp_path, data, says):
    path = tmp_path / "camera.json"
    write_json(path, {"camera": TINY.to_dict(), **data})
    with pytest.raises(FileFormatError, match=re.escape(says)):
        camera_model_from_option(path)


def test_a_captures_sidecar_holding_a_correction_is_refused(tmp_path):
    # The capture's own camera is the thin lens: a correction beside it would be ignored.
    path = tmp_path / "meta.json"
    write_json(path, {"kind": "lfsim.render", "camera": TINY.to_dict(), "correction": CORRECTION.to_dict()})
    with pytest.raises(FileFormatError, match=re.escape(f"{str(path)!r}: key 'kind' is 'lfsim.render', but")):
        read_sidecar(path)


def test_a_file_of_another_kind_is_no_mla_calibration(tmp_path):
    path = tmp_path / "mla.json"
    write_json(path, {"kind": "lfrefract.camera", "camera": TINY.to_dict(), "mla": {"grid": "hex"}})
    with pytest.raises(FileFormatError, match=re.escape(f"{str(path)!r}: key 'kind' is 'lfrefract.camera'")):
        mla_from_file(path)


# =============================================================================== the correction's keys
@pytest.mark.parametrize(
    ("correction", "says"),
    [
        ({**CORRECTION.to_dict(), "pupil_scale": 3.0}, "correction.pupil_scale must lie in [0.5, 2], got 3.0"),
        ({**CORRECTION.to_dict(), "k1": 11.0}, "correction.k1 must lie in [-10, 10], got 11.0"),
        ({**CORRECTION.to_dict(), "pupil_drift_m": 0.7}, "correction.pupil_drift_m must lie in [-0.5, 0.5] m"),
        ({**CORRECTION.to_dict(), "slope_scale": "nan"}, "correction.slope_scale must be a real number, got 'nan'"),
        ({**CORRECTION.to_dict(), "k2": None}, "correction.k2 must be a real number, got None"),
        ({"pupil_scale": 1.0}, "missing key(s) in"),
        ([1.0, 1.0, 0.0, 0.0], "key 'correction' must be a table"),
        (None, "key 'correction' must be a table"),
    ],
)
def test_every_problem_of_the_correction_names_the_file_and_the_key(tmp_path, correction, says):
    path = calibration(tmp_path / "camera.json", correction=correction)
    if correction is None:  # null, not absent
        data = read_json(path)
        del data["schema_version"]
        write_json(path, {**data, "correction": None})
    with pytest.raises(FileFormatError, match=re.escape(says)) as info:
        camera_model_from_option(path)
    assert str(path) in str(info.value)


def _covariance(matrix) -> dict:
    return {"parameters": list(PARAMETERS), "matrix": matrix}


SPD = (np.eye(len(PARAMETERS)) * 1e-6).tolist()
ASYMMETRIC = [[1.0 if (i, j) == (0, 1) else v for j, v in enumerate(r)] for i, r in enumerate(SPD)]


@pytest.mark.parametrize(
    ("covariance", "says"),
    [
        (None, "correction_covariance must be a table"),
        ([1.0], "correction_covariance must be a table"),
        ({"matrix": SPD}, "missing key(s) in"),
        ({"parameters": 5, "matrix": SPD}, "correction_covariance.parameters must be"),
        (_covariance([[*row[:4], "nan"] for row in SPD]), "correction_covariance.matrix[0][4] must be a real number"),
        (_covariance(SPD[:4]), "correction_covariance.matrix must be 5 rows of 5 numbers"),
        (_covariance(ASYMMETRIC), "correction_covariance must be symmetric"),
        (_covariance((-np.eye(5)).tolist()), "correction_covariance must be positive definite"),
    ],
)
def test_every_problem_of_the_covariance_names_the_file_and_the_key(tmp_path, covariance, says):
    path = calibration(tmp_path / "camera.json")
    data = read_json(path)
    del data["schema_version"]
    write_json(path, {**data, "correction_covariance": covariance})
    with pytest.raises(FileFormatError, match=re.escape(says)) as info:
        camera_model_from_option(path)
    assert str(path) in str(info.value)


def test_a_calibration_without_a_covariance_gives_its_correction_but_no_refinement(tmp_path):
    # Files written before the covariance was recorded: their correction is whole; only a
    # refinement needs the covariance, and it says what to do.
    path = calibration(tmp_path / "camera.json", correction_covariance=None)
    model = camera_model_from_option(path)
    assert model.correction == CORRECTION
    assert model.covariance is None
    said = re.escape(f"the camera model of {str(path)!r} has no correction_covariance")
    with pytest.raises(ParameterError, match=said):
        model.estimate()


# =============================================================================== port files and their ray model
def _port_calibration(path: Path, kind: str = "lfrefract.calibrate.port", correction=None) -> Path:
    write_json(
        path,
        {"kind": kind, "port": PORT.to_dict(), "ray_model": {"camera": "camera.json", "correction": correction}},
    )
    return path


@pytest.mark.parametrize("name", ["port.json", "port.cal"])
def test_a_port_calibrated_on_another_ray_model_is_refused_under_any_suffix(tmp_path, name):
    path = _port_calibration(tmp_path / name, correction=None)
    assert port_from_file(path) == PORT
    with pytest.raises(ParameterError, match=re.escape("was calibrated on the ray model of 'camera.json'")):
        check_port_ray_model(path, CameraModel(camera=TINY, correction=CORRECTION, source="camera.json"))
    check_port_ray_model(path, CameraModel(camera=TINY, source="tiny"))


@pytest.mark.parametrize("kind", ["lfrefract.port", "lfsim.render", None])
def test_a_ray_model_in_a_port_file_of_another_kind_is_refused(tmp_path, kind):
    path = _port_calibration(tmp_path / "port.json", kind="lfrefract.calibrate.port")
    data = read_json(path)
    del data["schema_version"], data["kind"]
    write_json(path, data if kind is None else {"kind": kind, **data})
    said = re.escape(f"{str(path)!r}: key 'kind' is {kind!r}, but the file holds a 'ray_model' table")
    with pytest.raises(FileFormatError, match=said):
        port_from_file(path)
    with pytest.raises(FileFormatError, match=said):
        check_port_ray_model(path, CameraModel(camera=TINY, source="tiny"))


def test_a_port_calibrations_bad_ray_model_names_the_file_and_the_key(tmp_path):
    path = _port_calibration(tmp_path / "port.json", correction={**CORRECTION.to_dict(), "k2": 20.0})
    with pytest.raises(FileFormatError, match=re.escape(f"{str(path)!r}: ray_model.correction.k2 must lie in")):
        check_port_ray_model(path, CameraModel(camera=TINY, correction=CORRECTION, source="camera.json"))
