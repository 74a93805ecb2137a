"""lfrefract._memory: the available memory, the refusal of work that cannot fit, and the estimates of
the warp map, the naive views and the view stacks against what tracemalloc measures."""

from __future__ import annotations

import os
import re
import tracemalloc

import numpy as np
import pytest

import lfrefract._memory as memory
from lfrefract import FlatPort, ParameterError, PinholeCamera, camera_preset, virtual_camera_for
from lfrefract.synthesis.views import naive_view, naive_view_bytes, subaperture_stack, view_stack_bytes
from lfrefract.synthesis.warp_map import BLOCK_PIXELS, SynthesisOptions, build_warp_map
from tests.tolerances import MEMORY_ESTIMATE_RATIO_MAX, MEMORY_ESTIMATE_RATIO_MIN

TINY = camera_preset("tiny")
PORT = FlatPort.from_degrees(distance_m=0.03, thickness_m=0.005, tilt_x_deg=20.0)


def test_available_memory_is_memavailable_else_the_free_pages(tmp_path, monkeypatch):
    meminfo = tmp_path / "meminfo"
    meminfo.write_text("MemTotal:       24683584 kB\nMemFree:  100 kB\nMemAvailable:   123456 kB\n")
    monkeypatch.setattr(memory, "MEMINFO", meminfo)
    assert memory.available_memory() == (123456 * 1024, f"MemAvailable in {meminfo}")
    meminfo.write_text("MemTotal:       24683584 kB\n")  # kernels before 3.14
    nbytes, source = memory.available_memory()
    assert source == "free physical pages (sysconf)"
    assert nbytes == os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    meminfo.unlink()
    assert memory.available_memory()[1] == "free physical pages (sysconf)"


def test_require_memory_refuses_what_exceeds_the_available_memory_naming_both(monkeypatch):
    monkeypatch.setattr(memory, "available_memory", lambda: (16 * 2**30, "MemAvailable in /proc/meminfo"))
    memory.require_memory("a thing", 16 * 2**30)
    with pytest.raises(
        ParameterError,
        match=re.escape(
            "a thing needs about 71.1 GiB of memory (76335840000 bytes, estimated), more than the 16 GiB "
            "available (MemAvailable in /proc/meminfo)"
        ),
    ):
        memory.require_memory("a thing", 76_335_840_000)


def test_format_bytes():
    assert memory.format_bytes(512) == "512 B"
    assert memory.format_bytes(1536) == "1.5 KiB"
    assert memory.format_bytes(71.1 * 2**30) == "71.1 GiB"
    assert memory.format_bytes(3 * 2**50) == "3 PiB"
    assert memory.format_bytes(5000 * 2**50) == "5e+03 PiB"


def _peak_bytes(work) -> int:
    tracemalloc.start()
    try:
        work()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def _scaled_output(scale: int) -> PinholeCamera:
    base = virtual_camera_for(TINY)
    w, h = base.width_px * scale, base.height_px * scale
    return PinholeCamera(focal_px=base.focal_px * scale, cx_px=(w - 1) / 2, cy_px=(h - 1) / 2, width_px=w, height_px=h)


@pytest.mark.parametrize(
    ("scale", "supersample", "k", "search"),
    [(1, 2, 32, "auto"), (2, 3, 16, "auto"), (1, 1, 4, "kdtree")],
    ids=["6k-px-s2-k32", "25k-px-s3-k16", "6k-px-kdtree"],
)
def test_the_warp_map_estimate_is_within_a_factor_of_two_of_the_measured_peak(scale, supersample, k, search):
    output = _scaled_output(scale)
    options = SynthesisOptions(k=k, supersample=supersample, search=search)
    raw = np.ones((TINY.sensor.height_px, TINY.sensor.width_px, 3), dtype=np.float32)
    build_warp_map(TINY, PORT, output=virtual_camera_for(TINY), options=options, workers=2)  # compiled, cached
    measured = _peak_bytes(lambda: build_warp_map(TINY, PORT, output=output, options=options, workers=2).apply(raw))
    estimate = memory.warp_map_bytes(
        output_pixels=output.width_px * output.height_px,
        raw_pixels=raw.shape[0] * raw.shape[1],
        channels=3,
        supersample=supersample,
        k=k,
        kdtree=search == "kdtree",
        workers=2,
        block_pixels=BLOCK_PIXELS,
    )
    assert MEMORY_ESTIMATE_RATIO_MIN <= measured / estimate <= MEMORY_ESTIMATE_RATIO_MAX, (measured, estimate)


