"""Render one sample into its folder: the task that a worker runs.

The folder (named by the sample id) is assembled in a staging folder beside it and renamed into
place only when every file is written, so it exists complete or not at all. It holds the files
of ``lfsim render`` (:func:`simulator.job.render_job`: ``raw.exr``, ``ideal.exr``, ``depth.exr``,
``lenses.npz``, ``meta.json``), ``sample.json`` (id, seed, swept values, hash), ``port.txt``
(the flat-port layout of Refractive COLMAP / calibmar) when the scene has a port, and the
optional outputs: the refraction-free image with its coverage and ``filled`` classes, ``views/``
(the sub-aperture view stack), ``previews/``, the ideal image's surface labels (normals, instance
ids) and the raw pixels' truth (depth along each pixel's true ray, lenslet). Images are written in
the dataset's format (:mod:`simulator.dataset.images`) and listed in ``sample.json``'s ``images``.
"""

from __future__ import annotations

import os
import socket
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from lfrefract import PinholeCamera
from lfrefract.errors import FileFormatError
from lfrefract.formats.capture import RAW_NAME, SIDECAR_NAME
from lfrefract.formats.exr import read_exr
from lfrefract.formats.flatport import write_flat_port
from lfrefract.formats.jsonio import write_json
from lfrefract.formats.outputs import staged_directory
from lfrefract.synthesis.warp_map import (
    FILLED_APPROXIMATED,
    FILLED_EMPTY,
    FILLED_EXACT,
    SynthesisOptions,
    build_warp_map,
)
from simulator.config import SceneConfig
from simulator.dataset.images import exr_entry, write_image
from simulator.dataset.spec import ViewOptions

__all__ = ["SampleTask", "render_sample"]

#: Files of a sample folder besides those of ``lfsim render``.
SAMPLE_FILE = "sample.json"
PORT_FILE = "port.txt"
REFRACTION_FREE_FILE = "refraction_free.exr"
COVERAGE_FILE = "refraction_free.coverage.exr"
VIEWS_DIR = "views"

#: The images of ``lfsim render`` by their name in ``sample.json``'s ``images`` (and the loader's):
#: file stem and role.
RENDER_IMAGES = {"raw": ("raw", "raw"), "ideal": ("ideal", "ideal"), "depth_m": ("depth", "depth")}


_threads_set: int | None = None
_digests = None  # this worker process's DigestCache (a mesh that many samples use is hashed once)


@dataclass(frozen=True, kw_only=True)
class SampleTask:
    """Everything a worker needs to render one sample (plain, picklable data).

    Attributes
    ----------
    id, index, seed, hash : str, int, int, str
        As in :class:`simulator.dataset.spec.SweepSample`.
    params : dict
        The swept values.
    config : SceneConfig
        The validated scene (its render seed is ``seed``).
    dataset_dir : str
        Absolute path of the dataset folder (on a cluster: the same path on every worker).
    outputs : tuple of str
        Extras among :data:`simulator.dataset.spec.OUTPUTS`.
    synthesis : SynthesisOptions or None
        Options of the refraction-free image.
    views : ViewOptions
        Options of the view stack (checked when the spec was parsed).
    image_format : {"exr", "npz", "png16"}
        File format of the sample's images (:mod:`simulator.dataset.images`).
    inputs : dict
        The files the scene reads (mesh files): absolute path -> SHA-256 (hex) when the sample
        was planned. The render fails if one differs once the scene has been read.
    threads : int or None
        Dr.Jit and numba threads of the worker process (None: their defaults, every core).
    variant : str or None
        Mitsuba variant (None: CUDA if present, else LLVM).
    """

    id: str
    index: int
    seed: int
    hash: str
    params: dict
    config: SceneConfig
    dataset_dir: str
    outputs: tuple[str, ...] = ()
    synthesis: SynthesisOptions | None = None
    views: ViewOptions = field(default_factory=lambda: ViewOptions())
    image_format: str = "exr"
    inputs: dict = field(default_factory=dict)
    threads: int | None = None
    variant: str | None = None


def _limit_threads(threads: int | None, variant: str | None) -> None:
    """Load Mitsuba in this process and cap Dr.Jit's and numba's thread pools (once per process)."""
    global _threads_set
    from simulator import backend

    backend.load_mitsuba(variant)
    if threads is None or _threads_set == threads:
        return
    import drjit as dr
    import numba

    dr.set_thread_count(threads)
    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    _threads_set = threads


