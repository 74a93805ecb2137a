"""MLA calibration on real white images: the light-field microscope examples the napari-LF package ships.

The wheel is fetched from the package index (``pip download --no-deps napari-lf==0.1.7``, 26 MB) by
``benchmarks/measure_real_whites.py``'s helpers; its radiometry frames less their dark frames are real
lenslet white images (square MLAs of 100-125 um behind microscope objectives).
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from lfrefract.calibration import calibrate_mla
from tests.tolerances import (
    REAL_WHITE_AFFINE_RMS_PX,
    REAL_WHITE_NOMINAL_PITCH_RELATIVE,
    REAL_WHITE_PITCH_RELATIVE,
    REAL_WHITE_RMS_PX,
)

ROOT = Path(__file__).resolve().parents[2]
_spec = importlib.util.spec_from_file_location("measure_real_whites", ROOT / "benchmarks" / "measure_real_whites.py")
real_whites = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(real_whites)


@pytest.fixture(scope="module")
def examples(tmp_path_factory) -> Path:
    return real_whites.examples_folder(tmp_path_factory.mktemp("napari-lf"))


@pytest.mark.parametrize("name", sorted(real_whites.EXAMPLES))
def test_real_lenslet_whites_are_calibrated(examples, name):
    *_, nominal_px = real_whites.EXAMPLES[name]
    calibration = calibrate_mla(real_whites.white_image(examples, name))
    assert calibration.grid == "square"
    assert abs(calibration.pitch_px / nominal_px - 1.0) < REAL_WHITE_NOMINAL_PITCH_RELATIVE
    assert calibration.residual_rms_px < REAL_WHITE_RMS_PX
    assert calibration.used.sum() > 700


def test_the_microscope_lattice_is_slightly_anisotropic(examples):
    """GUVExperim1's lattice is 0.15 % longer along v than along u: the affine model takes its
    residual from 0.13 to 0.03 px, and its pitch is the nominal 100 um / 6.5 um to 0.1 %."""
    image = real_whites.white_image(examples, "GUVExperim1")
    regular = calibrate_mla(image)
    affine = calibrate_mla(image, lattice_model="affine")
    assert affine.residual_rms_px < REAL_WHITE_AFFINE_RMS_PX < regular.residual_rms_px
    assert abs(regular.pitch_px / (100.0 / 6.5) - 1.0) < REAL_WHITE_PITCH_RELATIVE