@pytest.mark.parametrize("kind", ["central", "full"])
def test_the_naive_view_estimate_is_within_a_factor_of_two_of_the_measured_peak(kind):
    output = _scaled_output(4)
    raw = np.ones((TINY.sensor.height_px, TINY.sensor.width_px, 3), dtype=np.float32)
    measured = _peak_bytes(lambda: naive_view(TINY, raw, output=output, kind=kind))
    estimate = naive_view_bytes(TINY, output, kind=kind, channels=3)
    assert MEMORY_ESTIMATE_RATIO_MIN <= measured / estimate <= MEMORY_ESTIMATE_RATIO_MAX, (measured, estimate)


@pytest.mark.parametrize("grid", [3, 9])
def test_the_view_stack_estimate_is_within_a_factor_of_two_of_the_measured_peak(grid):
    output = _scaled_output(2)
    raw = np.ones((TINY.sensor.height_px, TINY.sensor.width_px, 3), dtype=np.float32)
    measured = _peak_bytes(lambda: subaperture_stack(TINY, raw, grid=grid, output=output))
    estimate = view_stack_bytes(TINY, output, grid=grid, channels=3)
    assert MEMORY_ESTIMATE_RATIO_MIN <= measured / estimate <= MEMORY_ESTIMATE_RATIO_MAX, (measured, estimate)


_DEPTH_AWARE_PEAK = """
import numpy as np
from pathlib import Path
from lfrefract import FlatPort, camera_preset
from lfrefract._memory import available_cpus, depth_aware_bytes
from lfrefract.synthesis.depth_aware import DepthAwareSynthesis, render_chunks, trace_scene_rays
from lfrefract.synthesis.warp_map import build_warp_map

def status_kb(key):
    line = next(x for x in Path("/proc/self/status").read_text().splitlines() if x.startswith(key + ":"))
    return int(line.split()[1])

port = FlatPort.from_degrees(tilt_x_deg=25.0, tilt_y_deg=10.0, distance_m=0.04, thickness_m=0.004)
tiny = camera_preset("tiny")  # compiles (or loads) the kernels first: their memory is not the estimate's
DepthAwareSynthesis(warp=build_warp_map(tiny, port), rays=trace_scene_rays(tiny, port)).apply(
    np.ones((tiny.sensor.height_px, tiny.sensor.width_px, 3), np.float32))
camera = camera_preset("tiny-2x")
warp = build_warp_map(camera, port)
raw = np.random.default_rng(0).random((camera.sensor.height_px, camera.sensor.width_px, 3), dtype=np.float32)
before = status_kb("VmRSS")
Path("/proc/self/clear_refs").write_text("5")  # the peak (VmHWM) starts again from the resident size
DepthAwareSynthesis(warp=warp, rays=trace_scene_rays(camera, port)).apply(raw)
grown = (status_kb("VmHWM") - before) * 1024
o = warp.output
print(grown / depth_aware_bytes(raw_pixels=raw.shape[0] * raw.shape[1], output_pixels=o.width_px * o.height_px,
      channels=3, depth_steps=48, threads=available_cpus(), render_chunks=render_chunks()))
"""


def test_the_depth_aware_estimate_errs_high_by_at_most_the_bound():
    """Numba allocates the sweep's and the render's accumulators, which tracemalloc does not see: the
    growth of the peak resident memory (Linux's VmHWM, reset before the work) in a fresh process stands
    in (measured 0.59 on tiny-2x, 0.70 with the kernels compiled afresh). Before the reset, a first
    compilation of the kernels in the same process had set a peak that the work never reached (ratio 0
    in a fresh clone's CI run)."""
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-c", _DEPTH_AWARE_PEAK], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    ratio = float(done.stdout.strip().splitlines()[-1])
    assert MEMORY_ESTIMATE_RATIO_MIN <= ratio <= MEMORY_ESTIMATE_RATIO_MAX, ratio
