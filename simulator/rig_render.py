"""Render a stereo rig (:mod:`simulator.rig`): every camera's capture folder and the rig's ground truth.

``lfsim rig [RIG] --out DIR`` (:func:`render_rig`) renders every camera of the rig into
``DIR/<name>/`` (the capture folder of ``lfsim render``, :func:`simulator.job.render_job`) and writes
``DIR/meta.json`` (kind ``lfsim.rig``): the wall, the water, each camera's folder, pose and port,
and the stereo ground truth, the pose of every camera relative to the first (``X_cam = R X_first + t``).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from lfrefract.errors import ParameterError
from lfrefract.formats.capture import SIDECAR_NAME
from lfrefract.formats.jsonio import write_json
from lfrefract.formats.outputs import staged_directory
from simulator.job import render_job
from simulator.rig import RigConfig

__all__ = ["RIG_KIND", "render_rig"]


#: Kind of a rig output directory (its manifest and ``meta.json``).
RIG_KIND = "lfsim.rig"


def render_rig(
    rig: RigConfig,
    out_dir: str | Path,
    *,
    overwrite: bool = False,
    progress: bool = True,
    write_previews: bool = True,
    variant: str | None = None,
    metadata: dict | None = None,
    write_lfr: bool = False,
) -> Path:
    """Render every camera of ``rig`` with its ground truth into ``out_dir/<name>/``.

    Writes ``meta.json`` (kind ``lfsim.rig``): the wall, the water (None without ``[water]``),
    each camera's folder, pose and port, and the stereo ground truth (each camera's rotation and
    translation relative to the first, and the baseline), plus the plain data of ``metadata`` (the
    caller's own keys, e.g. what the scene holds). The directory appears only when every camera is
    rendered; ``overwrite`` replaces only an earlier rig output (:func:`lfrefract.formats.outputs.staged_directory`).
    ``write_lfr``: each camera also writes its Lytro file (cameras with a ``[sensor]`` of 10 or 12
    bits; :func:`simulator.job.render_job`).

    Returns
    -------
    Path
        ``out_dir``.
    """
    out = Path(out_dir)
    taken = sorted(set(metadata or {}) & {"kind", "name", "source", "wall", "water", "cameras", "schema_version"})
    if taken:
        raise ParameterError(f"metadata may not set {taken}: the rig's own keys of its meta.json")
    with staged_directory(out, kind=RIG_KIND, overwrite=overwrite) as stage:
        cameras = {}
        for index, camera in enumerate(rig.cameras):
            if progress:
                print(f"camera {index + 1}/{len(rig.cameras)}: {camera.name}")
            render_job(
                camera.scene,
                stage / camera.name,
                variant=variant,
                progress=progress,
                write_previews=write_previews,
                write_lfr=write_lfr,
            )
            rotation, translation = rig.relative_pose(index)
            cameras[camera.name] = {
                "folder": camera.name,
                "pose": camera.scene.pose.to_dict(),
                "port": camera.scene.port.to_dict(),
                "relative_to_first": {
                    "rotation": rotation.tolist(),
                    "translation_m": translation.tolist(),
                    "baseline_m": float(np.linalg.norm(translation)),
                    "angle_deg": math.degrees(math.acos(np.clip((np.trace(rotation) - 1.0) / 2.0, -1.0, 1.0))),
                },
            }
        meta = {
            "kind": RIG_KIND,
            "name": rig.name,
            "source": rig.source,
            "wall": rig.wall.to_dict(),
            "water": None if rig.water is None else rig.water.to_dict(),
        }
        write_json(stage / SIDECAR_NAME, {**meta, "cameras": cameras, **(metadata or {})})
    return out