def render_sample(task: SampleTask) -> dict:
    """Render ``task``'s sample into ``dataset_dir / id`` and describe what was written.

    Parameters
    ----------
    task : SampleTask

    Returns
    -------
    dict
        The sample's manifest record without ``attempts`` and ``finished_at`` (the driver adds
        them): id, index, seed, hash, params, ``status = "done"``, ``files`` (relative path ->
        bytes and SHA-256), ``seconds`` (render, raw, ideal, refraction_free, views, total) and
        ``worker`` (host and process id).

    Raises
    ------
    FileFormatError
        If an input file (a mesh) is not what was planned (edited since): nothing is written.
    Exception
        Whatever the render raises (a mesh file that cannot be read, ...); nothing is left in
        the dataset folder then.
    """
    from simulator.dataset.manifest import folder_files
    from simulator.job import render_job

    start = time.perf_counter()
    _limit_threads(task.threads, task.variant)
    config = task.config
    seconds: dict[str, float] = {}
    out = Path(task.dataset_dir) / task.id
    with staged_directory(out, kind="lfsim.dataset.sample", overwrite=True) as stage:
        t0 = time.perf_counter()
        result = render_job(
            config,
            stage,
            variant=task.variant,
            progress=False,
            write_previews="previews" in task.outputs,
        )
        seconds["render"] = time.perf_counter() - t0
        _check_inputs(task)  # once the render has read them
        seconds["raw"], seconds["ideal"] = result.raw_seconds, result.ideal_seconds
        extras: dict[str, Any] = {}
        if config.port is not None:
            write_flat_port(stage / PORT_FILE, config.port)
        needs_raw = "refraction_free" in task.outputs or "views" in task.outputs
        raw = read_exr(stage / RAW_NAME, role="raw") if needs_raw else None
        images = _render_images(stage, result.metadata, task.image_format, raw=raw)
        if "refraction_free" in task.outputs:
            t0 = time.perf_counter()
            extras["refraction_free"] = _refraction_free(stage, config, raw, result.metadata, task, images)
            seconds["refraction_free"] = time.perf_counter() - t0
        traced = _PortFreeScene(config, task.variant)  # built once, if a label needs it
        if "views" in task.outputs:
            t0 = time.perf_counter()
            extras["views"] = _views(stage, config, raw, result.metadata, task, traced)
            seconds["views"] = time.perf_counter() - t0
        if "labels" in task.outputs or "raw_truth" in task.outputs:
            t0 = time.perf_counter()
            extras |= _truth_labels(stage, config, result.metadata, task, images, traced)
            seconds["labels"] = time.perf_counter() - t0
        write_json(
            stage / SAMPLE_FILE,
            {
                "kind": "lfsim.dataset.sample",
                "id": task.id,
                "index": task.index,
                "seed": task.seed,
                "hash": task.hash,
                "params": task.params,
                "outputs": list(task.outputs),
                "image_format": task.image_format,
                "images": images,
                **extras,
            },
        )
    files = folder_files(out)  # after the rename: the output's manifest is among them
    seconds["total"] = time.perf_counter() - start
    return {
        "id": task.id,
        "index": task.index,
        "seed": task.seed,
        "hash": task.hash,
        "params": task.params,
        "status": "done",
        "files": files,
        "seconds": seconds,
        "worker": f"{socket.gethostname()}:{os.getpid()}",
    }


def _check_inputs(task: SampleTask) -> None:
    """Raise unless every input file of ``task`` still has its planned SHA-256."""
    global _digests
    from simulator.dataset.manifest import DigestCache

    if _digests is None:
        _digests = DigestCache()
    for path, planned in task.inputs.items():
        _, sha = _digests.digest(path)
        if sha != planned:
            raise FileFormatError(
                f"sample {task.id}: input file {path!r} changed after the run was planned (SHA-256 {sha}, planned "
                f"{planned}): the sample is not written; the dataset would mix old and new files"
            )


def _render_images(stage: Path, meta: dict, image_format: str, *, raw=None) -> dict:
    """The entries of ``lfsim render``'s images; in another format than EXR they are converted
    (the EXR files removed, ``meta.json``'s ``files`` naming the new ones). ``raw``: the raw image
    if already read (not read again)."""
    images = {}
    for name, (stem, role) in RENDER_IMAGES.items():
        path = stage / f"{stem}.exr"
        if image_format == "exr":
            images[name] = exr_entry(path, role=role)
            continue
        image = raw if name == "raw" and raw is not None else read_exr(path, role=role)
        images[name] = write_image(stage, stem, image, image_format=image_format, role=role)
        path.unlink()
    if image_format != "exr":
        files = dict(meta["files"]) | {stem: images[name]["file"] for name, (stem, _) in RENDER_IMAGES.items()}
        write_json(stage / SIDECAR_NAME, meta | {"files": files})
    return images


