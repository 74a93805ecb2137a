"""Datasets under hostile or careless input (issue 12): edited meshes, same-size corruption,
huge sweeps, files that are not UTF-8, failed writes.

The render tests share one dataset of two samples of a tiny scene holding a user mesh (tiny
camera, 1 spp), rendered once per module by a local Dask cluster of one worker.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import resource
import shutil
import signal
import subprocess
import sys
import textwrap
import time
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from lfrefract import ParameterError
from lfrefract.errors import FileFormatError
from lfrefract.formats.exr import read_exr
from simulator.dataset import Dataset, DatasetMismatchError, check_dataset, expand, load_spec, parse_spec, run_dataset
from simulator.dataset import manifest as manifest_module
from simulator.dataset import run as run_module
from simulator.dataset import spec as spec_module
from simulator.dataset.manifest import DigestCache, append_record, file_digest, read_manifest
from simulator.dataset.run import _plan, _prepare
from simulator.dataset.spec import MAX_SAMPLES, iter_samples
from tests.tolerances import DATASET_PLAN_BYTES_PER_SAMPLE_MAX, DATASET_STREAM_PEAK_GROWTH_BYTES

MESH_OBJ = "v -0.05 -0.05 0\nv 0.05 -0.05 0\nv 0 0.05 0\nf 1 2 3\n"
#: The same triangle with one vertex moved and the file's size kept.
EDITED_OBJ = MESH_OBJ.replace("v 0 0.05 0", "v 0 0.04 0")
SCENE = """
[camera]
preset = "tiny"
[port]
distance_m = 0.02
thickness_m = 0.004
tilt_x_deg = 10.0
[render]
spp = 1
[[light]]
type = "point"
position_m = [0.0, -0.2, 0.1]
intensity_w_sr = 0.3
[[object]]
type = "textured_plane"
position_m = [0.0, 0.0, 0.6]
size_m = [0.8, 0.6]
texture_px = 64
[[object]]
type = "mesh"
path = "cube.obj"
position_m = [0.0, 0.0, 0.4]
"""
SPEC = '[sweep]\nname = "mesh"\nseed = 5\nscene = "scene.toml"\n[grid]\n"port.tilt_x_deg" = [0.0, 10.0]\n'


def _write_inputs(folder: Path) -> Path:
    """A sweep spec over a scene with a user mesh (``cube.obj``) in ``folder``; returns the spec file."""
    folder.mkdir(parents=True, exist_ok=True)
    assert len(EDITED_OBJ) == len(MESH_OBJ)
    (folder / "cube.obj").write_text(MESH_OBJ)
    (folder / "scene.toml").write_text(SCENE)
    (folder / "spec.toml").write_text(SPEC)
    return folder / "spec.toml"


def _lfsim(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "simulator.cli", *args], capture_output=True, text=True, check=False)


def _tree(root: Path) -> list[tuple[str, int, int]]:
    return sorted((str(p.relative_to(root)), p.stat().st_size, p.stat().st_mtime_ns) for p in root.rglob("*"))


@pytest.fixture(scope="module")
def mesh_run(tmp_path_factory):
    """The mesh sweep rendered once: (inputs folder, dataset folder)."""
    base = tmp_path_factory.mktemp("mesh")
    spec = _write_inputs(base / "inputs")
    report = run_dataset(spec, base / "reference", workers=1, progress=False)
    assert report.ok
    assert report.rendered == 2
    return base / "inputs", base / "reference"


def _copy(mesh_run, tmp_path: Path) -> tuple[Path, Path]:
    """A copy of the inputs (at the same relative place) and of the dataset."""
    inputs, reference = mesh_run
    shutil.copytree(inputs, tmp_path / "inputs")
    root = tmp_path / "data"
    shutil.copytree(reference, root)
    # dataset.json names the inputs by absolute path: point the copy at its own inputs.
    info = json.loads((root / "dataset.json").read_text())
    text = json.dumps(info).replace(str(inputs), str(tmp_path / "inputs"))
    (root / "dataset.json").write_text(text)
    return tmp_path / "inputs", root


# ------------------------------------------------------------------ 1. mesh content in the hash
def test_sample_hash_follows_mesh_content_read_once_per_run(tmp_path, monkeypatch):
    _write_inputs(tmp_path)
    data = {
        "sweep": {"name": "m", "seed": 1, "scene": "scene.toml", "repeats": 3},
        "grid": {"port.tilt_x_deg": [0.0, 5.0]},
    }
    spec = parse_spec(data, base_dir=tmp_path)
    reads = []
    digest = manifest_module.file_digest
    monkeypatch.setattr(manifest_module, "file_digest", lambda path: reads.append(path) or digest(path))
    before = expand(spec)
    scene, mesh = (str((tmp_path / name).resolve()) for name in ("scene.toml", "cube.obj"))
    assert reads == [Path(scene), Path(mesh)]  # six samples, each file read once
    assert all(dict(s.inputs) == dict(before[0].inputs) for s in before)
    assert dict(before[0].inputs[mesh]) == {"bytes": len(MESH_OBJ), "sha256": file_digest(Path(mesh))[1]}
    assert set(before[0].inputs[scene]) == {"bytes", "sha256", "toml_sha256"}
    assert before[0].record()["inputs"] == sorted([scene, mesh])
    (tmp_path / "cube.obj").write_text(EDITED_OBJ)  # same path, same size, other content
    after = expand(spec)
    assert all(a.hash != b.hash for a, b in zip(after, before, strict=True))
    assert [(a.id, a.seed, dict(a.params)) for a in after] == [(b.id, b.seed, dict(b.params)) for b in before]


@pytest.mark.render
def test_an_edited_mesh_is_refused_on_resume_and_reported_by_check(mesh_run, tmp_path):
    inputs, root = _copy(mesh_run, tmp_path)
    assert check_dataset(root).ok
    before = _tree(root)
    (inputs / "cube.obj").write_text(EDITED_OBJ)
    with pytest.raises(
        DatasetMismatchError, match=r"samples differ now \(2 of 2 changed.*input file\(s\) edited since.*cube\.obj"
    ):
        run_dataset(inputs / "spec.toml", root, workers=1, progress=False)
    assert _tree(root) == before  # nothing touched, nothing mixed
    report = check_dataset(root)
    assert [(p.id, p.kind) for p in report.problems] == [("s000000", "stale"), ("s000001", "stale")]
    assert "cube.obj" in report.problems[0].detail
    assert "changed since" in report.problems[0].detail
    assert report.verified == 0
    assert [p.kind for p in check_dataset(root, hashes=False).problems] == []  # same size: sizes alone miss it
    proc = _lfsim("dataset", "check", str(root))
    assert proc.returncode == 1
    assert "s000001: stale: rendered from an input file that changed since" in proc.stdout
    assert "2 samples, 0 verified; 0 missing, 0 corrupt, 2 stale, 0 failed, 0 not run" in proc.stdout
    # The mesh restored: the same samples again; the resume has nothing to do.
    (inputs / "cube.obj").write_text(MESH_OBJ)
    again = run_dataset(inputs / "spec.toml", root, workers=1, progress=False)
    assert (again.ok, again.skipped, again.rendered) == (True, 2, 0)
    assert check_dataset(root).ok
    # Inputs that are not on this machine are named, not counted as problems.
    shutil.rmtree(inputs)
    gone = check_dataset(root)
    assert gone.ok
    assert gone.inputs_gone == (str(inputs / "cube.obj"), str(inputs / "scene.toml"))


@pytest.mark.render
def test_a_base_scene_is_compared_by_its_toml_content(mesh_run, tmp_path):
    """A comment added to the base scene changes nothing; a changed value makes other samples:
    the resume is refused and check calls the done samples stale."""
    inputs, root = _copy(mesh_run, tmp_path)
    scene = inputs / "scene.toml"
    scene.write_text("# a comment\n" + SCENE)
    again = run_dataset(inputs / "spec.toml", root, workers=1, progress=False)
    assert (again.ok, again.skipped, again.rendered) == (True, 2, 0)
    assert check_dataset(root).ok
    scene.write_text(SCENE.replace("texture_px = 64", "texture_px = 65"))
    with pytest.raises(DatasetMismatchError, match=r"2 of 2 changed.*input file\(s\) edited since: \[.*scene\.toml'\]"):
        run_dataset(inputs / "spec.toml", root, workers=1, progress=False)
    report = check_dataset(root)
    assert [(p.id, p.kind) for p in report.problems] == [("s000000", "stale"), ("s000001", "stale")]
    assert "scene.toml' (its TOML content changed since the run was planned)" in report.problems[0].detail
    scene.write_text("[camera\n")
    assert "no longer a readable scene" in check_dataset(root).problems[0].detail


@pytest.mark.render
def test_a_mesh_edited_after_planning_fails_the_sample(tmp_path):
    """The worker checks the planned SHA-256 of each input file once the render has read it."""
    from simulator.dataset.sample import SampleTask, render_sample

    _write_inputs(tmp_path)
    (sample,) = expand(parse_spec({"sweep": {"name": "m", "seed": 1, "scene": "scene.toml"}}, base_dir=tmp_path))
    mesh = str((tmp_path / "cube.obj").resolve())
    task = SampleTask(
        id=sample.id, index=0, seed=sample.seed, hash=sample.hash, params={}, config=sample.config,
        dataset_dir=str(tmp_path / "out"), inputs={mesh: sample.inputs[mesh]["sha256"]},
    )  # fmt: skip
    (tmp_path / "out").mkdir()
    (tmp_path / "cube.obj").write_text(EDITED_OBJ)
    with pytest.raises(
        FileFormatError, match=r"sample s000000: input file .*cube\.obj' changed after the run was planned"
    ):
        render_sample(task)
    assert [p.name for p in (tmp_path / "out").iterdir() if not p.name.startswith(".")] == []


# ------------------------------------------------------------- 2. resume verifies by SHA-256
def _cp_p_same_size(source: bytes, target: Path, scratch: Path) -> None:
    """Put ``source`` (padded with zero bytes to ``target``'s size) in place of ``target`` with ``cp -p``
    from a file given ``target``'s modification time: size and mtime stay as they were."""
    stat = target.stat()
    assert len(source) <= stat.st_size
    scratch.write_bytes(source + bytes(stat.st_size - len(source)))
    os.utime(scratch, ns=(stat.st_atime_ns, stat.st_mtime_ns))
    subprocess.run(["cp", "-p", str(scratch), str(target)], check=True)
    assert (target.stat().st_size, target.stat().st_mtime_ns) == (stat.st_size, stat.st_mtime_ns)


@pytest.mark.render
def test_resume_renders_again_a_raw_swapped_for_another_samples_of_the_same_size_and_mtime(mesh_run, tmp_path):
    """A sample's raw.exr (over 1 MiB) replaced by the other sample's, padded to its size and copied with
    ``cp -p`` from a file of its mtime, is a readable raw of the wrong sample: the resume must see it."""
    inputs, root = _copy(mesh_run, tmp_path)
    # The larger raw is the victim: the smaller one, padded with zeros, still reads as its own image.
    victim, donor = sorted((root / sid / "raw.exr" for sid in ("s000000", "s000001")), key=lambda p: -p.stat().st_size)
    assert victim.stat().st_size > 1 << 20
    truth = read_exr(victim)
    _cp_p_same_size(donor.read_bytes(), victim, tmp_path / "swap.exr")
    assert np.array_equal(read_exr(victim), read_exr(donor))  # silently another sample's raw image
    (problem,) = check_dataset(root).problems
    assert (problem.id, problem.kind) == (victim.parent.name, "corrupt")
    assert problem.detail.startswith("raw.exr: SHA-256 ")
    report = run_dataset(inputs / "spec.toml", root, workers=1, progress=False)
    assert (report.ok, report.skipped, report.rendered, report.damaged) == (True, 1, 1, (victim.parent.name,))
    assert f"1 failed and was rendered again ({victim.parent.name}: raw.exr: SHA-256 " in report.verification
    assert check_dataset(root).ok
    assert np.array_equal(read_exr(victim), truth)  # rendering is bit-reproducible: its own raw again


def test_digest_cache_sees_a_same_size_file_copied_or_moved_in_with_the_same_mtime(tmp_path, monkeypatch):
    """The cache of one run (a mesh many samples read) is keyed by more than path, size and mtime: a
    ``cp -p`` or a rename into place of a same-size file of the same mtime is read again."""
    mesh, other = tmp_path / "cube.obj", tmp_path / "other.obj"
    mesh.write_text(MESH_OBJ)
    reads = []
    digest = manifest_module.file_digest
    monkeypatch.setattr(manifest_module, "file_digest", lambda path: reads.append(path) or digest(path))
    cache = DigestCache()
    assert cache.digest(mesh) == cache.digest(mesh) == digest(mesh)
    assert len(reads) == 1  # an unchanged file is read once
    time.sleep(0.05)  # past the kernel's coarse clock tick (a few ms) of the file's last change
    _cp_p_same_size(EDITED_OBJ.encode(), mesh, other)
    assert cache.digest(mesh) == digest(other)
    time.sleep(0.05)
    moved = tmp_path / "moved.obj"
    moved.write_text(MESH_OBJ)
    os.utime(moved, ns=(mesh.stat().st_atime_ns, mesh.stat().st_mtime_ns))
    os.replace(moved, mesh)
    assert cache.digest(mesh) == (len(MESH_OBJ), hashlib.sha256(MESH_OBJ.encode()).hexdigest())


@pytest.mark.render
def test_resume_rehashes_every_file_and_renders_a_corrupt_sidecar_again(mesh_run, tmp_path):
    inputs, root = _copy(mesh_run, tmp_path)
    sidecar = root / "s000001" / "sample.json"
    text = sidecar.read_text()
    assert '"lfsim.dataset.sample"' in text
    sidecar.write_text(text.replace('"lfsim.dataset.sample"', '"lfsim.dataset.sampLe"'))  # same size
    assert not check_dataset(root).ok
    assert check_dataset(root, hashes=False).ok
    proc = _lfsim("dataset", "run", str(inputs / "spec.toml"), "--out", str(root), "--workers", "1", "--quiet")
    assert proc.returncode == 0, proc.stderr
    assert "2 samples; 1 rendered now" in proc.stdout
    assert "1 already done" in proc.stdout
    (line,) = [s for s in proc.stdout.splitlines() if s.startswith("resume verified")]
    assert "resume verified 2 done sample(s) by the SHA-256 of every file (" in line
    assert "1 failed and was rendered again (s000001: sample.json: SHA-256 " in line
    assert check_dataset(root).ok
    assert '"lfsim.dataset.sample"' in sidecar.read_text()
    records = read_manifest(root / "manifest.jsonl")
    assert [r["id"] for r in records][-1] == "s000001"
    assert len(records) == 3


@pytest.mark.render
def test_resume_reports_what_it_verified_and_how_long_the_hashing_took(mesh_run, tmp_path):
    inputs, root = _copy(mesh_run, tmp_path)
    report = run_dataset(inputs / "spec.toml", root, workers=1, progress=False)
    assert (report.ok, report.skipped, report.rendered, report.damaged) == (True, 2, 0, ())
    files = [entry for r in read_manifest(root / "manifest.jsonl") for entry in r["files"].values()]
    megabytes = sum(e["bytes"] for e in files) / 1e6
    match = re.fullmatch(
        rf"resume verified 2 done sample\(s\) by the SHA-256 of every file \({len(files)} files, "
        rf"{megabytes:.1f} MB, in ([0-9.e-]+) s: (\d+\.\d) s per GB\); 0 failed and were rendered again",
        report.verification,
    )
    assert match, report.verification
    print(f"\nresume hashing: {megabytes:.1f} MB in {match[1]} s, {match[2]} s per GB")
    fresh = run_dataset(inputs / "spec.toml", tmp_path / "fresh", workers=1, progress=False)
    assert fresh.verification == ""  # nothing was done before


# --------------------------------------------------------------------- 3. huge sweeps
def test_a_sweep_over_the_limit_is_refused_before_any_sample_is_built(tmp_path, monkeypatch):
    def never(*args, **kwargs):
        raise AssertionError("a sample was built")

    monkeypatch.setattr(spec_module, "_build_sample", never)
    count = 100_002  # the documented limit (docs/datasets.md), MAX_SAMPLES = 100 000, and 2
    data = {
        "sweep": {"name": "big", "seed": 0, "scene": "default", "repeats": count // 2},
        "grid": {"port.tilt_x_deg": [0.0, 1.0]},
    }
    with pytest.raises(ParameterError, match=rf"the sweep has {count} samples, more than 100000"):
        parse_spec(data)
    (tmp_path / "big.toml").write_text(
        f'[sweep]\nname = "big"\nseed = 0\nscene = "default"\nrepeats = {count // 2}\n'
        '[grid]\n"port.tilt_x_deg" = [0.0, 1.0]\n'
    )
    proc = _lfsim("dataset", "run", str(tmp_path / "big.toml"), "--out", str(tmp_path / "out"))
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        f"lfsim: error: sweep spec file {str(tmp_path / 'big.toml')!r}: the sweep has {count} samples, more than "
        f"{MAX_SAMPLES}: check [grid] and sweep.repeats"
    ]
    assert not (tmp_path / "out").exists()


def _peak(fn) -> int:
    tracemalloc.start()
    try:
        fn()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def _tilt_spec(count: int):
    data = {
        "sweep": {"name": "m", "seed": 1, "scene": "default", "repeats": count // 4},
        "grid": {"port.tilt_x_deg": [0.0, 5.0, 10.0, 15.0]},
    }
    return parse_spec(data)


def test_checking_a_sweep_holds_one_sample_at_a_time():
    """Building and checking every sample (a run's first pass) keeps only each sample's record:
    the peak of iterating does not grow with the count, and the plan grows by a small record."""
    small, large = _tilt_spec(52), _tilt_spec(200)

    def drain(spec):
        for _ in iter_samples(spec):
            pass

    # Warm-up: imports, the base scene's meshes generated once, and Python's free lists filled
    # (tracemalloc counts a block parked on a free list as alive).
    drain(large)
    assert _peak(lambda: drain(large)) - _peak(lambda: drain(small)) < DATASET_STREAM_PEAK_GROWTH_BYTES
    grown = _peak(lambda: _plan(large, DigestCache(), False)) - _peak(lambda: _plan(small, DigestCache(), False))
    assert grown / (200 - 52) < DATASET_PLAN_BYTES_PER_SAMPLE_MAX


def test_a_long_check_says_how_long_it_will_take(monkeypatch, capsys):
    monkeypatch.setattr(spec_module, "_ESTIMATE_AFTER_S", 0.0)
    monkeypatch.setattr(spec_module, "_ESTIMATE_MIN_S", 0.0)
    for _ in iter_samples(_tilt_spec(8), progress=True):
        pass
    err = capsys.readouterr().err
    assert "checking 8 samples before any work: about " in err
    assert " ms per sample)" in err


# ------------------------------------------------------------------- 4. not UTF-8
UTF16 = "utf-16"  # with its byte-order mark


def test_a_sweep_spec_or_base_scene_that_is_not_utf8_is_a_clear_error(tmp_path):
    (tmp_path / "spec16.toml").write_text(SPEC, encoding=UTF16)
    with pytest.raises(
        FileFormatError, match=r"sweep spec file '.*spec16\.toml' is not UTF-8 text \(it starts with a UTF-16"
    ):
        load_spec(tmp_path / "spec16.toml")
    (tmp_path / "latin1.toml").write_bytes(SPEC.replace('"mesh"', '"m\xe9sh"').encode("latin-1"))
    at = SPEC.index('"mesh"') + 2
    with pytest.raises(FileFormatError, match=rf"sweep spec file '.*latin1\.toml' is not UTF-8 text: byte {at} "):
        load_spec(tmp_path / "latin1.toml")
    proc = _lfsim("dataset", "run", str(tmp_path / "spec16.toml"), "--out", str(tmp_path / "out"))
    assert proc.returncode == 2
    (line,) = proc.stderr.strip().splitlines()
    assert line.startswith("lfsim: error: sweep spec file ")
    assert "spec16.toml" in line
    assert not (tmp_path / "out").exists()
    _write_inputs(tmp_path / "inputs")
    (tmp_path / "inputs" / "scene.toml").write_text(SCENE, encoding=UTF16)
    with pytest.raises(FileFormatError, match=r"scene file '.*inputs/scene\.toml' is not UTF-8 text"):
        expand(load_spec(tmp_path / "inputs" / "spec.toml"))


def _planned_dataset(root: Path) -> None:
    """A dataset folder as a run leaves it before any sample is done (no rendering)."""
    spec = load_spec("tilt")
    planned, inputs = _plan(spec, DigestCache(), False)
    _prepare(root, spec, planned, inputs)


def test_a_dataset_json_or_manifest_that_is_not_utf8_is_a_clear_error(tmp_path):
    root = tmp_path / "data"
    _planned_dataset(root)
    info = (root / "dataset.json").read_text()
    (root / "dataset.json").write_text(info, encoding=UTF16)
    for read in (Dataset, check_dataset):
        with pytest.raises(FileFormatError, match=r"'.*data/dataset\.json' is not UTF-8 text"):
            read(root)
    proc = _lfsim("dataset", "check", str(root))
    assert proc.returncode == 2
    (line,) = proc.stderr.strip().splitlines()
    assert line.startswith("lfsim: error: ")
    assert "dataset.json' is not UTF-8 text" in line
    with pytest.raises(DatasetMismatchError, match=r"is not an lfsim dataset \(.*dataset\.json' is not UTF-8"):
        run_dataset("tilt", root, progress=False)
    (root / "dataset.json").write_text(info)
    record = {"id": "s000000", "index": 0, "status": "failed", "error": "caf\xe9"}
    (root / "manifest.jsonl").write_bytes((json.dumps(record, ensure_ascii=False) + "\n").encode("latin-1"))
    for read in (Dataset, check_dataset):
        with pytest.raises(FileFormatError, match=r"'.*data/manifest\.jsonl' line 1 is not UTF-8 text"):
            read(root)
    (root / "manifest.jsonl").write_text(json.dumps(record) + "\n", encoding=UTF16)
    with pytest.raises(FileFormatError, match=r"manifest\.jsonl' line 1 is not"):
        check_dataset(root)


@pytest.mark.parametrize(
    "info",
    [
        {"kind": "lfsim.dataset", "samples": [{"id": "s000000"}]},
        {"kind": "lfsim.dataset", "samples": [], "inputs": {"/x.obj": "abc"}},
    ],
    ids=["sample without hash", "inputs not files"],
)
def test_a_malformed_dataset_json_is_a_clear_error(tmp_path, info):
    from lfrefract.formats.jsonio import write_json

    write_json(tmp_path / "dataset.json", info)
    with pytest.raises(FileFormatError, match=r"dataset\.json'"):
        check_dataset(tmp_path)


def test_a_malformed_manifest_record_is_a_clear_error(tmp_path):
    root = tmp_path / "data"
    _planned_dataset(root)
    record = {"id": "s000000", "status": "done", "files": {"raw.exr": 9}}  # a size, not {bytes, sha256}
    (root / "manifest.jsonl").write_text(json.dumps(record) + "\n")
    for read in (Dataset, check_dataset):
        with pytest.raises(FileFormatError, match=r"manifest\.jsonl' line 1: a done record needs 'files'"):
            read(root)


# ------------------------------------------------------------------- 5. failed writes
def test_a_failed_manifest_append_leaves_the_manifest_as_it_was(tmp_path):
    """A write that fails part-way (here: the file-size limit, EFBIG, as a full disk would) is cut
    back: the manifest keeps exactly its earlier lines, and the error names the file."""
    manifest = tmp_path / "manifest.jsonl"
    append_record(manifest, {"id": "s000000", "status": "done", "files": {}})
    code = textwrap.dedent(
        f"""
        import resource, signal, sys
        from simulator.dataset.manifest import append_record
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        size = {manifest.stat().st_size}
        resource.setrlimit(resource.RLIMIT_FSIZE, (size + 20, resource.getrlimit(resource.RLIMIT_FSIZE)[1]))
        try:
            append_record({str(manifest)!r}, {{"id": "s000001", "status": "done", "files": {{"raw.exr": "x" * 500}}}})
        except OSError as exc:
            print(exc)
            sys.exit(3)
        """
    )
    before = manifest.read_bytes()
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert proc.returncode == 3, proc.stderr
    assert manifest.read_bytes() == before
    assert [r["id"] for r in read_manifest(manifest)] == ["s000000"]
    assert proc.stdout.strip() == f"[Errno 27] File too large: {str(manifest)!r}"


@pytest.mark.render
def test_lfsim_dataset_run_ends_in_one_line_when_the_manifest_cannot_grow(mesh_run, tmp_path, monkeypatch, capsys):
    """The driver's append fails (a real EFBIG under a file-size limit): one line naming the
    manifest, exit 2, earlier output intact; the next run completes the dataset."""
    from simulator import cli

    inputs, root = _copy(mesh_run, tmp_path)
    shutil.rmtree(root / "s000001")
    lines = [line for line in (root / "manifest.jsonl").read_text().splitlines() if '"s000001"' not in line]
    (root / "manifest.jsonl").write_text("".join(f"{line}\n" for line in lines))
    before = (root / "manifest.jsonl").read_bytes()
    real_append = run_module.append_record

    def append_at_the_size_limit(path, record):
        soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
        handler = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (Path(path).stat().st_size + 10, hard))
        try:
            real_append(path, record)
        finally:
            resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
            signal.signal(signal.SIGXFSZ, handler)

    monkeypatch.setattr(run_module, "append_record", append_at_the_size_limit)
    status = cli.main(["dataset", "run", str(inputs / "spec.toml"), "--out", str(root), "--workers", "1", "--quiet"])
    err = capsys.readouterr().err
    assert status == 2
    assert err.strip().splitlines() == [f"lfsim: error: [Errno 27] File too large: {str(root / 'manifest.jsonl')!r}"]
    assert (root / "manifest.jsonl").read_bytes() == before
    assert (root / "s000000").is_dir()
    monkeypatch.setattr(run_module, "append_record", real_append)
    again = run_dataset(inputs / "spec.toml", root, workers=1, progress=False)
    assert (again.ok, again.skipped, again.rendered) == (True, 1, 1)
    assert check_dataset(root).ok


def test_a_manifest_that_is_not_a_file_is_refused_and_no_sample_is_removed(tmp_path):
    root = tmp_path / "data"
    _planned_dataset(root)
    (root / "s000000").mkdir()
    (root / "s000000" / "raw.exr").write_bytes(b"pixels")
    (root / "manifest.jsonl").mkdir()
    spec = load_spec("tilt")
    planned, inputs = _plan(spec, DigestCache(), False)
    with pytest.raises(FileFormatError, match=r"manifest\.jsonl' is not a file"):
        _prepare(root, spec, planned, inputs)
    assert (root / "s000000" / "raw.exr").read_bytes() == b"pixels"
    proc = _lfsim("dataset", "check", str(root))
    assert proc.returncode == 2
    assert "manifest.jsonl' is not a file" in proc.stderr
