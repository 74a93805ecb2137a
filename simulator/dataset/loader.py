"""Read a dataset for training code: the done samples in index order, arrays loaded on access.

    from simulator.dataset import Dataset

    data = Dataset("out/tilt")
    for sample in data:
        x = sample.raw                      # (H, W, 3) float32 lenslet image
        y = sample.depth_m                  # (h, w) float32, +inf where no surface
        tilt = sample.params["port.tilt_x_deg"]

Only the manifest's done samples are listed (their latest record); failed and not-yet-run samples
are left out (:attr:`Dataset.missing` names them). Arrays are read from the sample folder each
time they are accessed, so holding a :class:`Sample` costs nothing until then.
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from lfrefract.formats.capture import DEPTH_NAME, IDEAL_NAME, LENSES_NAME, RAW_NAME, SIDECAR_NAME
from lfrefract.formats.exr import read_exr
from lfrefract.formats.flatport import read_flat_port
from lfrefract.formats.jsonio import read_json
from lfrefract.optics.port import FlatPort
from simulator.dataset.manifest import MANIFEST_FILE, latest_records, read_dataset, read_manifest
from simulator.dataset.sample import COVERAGE_FILE, PORT_FILE, REFRACTION_FREE_FILE, VIEWS_DIR

__all__ = ["Dataset", "Sample"]


@dataclass(frozen=True)
class Sample:
    """One done sample of a dataset.

    Attributes
    ----------
    id : str
        ``s000042``.
    index : int
        Position in the sweep.
    seed : int
        The sample's seed (also its render seed).
    params : Mapping
        The swept values by dotted key (read-only).
    path : Path
        The sample folder.
    files : tuple of str
        The files of the folder (relative paths), as recorded.
    """

    id: str
    index: int
    seed: int
    params: Mapping[str, Any]
    path: Path
    files: tuple[str, ...]

    @property
    def raw(self) -> np.ndarray:
        """Raw lenslet image, float32, shape (H, W, 3) (sensor pixels), radiance in the air."""
        return read_exr(self.path / RAW_NAME, role="raw")

    @property
    def ideal(self) -> np.ndarray:
        """Ideal refraction-free image, float32, shape (h, w, 3) (the ``ideal`` pinhole of
        :attr:`meta`), radiance in the water."""
        return read_exr(self.path / IDEAL_NAME, role="ideal")

    @property
    def depth_m(self) -> np.ndarray:
        """Camera-frame z of the ideal image's pixel centres, metres, float32, shape (h, w);
        +inf where no surface."""
        return read_exr(self.path / DEPTH_NAME, role="depth")

    @property
    def refraction_free(self) -> np.ndarray | None:
        """Refraction-free image synthesized from the raw image, float32, shape (h, w, 3); None
        unless the sweep asked for it."""
        return self._optional(REFRACTION_FREE_FILE, "refraction_free")

    @property
    def coverage(self) -> np.ndarray | None:
        """Coverage of :attr:`refraction_free` (share of exact sub-pixel rays), float32, (h, w)."""
        return self._optional(COVERAGE_FILE, "coverage")

    @property
    def lenses(self) -> dict[str, np.ndarray]:
        """Microlens ground truth (``lenses.npz``): lattice index, centres, micro-image centres."""
        with np.load(self.path / LENSES_NAME, allow_pickle=False) as data:
            return {k: data[k] for k in data.files}

    @property
    def meta(self) -> dict:
        """The render's sidecar (``meta.json``): camera, port, pose, scene, ideal pinhole, versions."""
        return read_json(self.path / SIDECAR_NAME)

    @property
    def port(self) -> FlatPort | None:
        """The port (from ``port.txt``), or None for a scene without one."""
        return read_flat_port(self.path / PORT_FILE) if PORT_FILE in self.files else None

    @property
    def views_dir(self) -> Path | None:
        """Folder of the sub-aperture view stack (HCI layout), or None unless the sweep asked for it."""
        return self.path / VIEWS_DIR if any(f.startswith(VIEWS_DIR + "/") for f in self.files) else None

    @property
    def view_stack(self):
        """The sub-aperture view stack (:class:`lfrefract.synthesis.views.ViewStack`: ``views`` float32,
        shape (grid, grid, h, w, 3), NaN outside the lenses' hull), or None unless asked for."""
        from lfrefract.formats.viewstack import read_view_stack

        return None if self.views_dir is None else read_view_stack(self.views_dir)

    def _optional(self, name: str, role: str) -> np.ndarray | None:
        return read_exr(self.path / name, role=role) if name in self.files else None


class Dataset:
    """The done samples of a dataset folder, in index order.

    Parameters
    ----------
    root : path-like
        A folder written by :func:`simulator.dataset.run_dataset` (``lfsim dataset run``).

    Raises
    ------
    FileFormatError
        If ``root`` holds no ``dataset.json``, or the manifest has a malformed complete line.

    Notes
    -----
    ``len``, integer indexing (negative too), indexing by id (``data["s000042"]``) and iteration
    are supported. The listing is read once, when the object is made; files are not re-hashed
    (``lfsim dataset check`` does that).
    """

    def __init__(self, root: str | os.PathLike) -> None:
        self.root = Path(root)
        info = read_dataset(self.root)
        self.name: str = info.get("name", self.root.name)
        self.spec: dict = info.get("spec", {})
        self.swept_keys: tuple[str, ...] = tuple(info.get("swept_keys", ()))
        latest = latest_records(read_manifest(self.root / MANIFEST_FILE))
        samples = []
        missing = []
        for planned in sorted(info["samples"], key=lambda s: s["index"]):
            record = latest.get(planned["id"])
            if record is None or record["status"] != "done" or record.get("hash") != planned["hash"]:
                missing.append(planned["id"])
                continue
            samples.append(
                Sample(
                    id=planned["id"],
                    index=int(planned["index"]),
                    seed=int(planned["seed"]),
                    params=MappingProxyType(dict(planned["params"])),
                    path=self.root / planned["id"],
                    files=tuple(sorted(record.get("files", {}))),
                )
            )
        self._samples = tuple(samples)
        self._by_id = {s.id: s for s in samples}
        #: Ids of planned samples that are not done (failed or not yet run), in index order.
        self.missing: tuple[str, ...] = tuple(missing)

    def __len__(self) -> int:
        return len(self._samples)

    def __iter__(self) -> Iterator[Sample]:
        return iter(self._samples)

    def __getitem__(self, key: int | str) -> Sample:
        if isinstance(key, str):
            if key not in self._by_id:
                raise KeyError(f"no done sample {key!r} in {str(self.root)!r}")
            return self._by_id[key]
        if isinstance(key, bool) or not isinstance(key, (int, np.integer)):
            raise TypeError(f"index a Dataset by position (int) or sample id (str), got {key!r}")
        return self._samples[int(key)]

    def __repr__(self) -> str:
        return f"Dataset({str(self.root)!r}: {len(self)} done samples, {len(self.missing)} not done)"

    @property
    def ids(self) -> tuple[str, ...]:
        """Ids of the done samples, in index order."""
        return tuple(s.id for s in self._samples)

    def params_table(self) -> dict[str, list]:
        """The swept values as columns: key -> one value per done sample (index order), plus
        ``id`` and ``seed``."""
        table: dict[str, list] = {"id": [s.id for s in self], "seed": [s.seed for s in self]}
        for key in self.swept_keys:
            table[key] = [s.params.get(key) for s in self]
        return table