def _refraction_free(stage: Path, config: SceneConfig, raw, meta: dict, task: SampleTask, images: dict) -> dict:
    """Synthesize the refraction-free image (the ideal image's geometry), its coverage and its
    ``filled`` classes; NaN where no captured ray was found (the project's "no value")."""
    options = task.synthesis if task.synthesis is not None else SynthesisOptions()
    output = PinholeCamera.from_dict(meta["ideal"])
    warp = build_warp_map(config.camera, config.port, output=output, options=options, workers=task.threads)
    image = warp.apply(raw)
    image[~warp.filled] = np.nan
    fmt = task.image_format
    images["refraction_free"] = write_image(stage, "refraction_free", image, image_format=fmt, role="refraction_free")
    coverage = warp.coverage.astype(np.float32)
    images["coverage"] = write_image(stage, "refraction_free.coverage", coverage, image_format=fmt, role="coverage")
    classes = warp.filled_classes
    images["filled"] = write_image(stage, "refraction_free.filled", classes, image_format=fmt, role="filled")
    return {
        "files": {name: images[name]["file"] for name in ("refraction_free", "coverage", "filled")},
        "filled_classes": {"empty": FILLED_EMPTY, "approximated": FILLED_APPROXIMATED, "exact": FILLED_EXACT},
        "K": warp.output.K.tolist(),
        "options": options.to_dict(),
        "map_key": warp.key,
        "exact_fraction": float(warp.exact.mean()),
        "filled_fraction": float(warp.filled.mean()),
    }


class _PortFreeScene:
    """The sample's Mitsuba scene without the port, in which the labels are traced; built on first use."""

    def __init__(self, config: SceneConfig, variant: str | None) -> None:
        self._config, self._variant = config, variant
        self._built: tuple[Any, Any] | None = None

    def get(self) -> tuple[Any, Any]:
        """``(mi, scene)``."""
        if self._built is None:
            from simulator import backend
            from simulator.scene import build_scene

            mi = backend.load_mitsuba(self._variant)
            self._built = (mi, build_scene(mi, self._config, port_geometry=False))
        return self._built


def _truth_labels(
    stage: Path, config: SceneConfig, meta: dict, task: SampleTask, images: dict, traced: _PortFreeScene
) -> dict:
    """The ideal image's surface labels (``"labels"``: ``normal_cam``, ``instance_id``) and the raw
    pixels' truth (``"raw_truth"``: ``raw_depth_m``, ``lens_index``), traced in the port-free scene
    (:mod:`simulator.groundtruth`); returns the extras for ``sample.json``."""
    from simulator import groundtruth

    mi, scene = traced.get()
    fmt = task.image_format
    extras: dict[str, Any] = {}
    if "labels" in task.outputs:
        labels = groundtruth.surface_labels(mi, scene, config, PinholeCamera.from_dict(meta["ideal"]))
        images["normal_cam"] = write_image(stage, "normal_cam", labels.normal_cam, image_format=fmt, role="normal_cam")
        images["instance_id"] = write_image(
            stage, "instance_id", labels.instance_id, image_format=fmt, role="instance_id", no_value=0
        )
        extras["instances"] = groundtruth.instance_table(config)
    if "raw_truth" in task.outputs:
        truth = groundtruth.raw_pixel_truth(mi, scene, config)
        images["raw_depth_m"] = write_image(stage, "raw_depth", truth.depth_m, image_format=fmt, role="raw_depth")
        images["lens_index"] = write_image(
            stage, "lens_index", truth.lens_row, image_format=fmt, role="lens_index", no_value=-1
        )
    return extras


def _views(stage: Path, config: SceneConfig, raw, meta: dict, task: SampleTask, traced: _PortFreeScene) -> dict:
    """The sub-aperture view stack of the raw image (the ideal image's geometry), under ``views/``,
    with its ground-truth disparity (:func:`simulator.view_truth.view_stack_disparity`) for a
    thin-lens camera; a real lens's views are not pinholes, and get none (said in the extras)."""
    from lfrefract.formats.viewstack import write_view_stack
    from lfrefract.synthesis.views import subaperture_stack
    from simulator.view_truth import view_stack_disparity

    views = task.views
    output = PinholeCamera.from_dict(meta["ideal"])
    stack = subaperture_stack(config.camera, raw, output=output, **views.stack_options())
    disparity, why_none = None, None
    if config.lens is None:
        mi, scene = traced.get()
        truth = view_stack_disparity(mi, scene, config, output, grid=stack.grid, spacing_px=stack.spacing_px)
        disparity = (truth.disparity_x_px, truth.disparity_y_px)
    else:
        why_none = "a real main lens's sub-aperture views are not pinholes: no ground-truth disparity"
    metadata = {"sample": task.id, "source": RAW_NAME}
    write_view_stack(stage / VIEWS_DIR, stack, metadata=metadata, disparity_px=disparity, **views.write_options())
    return {
        "dir": VIEWS_DIR,
        "grid": stack.grid,
        "spacing_px": stack.spacing_px,
        "baseline_m": stack.baseline_m,
        "disparity": "gt_disparity.npz and gt_disp_lowres*.pfm" if disparity is not None else why_none,
    }
