"""Read a dataset for training code: the done samples in index order, arrays loaded on access.

    from simulator.dataset import Dataset

    data = Dataset("out/tilt")
    for sample in data:
        x = sample.raw                      # (H, W, 3) float32 lenslet image
        y = sample.depth_m                  # (h, w) float32, +inf where no surface
        tilt = sample.params["port.tilt_x_deg"]

    batches = data.select("raw", "ideal", "depth_m")   # map-style: items are dicts of arrays

Only the manifest's done samples are listed (their latest record); failed and not-yet-run samples
are left out (:attr:`Dataset.missing` names them). Arrays are read from the sample folder each
time they are accessed, in the dataset's format (:mod:`simulator.dataset.images`, by the entries of
``sample.json``), so holding a :class:`Sample` costs nothing until then. Every object here holds
only paths and the listing and pickles, so a PyTorch ``DataLoader``'s worker processes receive it
under any start method.
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lfrefract.errors import FileFormatError, ParameterError
from lfrefract.formats.capture import DEPTH_NAME, IDEAL_NAME, LENSES_NAME, RAW_NAME, SIDECAR_NAME
from lfrefract.formats.exr import read_exr
from lfrefract.formats.flatport import read_flat_port
from lfrefract.formats.jsonio import read_json
from lfrefract.optics.port import FlatPort
from simulator.dataset.images import read_image
from simulator.dataset.manifest import MANIFEST_FILE, latest_records, read_dataset, read_manifest
from simulator.dataset.sample import COVERAGE_FILE, PORT_FILE, REFRACTION_FREE_FILE, SAMPLE_FILE, VIEWS_DIR

__all__ = ["ArrayDataset", "Dataset", "ReadOnlyDict", "Sample"]


class ReadOnlyDict(Mapping[str, Any]):
    """A read-only mapping that pickles (``types.MappingProxyType`` does not, and a PyTorch
    DataLoader's worker processes receive the dataset by pickling it)."""

    __slots__ = ("_data",)

    def __init__(self, data: Mapping[str, Any] = ()) -> None:
        self._data = dict(data)

    def __getitem__(self, key: str) -> Any:
        return self._data[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._data)

    def __len__(self) -> int:
        return len(self._data)

    def __repr__(self) -> str:
        return f"ReadOnlyDict({self._data!r})"

    def __getstate__(self) -> dict:
        return self._data

    def __setstate__(self, state: dict) -> None:
        self._data = state


#: Images of a sample by name: ``lfsim render``'s (always there) and the optional outputs'.
#: A dataset written before ``sample.json`` listed its images has them as EXR files of these
#: names and roles (file, role); newer ones are read from ``sample.json``'s ``images``.
_LEGACY_IMAGES = {
    "raw": (RAW_NAME, "raw"),
    "ideal": (IDEAL_NAME, "ideal"),
    "depth_m": (DEPTH_NAME, "depth"),
    "refraction_free": (REFRACTION_FREE_FILE, "refraction_free"),
    "coverage": (COVERAGE_FILE, "coverage"),
}


@dataclass(frozen=True)
class Sample:
    """One done sample of a dataset (plain, picklable data; arrays are read when asked for).

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
    def info(self) -> dict:
        """The sample's ``sample.json``: id, seed, params, outputs, image entries, extras' details."""
        return read_json(self.path / SAMPLE_FILE)

    @property
    def image_names(self) -> tuple[str, ...]:
        """Names of the images this sample holds (for :meth:`image`), in the order written."""
        images = self.info.get("images")
        if images is None:
            return tuple(n for n, (f, _) in _LEGACY_IMAGES.items() if f in self.files)
        return tuple(images)

    def image(self, name: str) -> np.ndarray | None:
        """The image ``name`` (see :attr:`image_names`), or None if the sample has none of it.

        Float images are float32 with NaN where there is no value; label images keep their
        integer dtype (see docs/datasets.md for each name's shape, unit and frame).
        """
        images = self.info.get("images")
        if images is None:
            if name not in _LEGACY_IMAGES or _LEGACY_IMAGES[name][0] not in self.files:
                return None
            file, role = _LEGACY_IMAGES[name]
            return read_exr(self.path / file, role=role)
        return read_image(self.path, images[name]) if name in images else None

    def arrays(self, names: Sequence[str]) -> dict[str, np.ndarray]:
        """The images ``names`` as a dict (one read of ``sample.json``).

        Raises
        ------
        KeyError
            Naming an image the sample does not hold, and those it does.
        """
        images = self.info.get("images")
        if images is None:
            out = {}
            for name in names:
                value = self.image(name)
                if value is None:
                    raise KeyError(f"sample {self.id} has no image {name!r}; it has {list(self.image_names)}")
                out[name] = value
            return out
        missing = [n for n in names if n not in images]
        if missing:
            raise KeyError(f"sample {self.id} has no image(s) {missing}; it has {list(images)}")
        return {name: read_image(self.path, images[name]) for name in names}

    @property
    def raw(self) -> np.ndarray:
        """Raw lenslet image, float32, shape (H, W, 3) (sensor pixels), radiance in the air."""
        return self._required("raw")

    @property
    def ideal(self) -> np.ndarray:
        """Ideal refraction-free image, float32, shape (h, w, 3) (the ``ideal`` pinhole of
        :attr:`meta`), radiance in the water."""
        return self._required("ideal")

    @property
    def depth_m(self) -> np.ndarray:
        """Camera-frame z of the ideal image's pixel centres, metres, float32, shape (h, w);
        +inf where no surface."""
        return self._required("depth_m")

    @property
    def refraction_free(self) -> np.ndarray | None:
        """Refraction-free image synthesized from the raw image, float32, shape (h, w, 3), NaN
        where no captured ray was found; None unless the sweep asked for it."""
        return self.image("refraction_free")

    @property
    def coverage(self) -> np.ndarray | None:
        """Coverage of :attr:`refraction_free` (share of exact sub-pixel rays), float32, (h, w)."""
        return self.image("coverage")

    @property
    def filled(self) -> np.ndarray | None:
        """How each pixel of :attr:`refraction_free` got its value, uint8 (h, w): 2 exact, 1
        approximated (nearby rays stand in), 0 empty (NaN in the image); None unless asked for."""
        return self.image("filled")

    @property
    def normal_cam(self) -> np.ndarray | None:
        """Unit surface normals of the ideal image's pixels, camera frame, facing the camera,
        float32 (h, w, 3), NaN where no surface; None unless ``labels`` was asked for."""
        return self.image("normal_cam")

    @property
    def instance_id(self) -> np.ndarray | None:
        """Object of each ideal-image pixel, uint16 (h, w): 0 background, ``i + 1`` the scene's
        object ``i`` (``sample.info["instances"]``); None unless ``labels`` was asked for."""
        return self.image("instance_id")

    @property
    def raw_depth_m(self) -> np.ndarray | None:
        """Camera-frame z of the first surface along each raw pixel's true ray (through the port),
        metres, float32 (H, W); +inf: the ray reaches no surface, NaN: the pixel records no ray;
        None unless ``raw_truth`` was asked for."""
        return self.image("raw_depth_m")

    @property
    def lens_index(self) -> np.ndarray | None:
        """Row of :attr:`lenses` of each raw pixel's microlens, int32 (H, W), -1 for none; None
        unless ``raw_truth`` was asked for."""
        return self.image("lens_index")

    @property
    def view_disparity(self) -> tuple[np.ndarray, np.ndarray] | None:
        """Ground-truth disparity of :attr:`view_stack`, pixels between neighbouring views (the HCI
        benchmark's convention): horizontal and vertical, float32 (grid, grid, h, w) each, NaN where
        a view pixel sees nothing; None without a view stack or for a real main lens."""
        from lfrefract.formats.viewstack import read_view_disparity

        return None if self.views_dir is None else read_view_disparity(self.views_dir)

    def _required(self, name: str) -> np.ndarray:
        value = self.image(name)
        if value is None:
            raise FileFormatError(f"sample {self.id} in {str(self.path)!r} has no {name!r} image")
        return value

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
        #: The ``[set]`` values, the same for every sample, by dotted key (read-only).
        self.set_values: Mapping[str, Any] = ReadOnlyDict(info.get("set", {}))
        #: The image format of the samples (``"exr"``, ``"npz"`` or ``"png16"``).
        self.image_format: str = info.get("image_format", "exr")
        #: Draws refused while planning (``[constraints]``): in all, samples redrawn, by reason.
        self.rejections: Mapping[str, Any] = ReadOnlyDict(
            info.get("rejections", {"draws_refused": 0, "samples_redrawn": 0, "by_reason": {}})
        )
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
                    params=ReadOnlyDict(planned["params"]),
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
        """The sweep's values as columns: key -> one value per done sample (index order): ``id``
        and ``seed``, the swept keys, then the ``[set]`` keys (the same in every row)."""
        table: dict[str, list] = {"id": [s.id for s in self], "seed": [s.seed for s in self]}
        for key in self.swept_keys:
            table[key] = [s.params.get(key) for s in self]
        for key, value in self.set_values.items():
            table[key] = [value] * len(self)
        return table

    def select(self, *names: str) -> ArrayDataset:
        """A map-style dataset of the images ``names`` per sample (see :class:`ArrayDataset`)."""
        return ArrayDataset(self, names)


class ArrayDataset:
    """Images of a dataset's done samples, one dict of arrays per sample: a map-style dataset.

    ``len`` and integer indexing give ``{"id": str, "index": int, name: ndarray, ...}`` for every
    name asked for, read from disk at each access, so PyTorch's ``DataLoader`` (whose default
    collation stacks the arrays into batches) takes it as it is, with worker processes too: the
    object pickles (it holds only paths and the listing), under the ``spawn`` start method as well.
    The project does not depend on PyTorch.

    Parameters
    ----------
    dataset : Dataset
    names : sequence of str
        Image names (:attr:`Sample.image_names`), at least one.

    Raises
    ------
    ParameterError
        For no names, a name that is not a string, or a name given twice.
    """

    def __init__(self, dataset: Dataset, names: Sequence[str]) -> None:
        if not isinstance(dataset, Dataset):
            raise ParameterError(f"dataset must be a Dataset, got {dataset!r}")
        names = tuple(names)
        if not names or any(not isinstance(n, str) for n in names) or len(set(names)) != len(names):
            raise ParameterError(f"names must be distinct image names (strings), at least one; got {names!r}")
        self.dataset = dataset
        self.names = names

    def __len__(self) -> int:
        return len(self.dataset)

    def __getitem__(self, index: int) -> dict[str, Any]:
        if isinstance(index, bool) or not isinstance(index, (int, np.integer)):
            raise TypeError(f"index an ArrayDataset by position (int), got {index!r}")
        sample = self.dataset[int(index)]
        return {"id": sample.id, "index": sample.index, **sample.arrays(self.names)}

    def __repr__(self) -> str:
        return f"ArrayDataset({self.dataset!r}, names={self.names!r})"
