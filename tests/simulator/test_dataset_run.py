"""Dataset runs on a local Dask cluster: files and manifest, check, loader, kill and resume, failures.

The reference is the embedded ``tilt`` sweep (4 samples of the tiny default scene at 4 spp, with the
refraction-free image) rendered once per module by a local cluster of 2 workers.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from lfrefract import FlatPort, PinholeCamera
from lfrefract.formats.flatport import read_flat_port
from lfrefract.formats.jsonio import read_json
from lfrefract.synthesis.warp_map import SynthesisOptions, build_warp_map
from simulator.dataset import Dataset, DatasetMismatchError, check_dataset, expand, load_spec, parse_spec, run_dataset
from simulator.dataset.manifest import file_digest, read_manifest
from tests.tolerances import DATASET_TURBID_OVER_CLEAR_MAX

pytestmark = pytest.mark.render

ARRAYS = ("raw", "ideal", "depth_m", "refraction_free", "coverage")
#: Files whose bytes differ between runs of the same spec: the render sidecar holds timings, and the
#: folder's output manifest lists the sidecar's size.
TIMED_FILES = {"meta.json", ".lfrefract-output.json"}
#: Files of a view stack folder besides the views.
VIEW_STACK_FILES = (".lfrefract-output.json", "parameters.cfg", "stack.npz", "valid_mask.png", "views.json")
#: Seconds a test waits for a subprocess event before it fails.
WAIT_S = 180.0


@pytest.fixture(scope="module")
def tilt_run(tmp_path_factory):
    """The embedded tilt sweep rendered by a local Dask cluster of 2 worker processes."""
    out = tmp_path_factory.mktemp("tilt") / "uninterrupted"
    report = run_dataset("tilt", out, workers=2, progress=False)
    return report


@pytest.fixture(scope="module")
def scheduler():
    """Address of a running Dask cluster (2 worker processes) for runs given ``scheduler=``."""
    from dask.distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as cluster:
        yield cluster.scheduler_address


def _records(root: Path) -> list[dict]:
    return read_manifest(root / "manifest.jsonl")


def _lfsim(*args: str, **kwargs) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "simulator.cli", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        **kwargs,
    )


def test_run_writes_every_sample_and_its_record(tilt_run):
    root = tilt_run.out_dir
    samples = expand(load_spec("tilt"))
    assert tilt_run.ok
    assert (tilt_run.total, tilt_run.rendered, tilt_run.skipped, tilt_run.failed) == (4, 4, 0, ())
    assert sorted(p.name for p in root.iterdir()) == ["dataset.json", "manifest.jsonl", *[s.id for s in samples]]
    info = read_json(root / "dataset.json")
    assert info["spec_hash"] == load_spec("tilt").hash
    assert info["samples"] == [s.record() for s in samples]
    records = _records(root)
    assert sorted(r["id"] for r in records) == [s.id for s in samples]
    for sample in samples:
        (record,) = [r for r in records if r["id"] == sample.id]
        folder = root / sample.id
        assert record["status"] == "done"
        assert record["attempts"] == 1
        assert (record["seed"], record["hash"], record["params"]) == (sample.seed, sample.hash, dict(sample.params))
        assert set(record["seconds"]) >= {"render", "raw", "ideal", "refraction_free", "total"}
        assert sorted(record["files"]) == [
            ".lfrefract-output.json", "depth.exr", "ideal.exr", "lenses.npz", "meta.json", "port.txt", "raw.exr",
            "refraction_free.coverage.exr", "refraction_free.exr", "refraction_free.filled.exr", "sample.json",
        ]  # fmt: skip
        for name, entry in record["files"].items():
            assert file_digest(folder / name) == (entry["bytes"], entry["sha256"])
        meta = read_json(folder / "meta.json")
        assert meta["render"]["seed"] == sample.seed
        assert meta["render"]["spp"] == 4
        # port.txt: the flat-port layout, the sample's port.
        port = read_flat_port(folder / "port.txt")
        expected = FlatPort.from_degrees(
            distance_m=0.02,
            thickness_m=0.006,
            tilt_x_deg=sample.params["port.tilt_x_deg"],
            tilt_y_deg=sample.params["port.tilt_y_deg"],
        )
        np.testing.assert_allclose(port.normal, expected.normal, atol=1e-12)
        assert (port.distance_m, port.thickness_m, port.n_water) == (0.02, 0.006, 1.333)
        assert read_json(folder / "sample.json")["params"] == dict(sample.params)


def test_refraction_free_image_is_the_synthesis_of_the_raw_image(tilt_run):
    sample = Dataset(tilt_run.out_dir)[2]
    meta = sample.meta
    from lfrefract import LightFieldCamera

    warp = build_warp_map(
        LightFieldCamera.from_dict(meta["camera"]),
        sample.port,
        output=PinholeCamera.from_dict(meta["ideal"]),
        options=SynthesisOptions(),
    )
    expected = np.where(warp.filled[..., None], warp.apply(sample.raw), np.nan)  # NaN: no value
    assert np.array_equal(sample.refraction_free, expected, equal_nan=True)
    assert np.array_equal(sample.coverage, warp.coverage.astype(np.float32))
    assert sample.refraction_free.shape == sample.ideal.shape
    # The filled classes: 2 exact, 1 approximated, 0 empty (where the image is NaN).
    filled = sample.filled
    assert filled.dtype == np.uint8
    assert np.array_equal(filled == 2, warp.exact & warp.filled)
    assert np.array_equal(filled == 1, warp.filled & ~warp.exact)
    assert np.array_equal(filled == 0, np.all(np.isnan(sample.refraction_free), axis=2))
    empty = [np.count_nonzero(s.filled == 0) for s in Dataset(tilt_run.out_dir)]
    assert 0 < max(empty) < filled.size  # the steepest tilts leave pixels without any captured ray


def test_loader_gives_arrays_and_parameters_in_index_order(tilt_run):
    data = Dataset(tilt_run.out_dir)
    samples = expand(load_spec("tilt"))
    assert len(data) == 4
    assert data.ids == tuple(s.id for s in samples)
    assert data.missing == ()
    assert [s.index for s in data] == [0, 1, 2, 3]
    assert data[-1] is data["s000003"]
    for got, want in zip(data, samples, strict=True):
        assert (got.seed, dict(got.params)) == (want.seed, dict(want.params))
        raw, ideal, depth = got.raw, got.ideal, got.depth_m
        assert raw.shape == (360, 480, 3)
        assert raw.dtype == ideal.dtype == depth.dtype == np.float32
        assert ideal.shape == (*depth.shape, 3)
        assert np.all(depth[np.isfinite(depth)] > 0.0)
        assert got.views_dir is None
    assert data.params_table()["port.tilt_x_deg"] == [0.0, 10.0, 20.0, 30.0]
    with pytest.raises(KeyError, match="s000009"):
        data["s000009"]


def test_check_reports_corrupt_missing_and_extra_files(tilt_run, tmp_path):
    root = tmp_path / "copy"
    shutil.copytree(tilt_run.out_dir, root)
    assert check_dataset(root).ok
    raw = root / "s000001" / "raw.exr"
    data = bytearray(raw.read_bytes())
    data[len(data) // 2] ^= 0xFF  # one flipped byte, same size
    raw.write_bytes(bytes(data))
    (root / "s000002" / "ideal.exr").unlink()
    shutil.rmtree(root / "s000003")
    (root / "s000000" / "notes.txt").write_text("hello")
    report = check_dataset(root)
    assert not report.ok
    assert report.verified == 0
    assert [(p.id, p.kind) for p in report.problems] == [
        ("s000000", "corrupt"),
        ("s000001", "corrupt"),
        ("s000002", "missing"),
        ("s000003", "missing"),
    ]
    assert "notes.txt" in report.problems[0].detail
    assert "raw.exr: SHA-256" in report.problems[1].detail
    assert "ideal.exr" in report.problems[2].detail
    # Sizes alone miss the flipped byte.
    assert [p.id for p in check_dataset(root, hashes=False).problems] == ["s000000", "s000002", "s000003"]
    proc = subprocess.run(
        [sys.executable, "-m", "simulator.cli", "dataset", "check", str(root)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert proc.returncode == 1
    assert "s000001: corrupt: raw.exr: SHA-256" in proc.stdout
    assert "4 samples, 0 verified; 2 missing, 2 corrupt, 0 stale, 0 failed, 0 not run" in proc.stdout


def test_resume_with_an_edited_spec_is_refused(tilt_run, tmp_path):
    root = tmp_path / "copy"
    shutil.copytree(tilt_run.out_dir, root)
    before = sorted((p.name, p.stat().st_mtime_ns) for p in root.rglob("*"))
    edited = json.loads(json.dumps(read_json(tilt_run.out_dir / "dataset.json")["spec"]))
    edited["sweep"]["seed"] += 1
    with pytest.raises(DatasetMismatchError, match="holds a dataset of another spec"):
        run_dataset(parse_spec(edited, base_dir=tmp_path), root, progress=False)
    with pytest.raises(DatasetMismatchError, match="is not an lfsim dataset"):
        run_dataset("tilt", tmp_path, progress=False)  # tmp_path holds 'copy/', not a dataset
    assert sorted((p.name, p.stat().st_mtime_ns) for p in root.rglob("*")) == before


def _live_in_group(pgid: int) -> list[int]:
    """Processes of process group ``pgid`` that are not zombies."""
    live = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except (FileNotFoundError, ProcessLookupError):
            continue
        if int(fields[2]) == pgid and fields[0] != "Z":
            live.append(int(stat.parent.name))
    return live


def test_resume_after_a_kill_completes_the_same_dataset(tilt_run, tmp_path):
    """A real ``lfsim dataset run`` killed with SIGKILL after its first record; run again; the
    dataset matches the uninterrupted one (other worker count) file for file, timings aside."""
    root = tmp_path / "killed"
    manifest = root / "manifest.jsonl"
    proc = _lfsim("dataset", "run", "tilt", "--out", str(root), "--workers", "1", "--quiet", start_new_session=True)
    deadline = time.monotonic() + WAIT_S
    done_at_kill = 0
    while time.monotonic() < deadline and proc.poll() is None:
        if manifest.is_file() and (done_at_kill := manifest.read_bytes().count(b"\n")) >= 1:
            os.kill(proc.pid, signal.SIGKILL)
            break
        time.sleep(0.01)
    _, err = proc.communicate(timeout=60)  # returns once the workers, which share its pipes, are gone too
    assert proc.returncode == -signal.SIGKILL, err
    assert 1 <= done_at_kill < 4  # killed mid-run
    # The workers die with the driver (Dask's nanny watches its parent): none keeps writing.
    deadline = time.monotonic() + 30
    while _live_in_group(proc.pid) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert _live_in_group(proc.pid) == []
    # Also as if killed while appending a record and while a worker staged a folder.
    data = manifest.read_bytes()
    manifest.write_bytes(data[: len(data) - 40])
    (root / ".s000003.x1y2z3.partial").mkdir()
    (root / ".s000003.x1y2z3.partial" / "raw.exr").write_bytes(b"half")
    assert check_dataset(root).count("not run") >= 1

    again = _lfsim("dataset", "run", "tilt", "--out", str(root), "--workers", "1", "--quiet")
    out, err = again.communicate(timeout=WAIT_S)
    assert again.returncode == 0, err
    assert "4 samples;" in out

    report = check_dataset(root)
    assert report.ok, report.problems
    assert report.leftovers == ()
    records = _records(root)
    assert all(r["status"] == "done" for r in records)
    assert sorted(r["id"] for r in records) == ["s000000", "s000001", "s000002", "s000003"]  # none twice
    reference = {r["id"]: r for r in _records(tilt_run.out_dir)}
    for record in records:
        ref = reference[record["id"]]
        assert (record["index"], record["seed"], record["hash"], record["params"]) == (
            ref["index"], ref["seed"], ref["hash"], ref["params"],
        )  # fmt: skip
        assert set(record["files"]) == set(ref["files"])
        for name in set(record["files"]) - TIMED_FILES:
            assert record["files"][name] == ref["files"][name], (record["id"], name)
    resumed, uninterrupted = Dataset(root), Dataset(tilt_run.out_dir)
    assert resumed.ids == uninterrupted.ids
    for a, b in zip(resumed, uninterrupted, strict=True):
        assert dict(a.params) == dict(b.params)
        for name in ARRAYS:
            assert np.array_equal(getattr(a, name), getattr(b, name), equal_nan=True), (a.id, name)


def test_end_processes_leaves_no_worker_running_even_one_that_ignores_signals():
    """A Ctrl-C'd run exited while a worker of its cluster was still ending (seen under load in CI):
    closing the cluster returns once the nannies report. The driver now waits for its workers and kills
    the ones still running when the time is up, so none outlives it."""
    import psutil

    from simulator.dataset.run import end_processes

    code = (
        "import signal, time; signal.signal(signal.SIGTERM, signal.SIG_IGN); "
        "signal.signal(signal.SIGINT, signal.SIG_IGN); time.sleep(60)"
    )
    stubborn = subprocess.Popen([sys.executable, "-c", code])
    handles = [psutil.Process(stubborn.pid)]
    t0 = time.monotonic()
    end_processes(handles, timeout_s=0.5)
    assert 0.5 <= time.monotonic() - t0 < 10  # waited the time given, then killed
    assert not handles[0].is_running()  # killed and reaped
    stubborn.wait(timeout=5)  # settles the Popen (psutil reaped the process)


GOOD_OBJ = "v -0.05 -0.05 0\nv 0.05 -0.05 0\nv 0 0.05 0\nf 1 2 3\n"


def test_ctrl_c_ends_a_dataset_run_in_one_line_and_leaves_nothing_half_written(tilt_run, tmp_path):
    """Ctrl-C on ``lfsim dataset run`` gave a KeyboardInterrupt traceback (and the workers' own). Now,
    with SIGINT sent to the whole process group as a terminal does: one line, exit 130, the workers
    stopped, no sample's staging folder left; the next run completes the dataset."""
    root = tmp_path / "interrupted"
    manifest = root / "manifest.jsonl"
    proc = _lfsim("dataset", "run", "tilt", "--out", str(root), "--workers", "1", "--quiet", start_new_session=True)
    deadline = time.monotonic() + WAIT_S
    while time.monotonic() < deadline and proc.poll() is None:
        if manifest.is_file() and manifest.read_bytes().count(b"\n") >= 1:
            os.killpg(proc.pid, signal.SIGINT)
            break
        time.sleep(0.01)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert err.strip().splitlines() == ["lfsim: interrupted; unfinished outputs removed; run again to resume"], err
    assert _live_in_group(proc.pid) == []
    assert sorted(p.name for p in root.iterdir() if p.name.startswith(".")) == []
    assert check_dataset(root).leftovers == ()

    again = _lfsim("dataset", "run", "tilt", "--out", str(root), "--workers", "1", "--quiet")
    _, err = again.communicate(timeout=WAIT_S)
    assert again.returncode == 0, err
    report = check_dataset(root)
    assert report.ok, report.problems
    assert sorted(r["id"] for r in latest_done(root)) == ["s000000", "s000001", "s000002", "s000003"]


def latest_done(root: Path) -> list[dict]:
    """The done records of ``root``'s manifest, one per sample (the latest)."""
    latest = {r["id"]: r for r in _records(root)}
    return [r for r in latest.values() if r["status"] == "done"]


def test_failed_samples_are_recorded_then_retried_by_the_next_run(tmp_path, scheduler):
    """A mesh file that exists but cannot be read passes the spec checks and fails at render time:
    retried, then recorded as failed, reported, and tried again by a later run (on an existing
    Dask cluster, given by its scheduler's address). Fixing the mesh makes another sample (its
    content is in the sample's hash): a resume is then refused, a new folder gets every sample."""
    (tmp_path / "good.obj").write_text(GOOD_OBJ)
    (tmp_path / "bad.obj").write_text("v 1 2\nf 1 2 9\n")
    (tmp_path / "scene.toml").write_text(
        """
[camera]
preset = "tiny"
[port]
distance_m = 0.02
thickness_m = 0.004
tilt_x_deg = 10.0
[render]
spp = 2
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
path = "good.obj"
position_m = [0.0, 0.0, 0.4]
"""
    )
    (tmp_path / "spec.toml").write_text(
        '[sweep]\nname = "meshes"\nseed = 5\nscene = "scene.toml"\n[grid]\n"object.1.path" = ["good.obj", "bad.obj"]\n'
    )
    root = tmp_path / "out"
    report = run_dataset(tmp_path / "spec.toml", root, scheduler=scheduler, retries=1, progress=False)
    assert not report.ok
    assert report.rendered == 1
    ((sid, error, attempts),) = report.failed
    assert (sid, attempts) == ("s000001", 2)
    assert "FileFormatError" in error
    assert "cannot load" in error
    assert "bad.obj" in error
    records = {r["id"]: r for r in _records(root)}
    assert records["s000001"]["status"] == "failed"
    assert records["s000001"]["attempts"] == 2
    assert "cannot load" in records["s000001"]["error"]
    assert records["s000001"]["params"] == {"object.1.path": "bad.obj"}
    assert not (root / "s000001").exists()
    check = check_dataset(root)
    assert [(p.id, p.kind) for p in check.problems] == [("s000001", "failed")]
    assert "after 2 attempt(s)" in check.problems[0].detail
    data = Dataset(root)
    assert (data.ids, data.missing) == (("s000000",), ("s000001",))

    again = run_dataset(tmp_path / "spec.toml", root, scheduler=scheduler, retries=0, progress=False)
    assert (again.ok, again.skipped, again.rendered) == (False, 1, 0)
    assert [(sid, attempts) for sid, _, attempts in again.failed] == [("s000001", 1)]
    assert (_records(root)[-1]["id"], _records(root)[-1]["status"]) == ("s000001", "failed")

    shutil.copy(tmp_path / "good.obj", tmp_path / "bad.obj")  # the mesh is fixed: another sample
    before = sorted((str(p), p.stat().st_mtime_ns) for p in root.rglob("*"))
    with pytest.raises(DatasetMismatchError, match=r"1 of 2 changed, e.g. \['s000001'\]; input file\(s\) edited"):
        run_dataset(tmp_path / "spec.toml", root, scheduler=scheduler, retries=0, progress=False)
    assert sorted((str(p), p.stat().st_mtime_ns) for p in root.rglob("*")) == before
    fixed = run_dataset(tmp_path / "spec.toml", tmp_path / "fixed", scheduler=scheduler, retries=0, progress=False)
    assert (fixed.ok, fixed.skipped, fixed.rendered) == (True, 0, 2)
    assert check_dataset(tmp_path / "fixed").ok
    assert Dataset(tmp_path / "fixed").ids == ("s000000", "s000001")


def test_views_output_is_the_view_stack_of_the_raw_image(tmp_path, scheduler):
    from lfrefract import LightFieldCamera
    from lfrefract.formats.viewstack import view_file_names
    from lfrefract.synthesis.views import subaperture_stack

    data = {
        "sweep": {"name": "views", "seed": 3, "scene": "default", "spp": 2, "outputs": ["views"], "views": {"grid": 3}},
        "grid": {"port.tilt_x_deg": [15.0]},
    }
    root = tmp_path / "out"
    assert run_dataset(parse_spec(data), root, scheduler=scheduler, progress=False).ok
    assert check_dataset(root).ok
    (sample,) = Dataset(root)
    assert sample.refraction_free is None
    truth_files = ["gt_disp_lowres.pfm", "gt_disparity.npz", *(f"gt_disp_lowres_Cam{i:03d}.pfm" for i in range(9))]
    expected_files = [*view_file_names(3, "png"), *VIEW_STACK_FILES, *truth_files]
    assert sorted(p.name for p in sample.views_dir.iterdir()) == sorted(expected_files)
    # The ground-truth disparity is simulator.view_truth's for the sample's scene (tested there).
    from lfrefract.formats.pfm import read_pfm
    from simulator import backend
    from simulator.scene import build_scene
    from simulator.view_truth import view_stack_disparity

    config = expand(parse_spec(data))[0].config
    mi = backend.load_mitsuba()
    truth = view_stack_disparity(
        mi, build_scene(mi, config, port_geometry=False), config, PinholeCamera.from_dict(sample.meta["ideal"]), grid=3
    )
    dx, dy = sample.view_disparity
    assert np.array_equal(dx, truth.disparity_x_px, equal_nan=True)
    assert np.array_equal(dy, truth.disparity_y_px, equal_nan=True)
    assert np.array_equal(read_pfm(sample.views_dir / "gt_disp_lowres.pfm"), dx[1, 1], equal_nan=True)
    assert np.array_equal(read_pfm(sample.views_dir / "gt_disp_lowres_Cam005.pfm"), dx[1, 2], equal_nan=True)
    assert np.nanmedian(dx) > 0.0  # nearer than the focus at infinity: positive, as the benchmark's
    stack = sample.view_stack
    meta = sample.meta
    expected = subaperture_stack(
        LightFieldCamera.from_dict(meta["camera"]), sample.raw, grid=3, output=PinholeCamera.from_dict(meta["ideal"])
    )
    assert stack.grid == 3
    assert np.array_equal(stack.views, expected.views, equal_nan=True)
    assert read_json(sample.path / "sample.json")["views"]["baseline_m"] == expected.baseline_m


def test_water_sweep_reaches_the_render(tmp_path, scheduler):
    """Swept ``water.*`` keys: salinity and temperature set the port's index (port.txt), and the
    absorption coefficient makes a participating medium that darkens the image."""
    from lfrefract import seawater_index

    data = {
        "sweep": {"name": "water", "seed": 4, "scene": "default", "spp": 2, "unset": ["port.n_water"]},
        "grid": {"water.absorption_per_m": [0.0, 1.0], "water.salinity_psu": [35.0], "water.temperature_c": [15.0]},
    }
    root = tmp_path / "out"
    assert run_dataset(parse_spec(data), root, scheduler=scheduler, progress=False).ok
    clear, turbid = Dataset(root)
    n_water = seawater_index(salinity_psu=35.0, temperature_c=15.0)
    assert clear.port.n_water == turbid.port.n_water == pytest.approx(n_water, abs=1e-12)
    assert turbid.meta["render"]["medium"] is not None
    assert turbid.raw.mean() / clear.raw.mean() < DATASET_TURBID_OVER_CLEAR_MAX


def test_a_local_cluster_starts_while_another_holds_the_dask_port():
    """Two clusters on one machine (another run, another test worker): the second once took the
    scheduler's web port 8787 too, warned that it was in use, and failed under warnings-as-errors
    (12 errors of a CI run whose two test workers each started one)."""
    import contextlib
    import socket

    from simulator.dataset.run import _dask_client

    with socket.socket() as held:
        with contextlib.suppress(OSError):  # held by another process already: the same case
            held.bind(("", 8787))
        with _dask_client(1, None) as client:
            assert client.submit(sum, [1, 2]).result() == 3
