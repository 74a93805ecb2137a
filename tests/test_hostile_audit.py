"""The hostile-input audit (benchmarks/audit_hostile_inputs.py) classifies what it sees, and its Lytro
cases hold on files made here without a render.

The whole audit (330 cases, fixtures rendered) runs by hand; here, its classification on commands
whose outcome is known, and a sample of its forged-Lytro cases on an LFR and an Illum .raw + .txt
written by lfrefract from a synthetic mosaic of the ``tiny`` camera.
"""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from lfrefract import camera_preset
from lfrefract.formats.lytro import pack_10bit, read_lfr, write_lfr
from lfrefract.formats.mosaic import RawMosaic

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def audit():
    spec = importlib.util.spec_from_file_location("audit_hostile_inputs", ROOT / "benchmarks/audit_hostile_inputs.py")
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    yield module
    sys.modules.pop(spec.name, None)


@pytest.fixture(scope="module")
def fixtures(tmp_path_factory) -> Path:
    """``lfr/capture.lfr`` and ``capture.raw`` + ``capture.txt`` (its metadata) of a lenslet-like
    mosaic of the tiny camera: mid-grey with a bright spot per 16 x 16 pixels."""
    root = tmp_path_factory.mktemp("audit-fixtures")
    camera = camera_preset("tiny")
    h, w = camera.sensor.height_px, camera.sensor.width_px
    rng = np.random.default_rng(3)
    counts = 200 + rng.integers(0, 300, size=(h, w))
    mosaic = RawMosaic(counts=counts, cfa_pattern="GRBG", black_level_dn=64, white_level_dn=1023, bit_depth=10)
    (root / "lfr").mkdir()
    write_lfr(root / "lfr" / "capture.lfr", mosaic, camera)
    lytro = read_lfr(root / "lfr" / "capture.lfr")
    (root / "capture.raw").write_bytes(pack_10bit(lytro.mosaic.counts))
    (root / "capture.txt").write_text(json.dumps(lytro.metadata))
    return root


def _run(audit, case, fixtures: Path, tmp_path: Path) -> dict:
    return audit.run_case(case, fixtures=fixtures, root=tmp_path, tree=ROOT, memory_gb=6.0)


def test_the_audit_has_its_groups_and_at_least_250_cases(audit, tmp_path):
    cases = audit.all_cases(tmp_path)
    groups = {c.group for c in cases}
    assert len(cases) >= 250
    expected = {"lytro", "lytro-metadata", "whites", "calibration", "camera-files", "synthesis", "outputs"}
    assert expected | {"simulator", "signals"} <= groups


def test_the_audit_tells_each_class_apart(audit, fixtures, tmp_path):
    """A refusal that was due and names its words is ok; one that does not name them is unclear; a
    success where a refusal was due is silent; a refusal where a result was due is refused."""
    Case = audit.Case
    synth = ("lfrefract", "synth", "{C}/none.exr", "--out", "{C}/o.exr", "--k", "0")
    describe = ("lfrefract", "describe", "tiny")
    outcomes = {
        "named": _run(audit, Case(group="t", name="named", argv=synth, says=("--k",)), fixtures, tmp_path),
        "unnamed": _run(audit, Case(group="t", name="unnamed", argv=synth, says=("--kk",)), fixtures, tmp_path),
        "silent": _run(audit, Case(group="t", name="silent", argv=describe), fixtures, tmp_path),
        "refused": _run(audit, Case(group="t", name="refused", argv=synth, expect="ok"), fixtures, tmp_path),
    }
    assert {k: v["class"] for k, v in outcomes.items()} == {
        "named": "ok",
        "unnamed": "unclear",
        "silent": "silent",
        "refused": "refused",
    }


SAMPLE = (
    "container-10-bytes-magic",
    "container-trailing-garbage",
    "lfr-symlink-loop",
    "raw-pair-reference",
    "image.width-nan",
    "width-height-swapped",
    "ccm-all-zero",
    "gain-not-a-table",
    "black-at-white",
)


def test_a_sample_of_the_forged_lytro_cases_is_refused_by_name(audit, fixtures, tmp_path):
    cases = {c.name: c for c in audit.lytro_cases()}
    outcomes = {name: _run(audit, cases[name], fixtures, tmp_path) for name in SAMPLE}
    wrong = {name: (o["class"], o["detail"]) for name, o in outcomes.items() if o["class"] != "ok"}
    assert wrong == {}


def test_the_audit_deletes_nothing_in_a_folder_it_did_not_write(audit, tmp_path):
    """Its fixtures and case folders are removed and made anew under --work: a --work folder holding
    a user's files is refused before anything is touched."""
    work = tmp_path / "mine"
    work.mkdir()
    (work / "fixtures").mkdir()
    (work / "fixtures" / "precious.txt").write_text("keep")
    with pytest.raises(SystemExit, match="holds files this script did not write"):
        audit.main(["--work", str(work), "--only", "nothing"])
    assert (work / "fixtures" / "precious.txt").read_text() == "keep"
    audit.claim_work_folder(tmp_path / "new")
    audit.claim_work_folder(tmp_path / "new")  # its own folder, again
