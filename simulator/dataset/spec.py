"""Sweep specs: a TOML file of grids and random ranges over scene keys, expanded into samples.

A sweep spec has three tables::

    [sweep]
    name = "tilt"                     # label of the dataset
    seed = 7                          # one seed for the whole sweep (integer in [0, 2**31))
    scene = "default"                 # base scene: an embedded scene name, or a .toml path
                                      #   relative to this file
    repeats = 1                       # samples per grid point (each with its own seed and draws)
    outputs = ["refraction_free"]     # optional extras: "refraction_free", "views", "previews",
                                      #   "labels" (normal_cam, instance_id), "raw_truth"
    spp = 4                           # optional: samples per pixel of every sample's raw image
    ideal_spp = 64                    # optional: samples per pixel of every sample's ideal image
    image_format = "exr"              # optional: "exr" (default), "npz" or "png16"
    max_draws = 100                   # optional: draws of the [random] keys per sample at most
    redraw_impossible = false         # optional: also draw again a sample the geometry check refuses
    unset = ["port.n_water"]          # optional: dotted keys removed from the base scene first
    [sweep.synthesis]                 # optional: lfrefract.synthesis.warp_map.SynthesisOptions fields
    k = 32                            #   (only with "refraction_free")
    [sweep.views]                     # optional (only with "views"): grid, spacing_px of
    grid = 5                          #   lfrefract.synthesis.views.subaperture_stack; image_format,
                                      #   white_level of lfrefract.formats.viewstack.write_view_stack

    [grid]                            # dotted scene keys -> lists of values (Cartesian product)
    "port.tilt_x_deg" = [0.0, 10.0, 20.0, 30.0]
    "camera.preset" = ["tiny"]

    [random]                          # dotted scene keys -> one distribution each
    "port.tilt_y_deg" = { uniform = [-5.0, 5.0] }
    "object.1.rotation_xyz_deg" = { uniform = [[0, -20, 0], [10, -10, 0]] }
    "object.0.texture_seed" = { integers = [0, 1000] }
    "port.thickness_m" = { normal = [0.006, 0.0005] }
    "light.0.intensity_w_sr" = { choice = [0.4, 0.5] }

    [set]                             # dotted scene keys -> one value each, the same for every
    "port.thickness_m" = 0.004        #   sample: constants, recorded as set, not swept

    [constraints]                     # named conditions on the sample's scene; a sample that
    board_before_backdrop = { key = "object.1.position_m.2", less_than = "object.0.position_m.2", margin = 0.05 }
                                      #   breaks one draws its [random] keys again

A dotted key addresses the scene TOML (:mod:`simulator.config`): ``port.tilt_x_deg``,
``camera.preset``, ``camera.pose.position_m``, ``object.2.rotation_xyz_deg`` (the third
``[[object]]``), ``water.temperature_c``, or a whole table or array (``object`` replaces every
object). Missing tables on the way are created; array entries must exist. The key ``scene``
chooses the base scene per sample (a grid of names or paths, or ``{choice = [...]}``).
``render.seed`` and ``name`` are set per sample and cannot be swept. ``sweep.unset`` removes keys
(or array entries, ``object.3``) from every base scene before the swept values are set: e.g.
``port.n_water``, which a ``[water]`` salinity and temperature would otherwise contradict.

Samples: the grid points in the order of ``itertools.product`` over the ``[grid]`` keys in file
order (the first key varies slowest), each repeated ``repeats`` times; sample ``i`` (id
``s{i:06d}``) has the seed ``SeedSequence([seed, i]).generate_state(1, uint32)[0] % 2**31``,
which is also its render seed, and draws the value of random key ``K`` from
``numpy.random.default_rng(SeedSequence([seed, i, crc32(K)]))``, so a key's draws do not depend
on the other keys. Every sample is built with :func:`simulator.config.parse_scene` and checked
with :func:`simulator.geometry.check_geometry` before anything is rendered.

Keys of ``[set]`` are applied to every sample after ``sweep.unset`` and before the swept values;
a key cannot be both set and swept. ``sweep.spp`` and ``sweep.ideal_spp`` set ``render.spp`` and
``render.ideal_spp`` the same way (the raw image's and the ideal image's samples per pixel: ground
truth is usually rendered with more).

A constraint ``{ key = K, less_than = L, margin = m }`` (or ``greater_than``) holds when the value
at ``K`` is below ``L - m`` (above ``L + m``); ``K`` and ``L`` are dotted keys into the sample's
scene, whose last parts may index a vector (``object.1.position_m.2`` is the second object's z),
or ``L`` is a number. A sample that breaks a constraint (or, with ``sweep.redraw_impossible``, that
the geometry check refuses) draws its ``[random]`` keys again, draw ``a`` from
``SeedSequence([seed, i, crc32(K), a])``, up to ``sweep.max_draws`` draws in all; then the sweep is
refused, naming the sample and the condition. The draws refused are counted per sample
(:attr:`SweepSample.rejected`) and for the whole sweep in ``dataset.json``.

Files a sample's scene reads besides its TOML (mesh files: every path in the scene) are its
*inputs*: their SHA-256 is part of the sample's hash, so an edited mesh makes another sample.
:func:`iter_samples` builds the samples one at a time (a run holds only their small records);
:func:`expand` holds them all.
"""

from __future__ import annotations

import copy
import dataclasses
import hashlib
import json
import math
import re
import sys
import time
import tomllib
import zlib
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from lfrefract.errors import FileFormatError, ParameterError
from lfrefract.synthesis.warp_map import SynthesisOptions
from lfrefract.validate import finite_float, finite_vector, one_of, positive_float, positive_int, reject_unknown_keys
from simulator import seeds
from simulator.config import SceneConfig, embedded_scenes, parse_scene, scene_files, scenes_dir
from simulator.dataset.images import IMAGE_FORMATS
from simulator.dataset.manifest import DigestCache
from simulator.geometry import check_geometry

__all__ = [
    "DEFAULT_MAX_DRAWS",
    "DISTRIBUTIONS",
    "MAX_SAMPLES",
    "OUTPUTS",
    "RELATIONS",
    "Constraint",
    "Distribution",
    "SweepSample",
    "SweepSpec",
    "ViewOptions",
    "canonical_json",
    "embedded_sweeps",
    "expand",
    "iter_samples",
    "key_rng",
    "load_spec",
    "parse_spec",
    "sample_id",
    "sample_seed",
    "toml_digest",
]

#: Optional outputs of a sample besides the render files: the refraction-free image (with its
#: coverage and its ``filled`` class image), the sub-aperture view stack (with its ground-truth
#: disparity), the PNG previews of ``lfsim render``, the ideal image's surface labels (normals in
#: the camera frame, instance ids) and the raw pixels' truth (depth along each pixel's true ray,
#: its lenslet).
OUTPUTS = ("refraction_free", "views", "previews", "labels", "raw_truth")

#: Draws of a sample's ``[random]`` keys at most, by default (``sweep.max_draws``).
DEFAULT_MAX_DRAWS = 100

#: Relations of a ``[constraints]`` entry.
RELATIONS = ("less_than", "greater_than")

#: Distributions of a ``[random]`` key, with the form of their arguments.
DISTRIBUTIONS = {
    "uniform": "[lo, hi] with lo < hi: numbers, or equal-length vectors (per entry; lo = hi fixes an entry)",
    "normal": "[mean, std] with std > 0: numbers, or equal-length vectors (per entry)",
    "integers": "[lo, hi] integers with lo <= hi (both included)",
    "choice": "a non-empty list of values, picked with equal probability",
}

#: Most samples of one sweep. Measured on the 2-core CI machine (default scene): every sample is
#: built and checked before any work, at 4-11 ms each (100 000 samples: 7-18 min, said up front with
#: a progress bar), and the driver reads ``dataset.json`` (about 0.3 kB per sample) and the manifest
#: (about 1.5 kB per line, 6.6 kB per record in memory) whole on resume and in ``check``: at this
#: limit some 0.7 GB. Split a bigger sweep into several specs (other seeds, or parts of a grid) in
#: folders of their own.
MAX_SAMPLES = 100_000

#: Keys set per sample, never swept.
_RESERVED_KEYS = ("render.seed", "name")
#: The key choosing the base scene.
SCENE_KEY = "scene"
_KEY_PART = re.compile(r"^(?:[A-Za-z_][A-Za-z0-9_]*|[0-9]+)$")


def canonical_json(value: Any) -> str:
    """Compact JSON with sorted keys: the form that sample and spec hashes are taken of."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"), allow_nan=False, default=str)


def _sha256(value: Any) -> str:
    return hashlib.sha256(canonical_json(value).encode()).hexdigest()


def sample_id(index: int) -> str:
    """The folder name and id of sample ``index``: ``s000042``."""
    return f"s{index:06d}"


def sample_seed(sweep_seed: int, index: int) -> int:
    """Seed of sample ``index`` (also its render seed), in [0, 2**31).

    ``numpy.random.SeedSequence([sweep_seed, index]).generate_state(1, uint32)[0] % 2**31``.
    """
    state = np.random.SeedSequence([sweep_seed, index]).generate_state(1, dtype=np.uint32)
    return int(state[0]) % seeds.SEED_LIMIT


def key_rng(sweep_seed: int, index: int, key: str, draw: int = 0) -> np.random.Generator:
    """Generator of random key ``key`` for draw ``draw`` of sample ``index``:
    ``default_rng(SeedSequence([sweep_seed, index, crc32(key)]))`` for the first draw,
    ``SeedSequence([sweep_seed, index, crc32(key), draw])`` for a later one (a sample that broke a
    constraint)."""
    entropy = [sweep_seed, index, zlib.crc32(key.encode())] + ([draw] if draw else [])
    return np.random.default_rng(np.random.SeedSequence(entropy))


def _plain(value: Any) -> Any:
    """numpy scalars and arrays as Python numbers and lists (for JSON and TOML-form dicts)."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


@dataclass(frozen=True, kw_only=True)
class Distribution:
    """A random range of one ``[random]`` key.

    Parameters
    ----------
    key : str
        The dotted key (named in errors).
    kind : {"uniform", "normal", "integers", "choice"}
    args : tuple
        ``(lo, hi)`` for uniform and integers, ``(mean, std)`` for normal (each a float or a
        tuple of floats of one length), the values for choice.
    """

    key: str
    kind: str
    args: tuple

    def __post_init__(self) -> None:
        where = f"random {self.key!r}"
        if self.kind not in DISTRIBUTIONS:
            raise ParameterError(f"{where}: unknown distribution {self.kind!r}; one of {sorted(DISTRIBUTIONS)}")
        args = self.args
        if not isinstance(args, (list, tuple)):
            raise ParameterError(f"{where}: {self.kind} needs {DISTRIBUTIONS[self.kind]}, got {args!r}")
        args = tuple(args)
        if self.kind == "choice":
            if not args:
                raise ParameterError(f"{where}: choice = [] is an empty range; give at least one value")
        elif self.kind == "integers":
            if len(args) != 2 or any(isinstance(a, bool) or not isinstance(a, int) for a in args):
                raise ParameterError(f"{where}: integers needs {DISTRIBUTIONS['integers']}, got {list(args)!r}")
            if args[0] > args[1]:
                raise ParameterError(f"{where}: integers = {list(args)!r} is an empty range (lo > hi)")
        else:
            if len(args) != 2:
                raise ParameterError(f"{where}: {self.kind} needs {DISTRIBUTIONS[self.kind]}, got {list(args)!r}")
            a, b = (self._numbers(f"{where}: {self.kind}[{i}]", v) for i, v in enumerate(args))
            if type(a) is not type(b) or (isinstance(a, tuple) and len(a) != len(b)):
                raise ParameterError(
                    f"{where}: {self.kind} = {list(args)!r} mixes a number and a vector, or vectors of "
                    "different lengths"
                )
            av, bv = np.atleast_1d(a), np.atleast_1d(b)
            if self.kind == "uniform" and (np.any(av > bv) or np.all(av == bv)):
                need = "lo < hi" if av.size == 1 else "lo <= hi in every entry, lo < hi in one"
                raise ParameterError(f"{where}: uniform = {list(args)!r} is an empty range (needs {need})")
            if self.kind == "normal" and np.any(bv <= 0.0):
                raise ParameterError(f"{where}: normal = {list(args)!r} needs std > 0")
            args = (a, b)
        object.__setattr__(self, "args", args)

    @staticmethod
    def _numbers(name: str, value: Any) -> float | tuple[float, ...]:
        if isinstance(value, (list, tuple)):
            if not value:
                raise ParameterError(f"{name} is an empty vector")
            return finite_vector(name, value, len(value))
        return finite_float(name, value)

    def draw(self, rng: np.random.Generator) -> Any:
        """One value: a float, a list of floats, an int, or one of the choices (a deep copy)."""
        if self.kind == "choice":
            return copy.deepcopy(self.args[int(rng.integers(len(self.args)))])
        if self.kind == "integers":
            return int(rng.integers(self.args[0], self.args[1], endpoint=True))
        a, b = (np.asarray(v, dtype=np.float64) for v in self.args)
        value = rng.uniform(a, b) if self.kind == "uniform" else rng.normal(a, b)
        return _plain(value) if isinstance(self.args[0], tuple) else float(value)

    def to_dict(self) -> dict:
        """The TOML form, ``{kind: [args]}``."""
        return {self.kind: [list(a) if isinstance(a, tuple) else a for a in self.args]}


@dataclass(frozen=True, kw_only=True)
class Constraint:
    """One ``[constraints]`` entry: the value at ``key`` below (``less_than``) or above
    (``greater_than``) ``other`` by more than ``margin``.

    Parameters
    ----------
    name : str
        The entry's name (named in errors and in the rejection counts).
    key : str
        Dotted key into the sample's scene; its last parts may index a vector
        (``object.1.position_m.2``).
    relation : {"less_than", "greater_than"}
    other : str or float
        A dotted key like ``key``, or a number.
    margin : float
        In the keys' unit, at least 0.
    """

    name: str
    key: str
    relation: str
    other: str | float
    margin: float = 0.0

    def __post_init__(self) -> None:
        where = f"[constraints] {self.name!r}"
        _check_path(f"{where} key", self.key)
        one_of(f"{where} relation", self.relation, RELATIONS)
        if isinstance(self.other, str):
            _check_path(f"{where} {self.relation}", self.other)
        else:
            object.__setattr__(self, "other", finite_float(f"{where} {self.relation}", self.other))
        margin = finite_float(f"{where} margin", self.margin)
        if margin < 0.0:
            raise ParameterError(f"{where} margin must be >= 0, got {self.margin!r}")
        object.__setattr__(self, "margin", margin)

    @classmethod
    def from_table(cls, name: str, table: Any) -> Constraint:
        """From ``{ key = ..., less_than | greater_than = ..., margin = ... }``."""
        where = f"[constraints] {name!r}"
        if not isinstance(table, dict):
            raise ParameterError(
                f"{where} must be a table such as {{ key = 'object.1.position_m.2', less_than = "
                f"'object.0.position_m.2', margin = 0.05 }}, got {table!r}"
            )
        reject_unknown_keys(where, table, {"key", "margin", *RELATIONS})
        relations = [r for r in RELATIONS if r in table]
        if "key" not in table or len(relations) != 1:
            raise ParameterError(f"{where} needs 'key' and exactly one of {list(RELATIONS)}, got {table!r}")
        return cls(
            name=name,
            key=table["key"],
            relation=relations[0],
            other=table[relations[0]],
            margin=table.get("margin", 0.0),
        )

    def holds(self, data: Mapping[str, Any]) -> bool:
        """Whether the scene ``data`` (TOML form) meets the condition.

        Raises
        ------
        ParameterError
            If a key does not address a number of the scene.
        """
        where = f"[constraints] {self.name!r}"
        value = _number_at(data, self.key, where)
        other = self.other if isinstance(self.other, float) else _number_at(data, self.other, where)
        if self.relation == "less_than":
            return value < other - self.margin
        return value > other + self.margin


def _is_dotted(key: Any) -> bool:
    """Whether ``key`` is a dotted scene key: names and array indices joined by '.'."""
    return isinstance(key, str) and all(_KEY_PART.match(part) for part in key.split("."))


def _check_path(where: str, key: Any) -> str:
    """``key`` if it is a dotted path of names and indices, else :class:`ParameterError`."""
    if not _is_dotted(key):
        raise ParameterError(f"{where} {key!r} is not a dotted scene key (e.g. 'object.1.position_m.2')")
    return key


def _number_at(data: Mapping[str, Any], key: str, where: str) -> float:
    """The number at dotted ``key`` of the scene ``data``: tables by name, arrays by index."""
    node: Any = data
    for depth, part in enumerate(key.split(".")):
        here = ".".join(key.split(".")[: depth + 1])
        if isinstance(node, (list, tuple)) and part.isdigit() and int(part) < len(node):
            node = node[int(part)]
        elif isinstance(node, Mapping) and part in node:
            node = node[part]
        else:
            raise ParameterError(f"{where}: the sample's scene has no {here!r} (key {key!r})")
    if isinstance(node, bool) or not isinstance(node, (int, float)):
        raise ParameterError(f"{where}: {key!r} is {node!r}, not a number; index a vector by its entry")
    return float(node)


@dataclass(frozen=True, kw_only=True)
class SweepSample:
    """One sample of a sweep: its id, seed, swept values and validated scene.

    Attributes
    ----------
    id : str
        Folder name, ``s{index:06d}``.
    index : int
        Position in the sweep (0-based).
    seed : int
        The sample's seed, also its render seed (:func:`sample_seed`).
    params : Mapping
        The swept values by dotted key (``scene`` included when swept), read-only.
    hash : str
        SHA-256 (hex) of the sample's whole scene (TOML form, after the sweep's changes), the
        base scene's name, the outputs and the content (SHA-256) of its input files: equal hashes
        mean equal samples.
    config : SceneConfig
        The validated scene.
    scene_data : Mapping
        The scene in TOML form that ``config`` was parsed from, read-only.
    inputs : Mapping
        The files the sample is made from, read-only: absolute path -> ``{"bytes", "sha256"}``
        (of the bytes) as read when the sample was built: its base scene file (whose entry also
        has ``toml_sha256``, the SHA-256 of its TOML in :func:`canonical_json` form: what the
        sample's hash covers of it) and the files its scene names (meshes).
    rejected : Mapping
        The draws of its ``[random]`` keys refused before this one, by reason (a constraint's
        name, or ``"geometry"``), read-only; empty for a sample drawn once.
    """

    id: str
    index: int
    seed: int
    params: Mapping[str, Any]
    hash: str
    config: SceneConfig
    scene_data: Mapping[str, Any]
    inputs: Mapping[str, Mapping[str, Any]] = field(default_factory=lambda: MappingProxyType({}))
    rejected: Mapping[str, int] = field(default_factory=lambda: MappingProxyType({}))

    def record(self) -> dict:
        """Plain data for ``dataset.json``: id, index, seed, params, hash, the paths of its input
        files (``inputs``, sorted) and, for a sample drawn more than once, ``rejected``."""
        record = {
            "id": self.id,
            "index": self.index,
            "seed": self.seed,
            "params": dict(self.params),
            "hash": self.hash,
            "inputs": sorted(self.inputs),
        }
        if self.rejected:
            record["rejected"] = dict(self.rejected)
        return record


@dataclass(frozen=True, kw_only=True)
class SweepSpec:
    """A parsed, validated sweep spec (see the module docstring for the format).

    Attributes
    ----------
    name : str
    seed : int
        Sweep seed, in [0, 2**31) (:func:`simulator.seeds.seed`).
    scene : str
        The base scene as given (embedded name or path relative to ``base_dir``).
    repeats : int
        Samples per grid point.
    outputs : tuple of str
        Extras among :data:`OUTPUTS`.
    spp : int or None
        Samples per pixel of the raw image replacing every scene's, or None to keep them.
    ideal_spp : int or None
        Samples per pixel of the ideal image replacing every scene's, or None to keep them.
    image_format : {"exr", "npz", "png16"}
        File format of the sample's images (:data:`IMAGE_FORMATS`).
    unset : tuple of str
        Dotted keys removed from every base scene before the swept values are set.
    synthesis : SynthesisOptions or None
        Options of the refraction-free image (None unless ``"refraction_free"`` is an output).
    views : ViewOptions
        Options of the view stack (``"views"`` output; empty without it).
    grid : tuple of (str, tuple)
        Grid keys in file order with their values.
    random : tuple of Distribution
        Random keys in file order.
    constants : tuple of (str, object)
        ``[set]``: keys in file order with their value, the same for every sample.
    constraints : tuple of Constraint
        ``[constraints]`` in file order.
    max_draws : int
        Draws of a sample's random keys at most.
    redraw_impossible : bool
        Whether a sample the geometry check refuses draws again (else the sweep is refused).
    base_dir : Path
        Directory of the spec file (relative scene paths are resolved against it).
    source : str
        Where the spec came from.
    data : Mapping
        The spec as parsed TOML (recorded in ``dataset.json``; its hash is :attr:`hash`).
    """

    name: str
    seed: int
    scene: str
    repeats: int = 1
    outputs: tuple[str, ...] = ()
    spp: int | None = None
    ideal_spp: int | None = None
    image_format: str = "exr"
    unset: tuple[str, ...] = ()
    synthesis: SynthesisOptions | None = None
    views: ViewOptions = field(default_factory=lambda: ViewOptions())
    grid: tuple[tuple[str, tuple], ...] = ()
    random: tuple[Distribution, ...] = ()
    constants: tuple[tuple[str, Any], ...] = ()
    constraints: tuple[Constraint, ...] = ()
    max_draws: int = DEFAULT_MAX_DRAWS
    redraw_impossible: bool = False
    base_dir: Path = Path(".")
    source: str = "<memory>"
    data: Mapping[str, Any] = field(default_factory=dict)

    @property
    def hash(self) -> str:
        """SHA-256 (hex) of :attr:`data` in :func:`canonical_json` form."""
        return _sha256(self.to_dict())

    def to_dict(self) -> dict:
        """The spec as plain TOML-form data (what :attr:`hash` is taken of)."""
        return _thaw(self.data)

    @property
    def size(self) -> int:
        """Number of samples: the product of the grid's lengths times ``repeats``."""
        return math.prod(len(values) for _, values in self.grid) * self.repeats

    @property
    def swept_keys(self) -> tuple[str, ...]:
        """Grid keys, then random keys, in file order."""
        return tuple(k for k, _ in self.grid) + tuple(d.key for d in self.random)

    @property
    def set_keys(self) -> tuple[str, ...]:
        """``[set]`` keys in file order."""
        return tuple(k for k, _ in self.constants)


def _thaw(value: Any) -> Any:
    if isinstance(value, Mapping):
        return {k: _thaw(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_thaw(v) for v in value]
    return value


def _freeze(value: Any) -> Any:
    if isinstance(value, Mapping):
        return MappingProxyType({k: _freeze(v) for k, v in value.items()})
    if isinstance(value, (list, tuple)):
        return tuple(_freeze(v) for v in value)
    return value


def _check_key(where: str, key: Any) -> str:
    if not _is_dotted(key):
        raise ParameterError(
            f"{where} key {key!r} is not a dotted scene key (names and array indices joined by '.', "
            "e.g. 'port.tilt_x_deg' or 'object.2.rotation_xyz_deg')"
        )
    if key in _RESERVED_KEYS or key.startswith("render.seed."):
        raise ParameterError(
            f"{where} key {key!r} is set per sample (from sweep.seed and the sample id) and cannot be swept"
        )
    return key


def _scene_file(where: str, value: Any, base_dir: Path) -> Path:
    """The base scene file for a ``scene`` value: ``*.toml`` relative to ``base_dir``, else an
    embedded scene name."""
    if not isinstance(value, str) or not value:
        raise ParameterError(f"{where} must be an embedded scene name or a .toml path, got {value!r}")
    if value.endswith(".toml"):
        path = (base_dir / value).resolve()
        if not path.is_file():
            raise ParameterError(f"{where} = {value!r}: no such scene file {str(path)!r}")
        return path
    embedded = embedded_scenes()
    if value not in embedded:
        raise ParameterError(
            f"{where} = {value!r} is not an embedded scene (one of {sorted(embedded)}) or a .toml path"
        )
    return embedded[value]


def _reject_non_finite(value: Any, where: str) -> None:
    """Raise on a NaN or infinite number anywhere in the spec (a choice value never drawn included)."""
    if isinstance(value, float) and not math.isfinite(value):
        raise ParameterError(f"sweep spec: {where} = {value!r} is not a finite number")
    if isinstance(value, dict):
        for k, v in value.items():
            part = k if re.fullmatch(r"[A-Za-z0-9_-]+", str(k)) else json.dumps(str(k))  # TOML's quoting
            _reject_non_finite(v, f"{where}.{part}" if where else part)
    elif isinstance(value, list):
        for i, v in enumerate(value):
            _reject_non_finite(v, f"{where}[{i}]")


def _unset_keys(unset: Any) -> list[str]:
    """``sweep.unset``: distinct dotted scene keys."""
    if not isinstance(unset, list):
        raise ParameterError(f"sweep.unset must be a list of dotted scene keys, got {unset!r}")
    for key in unset:
        _check_key("sweep.unset", key)
    if len(set(unset)) != len(unset):
        raise ParameterError(f"sweep.unset lists a key twice: {unset!r}")
    return unset


def _outputs(sweep: dict) -> tuple[list[str], SynthesisOptions | None, ViewOptions]:
    """``sweep.outputs`` and the options of those that have some (``[sweep.synthesis]``,
    ``[sweep.views]``, each only with its output)."""
    outputs = sweep.get("outputs", [])
    if not isinstance(outputs, list) or any(not isinstance(o, str) for o in outputs):
        raise ParameterError(f"sweep.outputs must be a list of names among {list(OUTPUTS)}, got {outputs!r}")
    for o in outputs:
        if o not in OUTPUTS:
            raise ParameterError(f"sweep.outputs: unknown output {o!r}; one of {list(OUTPUTS)}")
    if len(set(outputs)) != len(outputs):
        raise ParameterError(f"sweep.outputs lists an output twice: {outputs!r}")
    synthesis = None
    if "synthesis" in sweep and "refraction_free" not in outputs:
        raise ParameterError("[sweep.synthesis] is given but 'refraction_free' is not in sweep.outputs")
    if "refraction_free" in outputs:
        table = sweep.get("synthesis", {})
        if not isinstance(table, dict):
            raise ParameterError(f"[sweep.synthesis] must be a table, got {table!r}")
        reject_unknown_keys("[sweep.synthesis]", table, {f.name for f in dataclasses.fields(SynthesisOptions)})
        try:
            synthesis = SynthesisOptions(**table)
        except ParameterError as exc:
            raise ParameterError(f"[sweep.synthesis]: {exc}") from None
    if "views" in sweep and "views" not in outputs:
        raise ParameterError("[sweep.views] is given but 'views' is not in sweep.outputs")
    views = ViewOptions.from_table(sweep.get("views", {})) if "views" in outputs else ViewOptions()
    return outputs, synthesis, views


def _grid(grid_table: dict, base: Path) -> list[tuple[str, tuple]]:
    """``[grid]``: dotted keys in file order with non-empty lists of values (base scenes exist)."""
    grid: list[tuple[str, tuple]] = []
    for key, values in grid_table.items():
        _check_key("[grid]", key)
        if not isinstance(values, list):
            raise ParameterError(f"grid {key!r} must be a list of values, got {values!r}")
        if not values:
            raise ParameterError(f"grid {key!r} = [] is an empty range; give at least one value")
        if key == SCENE_KEY:
            for v in values:
                _scene_file(f"grid {key!r}", v, base)
        grid.append((key, tuple(values)))
    return grid


def _random(random_table: dict, grid_table: dict, base: Path) -> list[Distribution]:
    """``[random]``: one distribution per dotted key not in ``[grid]``, in file order."""
    random: list[Distribution] = []
    for key, table in random_table.items():
        _check_key("[random]", key)
        if key in grid_table:
            raise ParameterError(f"key {key!r} is both in [grid] and in [random]")
        if not isinstance(table, dict) or len(table) != 1:
            raise ParameterError(
                f"random {key!r} must be a table with one distribution, one of {sorted(DISTRIBUTIONS)} "
                f"(e.g. {{ uniform = [0, 10] }}), got {table!r}"
            )
        ((kind, args),) = table.items()
        dist = Distribution(key=key, kind=kind, args=args)
        if key == SCENE_KEY:
            if kind != "choice":
                raise ParameterError(
                    f"random {key!r} chooses among base scenes: use {{ choice = [...] }}, got {kind!r}"
                )
            for v in dist.args:
                _scene_file(f"random {key!r}", v, base)
        random.append(dist)
    return random


def _constants(set_table: dict, swept: dict) -> tuple[tuple[str, Any], ...]:
    """``[set]``: dotted keys in file order with their values (none of them swept)."""
    for key in set_table:
        _check_key("[set]", key)
        if key == SCENE_KEY:
            raise ParameterError("[set] 'scene': the base scene of every sample is sweep.scene")
        if key in swept:
            raise ParameterError(f"key {key!r} is both in [set] and swept ([grid] or [random]): give one of them")
    return tuple((key, _freeze(value)) for key, value in set_table.items())


def parse_spec(data: dict, *, base_dir: Path | str = ".", source: str = "<memory>") -> SweepSpec:
    """Build a :class:`SweepSpec` from a parsed TOML document (structure only).

    Parameters
    ----------
    data : dict
        The TOML document.
    base_dir : path-like
        Directory that a base scene given as a path is resolved against (the spec file's).
    source : str
        Where the data came from.

    Returns
    -------
    SweepSpec
        Validated in its form: tables, keys, ranges, outputs, base scenes. The samples
        themselves are checked by :func:`expand`.

    Raises
    ------
    ParameterError
        For unknown tables or keys, a NaN or infinite number, empty or inverted ranges, an unknown distribution or
        output, a reserved or malformed dotted key, a key both in ``[grid]`` and ``[random]`` (or
        set and swept), a malformed constraint,
        a missing base scene, or more than :data:`MAX_SAMPLES` samples; the message names the
        key and value.
    """
    base = Path(base_dir).resolve()
    if not isinstance(data, dict):
        raise ParameterError(f"a sweep spec must be a TOML document (a table), got {data!r}")
    reject_unknown_keys("sweep spec", data, {"sweep", "grid", "random", "set", "constraints"})
    _reject_non_finite(data, "")
    if "sweep" not in data or not isinstance(data["sweep"], dict):
        raise ParameterError("sweep spec: missing [sweep] table (name, seed, scene)")
    sweep = dict(data["sweep"])
    reject_unknown_keys(
        "[sweep]",
        sweep,
        {"name", "seed", "scene", "repeats", "outputs", "spp", "ideal_spp", "image_format", "synthesis", "views"}
        | {"unset", "max_draws", "redraw_impossible"},
    )
    for key in ("name", "seed", "scene"):
        if key not in sweep:
            raise ParameterError(f"[sweep]: missing key {key!r}")
    name = sweep["name"]
    if not isinstance(name, str) or not name.strip():
        raise ParameterError(f"sweep.name must be a non-empty string, got {name!r}")
    seed = seeds.seed("sweep.seed", sweep["seed"])
    scene = sweep["scene"]
    _scene_file("sweep.scene", scene, base)
    repeats = positive_int("sweep.repeats", sweep.get("repeats", 1))
    spp = None if "spp" not in sweep else positive_int("sweep.spp", sweep["spp"])
    ideal_spp = None if "ideal_spp" not in sweep else positive_int("sweep.ideal_spp", sweep["ideal_spp"])
    image_format = one_of("sweep.image_format", sweep.get("image_format", "exr"), IMAGE_FORMATS)
    max_draws = positive_int("sweep.max_draws", sweep.get("max_draws", DEFAULT_MAX_DRAWS))
    redraw_impossible = sweep.get("redraw_impossible", False)
    if not isinstance(redraw_impossible, bool):
        raise ParameterError(f"sweep.redraw_impossible must be true or false, got {redraw_impossible!r}")
    unset = _unset_keys(sweep.get("unset", []))
    outputs, synthesis, views = _outputs(sweep)
    grid_table = data.get("grid", {})
    random_table = data.get("random", {})
    set_table = data.get("set", {})
    constraints_table = data.get("constraints", {})
    for label, table in (("[grid]", grid_table), ("[random]", random_table), ("[set]", set_table)):
        if not isinstance(table, dict):
            raise ParameterError(f"{label} must be a table of dotted keys, got {table!r}")
    if not isinstance(constraints_table, dict):
        raise ParameterError(f"[constraints] must be a table of named conditions, got {constraints_table!r}")
    grid = _grid(grid_table, base)
    random = _random(random_table, grid_table, base)
    constants = _constants(set_table, grid_table | random_table)
    constraints = tuple(Constraint.from_table(key, table) for key, table in constraints_table.items())
    for option, key in (("spp", "render.spp"), ("ideal_spp", "render.ideal_spp")):
        if option in sweep and key in grid_table | random_table | set_table:
            raise ParameterError(f"{key} is swept or set and sweep.{option} is given: give one of them")
    spec = SweepSpec(
        name=name,
        seed=seed,
        scene=scene,
        repeats=repeats,
        outputs=tuple(outputs),
        spp=spp,
        ideal_spp=ideal_spp,
        image_format=image_format,
        unset=tuple(unset),
        synthesis=synthesis,
        views=views,
        grid=tuple(grid),
        random=tuple(random),
        constants=constants,
        constraints=constraints,
        max_draws=max_draws,
        redraw_impossible=redraw_impossible,
        base_dir=base,
        source=source,
        data=_freeze(data),
    )
    if spec.size > MAX_SAMPLES:
        raise ParameterError(
            f"the sweep has {spec.size} samples, more than {MAX_SAMPLES}: check [grid] and sweep.repeats"
        )
    return spec


#: Keys of ``[sweep.views]``: options of :func:`lfrefract.synthesis.views.subaperture_stack` and of
#: :func:`lfrefract.formats.viewstack.write_view_stack`.
VIEW_STACK_KEYS = ("grid", "spacing_px", "image_format", "white_level")
#: Views per side when ``[sweep.views]`` gives no ``grid``: the default of
#: :func:`lfrefract.synthesis.views.subaperture_stack`.
DEFAULT_VIEW_GRID = 9


@dataclass(frozen=True, kw_only=True)
class ViewOptions:
    """``[sweep.views]``, checked once when the spec is parsed (what does not depend on a camera;
    :func:`iter_samples` checks ``spacing_px`` against each sample's camera).

    Parameters
    ----------
    grid : int or None
        Views per side, odd and at least 3 (None: :data:`DEFAULT_VIEW_GRID`).
    spacing_px : float or None
        Pixel step between neighbouring views, positive (None: the stack's own choice).
    image_format : {"png", "exr"} or None
        File format of the written views (None: the writer's default).
    white_level : float or None
        Linear value written as full scale in PNG views, positive (None: the writer's default).

    Values are kept as given (an integer ``spacing_px`` stays one): :meth:`to_dict`, the table as
    given, is part of every sample's hash.

    Raises
    ------
    ParameterError
        Naming the key (``sweep.views.<key>``) and the value.
    """

    grid: int | None = None
    spacing_px: float | None = None
    image_format: str | None = None
    white_level: float | None = None

    def __post_init__(self) -> None:
        from lfrefract.formats import viewstack

        grid = self.grid
        if grid is not None and (isinstance(grid, bool) or not isinstance(grid, int) or grid < 3 or grid % 2 != 1):
            raise ParameterError(f"sweep.views.grid must be an odd integer >= 3, got {grid!r}")
        if self.spacing_px is not None:
            positive_float("sweep.views.spacing_px", self.spacing_px)
        if self.white_level is not None:
            positive_float("sweep.views.white_level", self.white_level)
        if self.image_format is not None:
            one_of("sweep.views.image_format", self.image_format, viewstack.VIEW_STACK_FORMATS)

    @classmethod
    def from_table(cls, table: Any) -> ViewOptions:
        """From a ``[sweep.views]`` table; unknown keys are an error."""
        if not isinstance(table, Mapping):
            raise ParameterError(f"[sweep.views] must be a table, got {table!r}")
        reject_unknown_keys("[sweep.views]", dict(table), set(VIEW_STACK_KEYS))
        return cls(**table)

    @property
    def grid_size(self) -> int:
        """Views per side: ``grid``, or :data:`DEFAULT_VIEW_GRID`."""
        return DEFAULT_VIEW_GRID if self.grid is None else self.grid

    def stack_options(self) -> dict:
        """Keyword options of :func:`lfrefract.synthesis.views.subaperture_stack` (those given)."""
        return {k: v for k, v in (("grid", self.grid), ("spacing_px", self.spacing_px)) if v is not None}

    def write_options(self) -> dict:
        """Keyword options of :func:`lfrefract.formats.viewstack.write_view_stack` (those given)."""
        pairs = (("image_format", self.image_format), ("white_level", self.white_level))
        return {k: v for k, v in pairs if v is not None}

    def to_dict(self) -> dict:
        """The table as given (keys not given left out)."""
        return self.stack_options() | self.write_options()


def _check_views(views: ViewOptions, camera) -> None:
    """Raise unless ``camera``'s micro-images leave room for the view stack of ``views``."""
    from lfrefract.synthesis.views import subaperture_limit_px

    limit = subaperture_limit_px(camera)
    if limit <= 0.0:
        raise ParameterError(f"camera {camera.name!r} has micro-images too small for sub-aperture views")
    if views.spacing_px is not None:
        half = (views.grid_size - 1) // 2
        reach = math.hypot(half * views.spacing_px, half * views.spacing_px)
        if reach > limit:
            raise ParameterError(
                f"sweep.views.spacing_px={views.spacing_px!r} puts the corner views {reach:.4g} px from the "
                f"micro-image centres of camera {camera.name!r}, beyond its limit of {limit:.4g} px"
            )


def load_spec(path: str | Path) -> SweepSpec:
    """Read a sweep spec file (or an embedded sweep by name, see :func:`embedded_sweeps`).

    Parameters
    ----------
    path : path-like
        A TOML file, or the name of an embedded sweep (``"tilt"``).

    Returns
    -------
    SweepSpec

    Raises
    ------
    FileNotFoundError
        If there is no such file or embedded sweep.
    ParameterError
        If the file is not valid TOML or not a valid spec (:func:`parse_spec`).
    """
    p = Path(path)
    embedded = embedded_sweeps()
    if not p.exists() and str(path) in embedded:
        p = embedded[str(path)]
    data = _read_toml(p, "sweep spec")  # its errors name the file already
    try:
        return parse_spec(data, base_dir=p.parent, source=str(p))
    except ParameterError as exc:
        raise ParameterError(f"sweep spec file {str(p)!r}: {exc}") from None


def toml_digest(path: str | Path) -> str:
    """SHA-256 (hex) of a TOML file's content in :func:`canonical_json` form: what a sample's hash
    covers of its base scene file (formatting and comments aside).

    Raises
    ------
    FileNotFoundError, FileFormatError, ParameterError
        As :func:`load_spec`, if the file is gone, not UTF-8, or not TOML.
    """
    return _sha256(_read_toml(Path(path), "scene"))


def _read_toml(path: Path, what: str) -> dict:
    """The TOML document at ``path`` (``what`` names it in errors: "sweep spec", "scene").

    Raises
    ------
    FileNotFoundError
        If ``path`` is not a file.
    FileFormatError
        If it is not UTF-8 text (TOML's only encoding; a UTF-16 or Latin-1 file, say).
    ParameterError
        If it is not valid TOML.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{what} file {str(path)!r} does not exist")
    data = path.read_bytes()
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        hint = " (it starts with a UTF-16 byte-order mark)" if data[:2] in (b"\xff\xfe", b"\xfe\xff") else ""
        raise FileFormatError(
            f"{what} file {str(path)!r} is not UTF-8 text{hint}: byte {exc.start} "
            f"({data[exc.start : exc.start + 1]!r}) cannot be decoded; TOML files must be UTF-8"
        ) from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ParameterError(f"{what} file {str(path)!r} is not valid TOML: {exc}") from None


def embedded_sweeps() -> dict[str, Path]:
    """Embedded sweep specs (``scenes/sweeps/*.toml``) by name (file stem)."""
    folder = scenes_dir() / "sweeps"
    return {p.stem: p for p in sorted(folder.glob("*.toml"))}


# ------------------------------------------------------------------------------- expansion
def _assign(data: dict, key: str, value: Any) -> None:
    """Set dotted ``key`` of the scene dict ``data`` to ``value`` (tables created on the way)."""
    parts = key.split(".")
    node: Any = data
    for depth, part in enumerate(parts):
        last = depth == len(parts) - 1
        here = ".".join(parts[:depth])  # the table or array that ``part`` addresses into
        if isinstance(node, list):
            if not part.isdigit():
                example = ".".join([*parts[:depth], "0", *parts[depth:]])
                raise ParameterError(
                    f"{key!r}: {here!r} is an array of tables; address an entry by its index (e.g. {example!r})"
                )
            i = int(part)
            if i >= len(node):
                entries = "entry" if len(node) == 1 else "entries"
                raise ParameterError(
                    f"{key!r}: index {i} is out of range: the scene has {len(node)} [[{here}]] {entries}"
                )
            if last:
                node[i] = value
            else:
                node = node[i]
        elif isinstance(node, dict):
            if part.isdigit():
                raise ParameterError(f"{key!r}: {here or 'the scene'!r} is a table, not an array")
            if last:
                node[part] = value
            else:
                node = node.setdefault(part, {})
        else:
            raise ParameterError(f"{key!r}: {here!r} is a value ({node!r}), not a table or array")


def _unset(data: dict, keys: tuple[str, ...]) -> None:
    """Remove dotted ``keys`` from the scene dict ``data``; array entries by their index in the
    base scene (all are located first, then removed, higher indices first)."""
    targets = []
    for key in keys:
        parts = key.split(".")
        node: Any = data
        for depth, part in enumerate(parts):
            here = ".".join(parts[: depth + 1])
            if isinstance(node, list) and part.isdigit() and int(part) < len(node):
                index: Any = int(part)
            elif isinstance(node, dict) and part in node:
                index = part
            else:
                raise ParameterError(f"sweep.unset: {key!r}: the base scene has no {here!r}")
            if depth == len(parts) - 1:
                targets.append((id(node), node, index))
            else:
                node = node[index]
    # Array entries from the highest index down, so that each index still means the base scene's.
    for _, node, index in sorted(targets, key=lambda t: (t[0], t[2] if isinstance(t[2], int) else -1), reverse=True):
        del node[index]


def _describe(params: Mapping[str, Any]) -> str:
    return ", ".join(f"{k}={v!r}" for k, v in params.items()) or "no swept keys"


def expand(spec: SweepSpec, *, progress: bool = False) -> tuple[SweepSample, ...]:
    """Every sample of ``spec``, each built and checked as a scene (all held in memory: for
    small sweeps; :func:`iter_samples` builds them one at a time).

    Parameters
    ----------
    spec : SweepSpec
    progress : bool
        Show a progress bar (tqdm, stderr) over the samples.

    Returns
    -------
    tuple of SweepSample
        In index order. The same spec (and input files) always gives the same samples (ids,
        seeds, values, hashes).

    Raises
    ------
    ParameterError, FileFormatError
        As :func:`iter_samples`.
    """
    return tuple(iter_samples(spec, progress=progress))


#: With a progress bar, the estimate of the whole check is printed once the first samples took
#: this long (seconds), if the whole check will take longer than ``_ESTIMATE_MIN_S``.
_ESTIMATE_AFTER_S = 1.0
_ESTIMATE_MIN_S = 10.0


def iter_samples(
    spec: SweepSpec,
    *,
    indices: Iterable[int] | None = None,
    progress: bool = False,
    digests: DigestCache | None = None,
) -> Iterator[SweepSample]:
    """Build and check the samples of ``spec`` one at a time, in index order.

    Parameters
    ----------
    spec : SweepSpec
    indices : iterable of int, optional
        Only these samples (increasing indices); default every sample.
    progress : bool
        Show a progress bar (tqdm, stderr) over the samples and, once the first ones have taken
        a second, print how long the whole check will take when that is more than 10 s.
    digests : DigestCache, optional
        Cache of input file hashes to use (and fill): one per run reads a mesh that many samples
        use once. Default: a new one for this call.

    Yields
    ------
    SweepSample
        The same spec (and input files) always gives the same samples (ids, seeds, values,
        hashes). Only the sample being yielded is held: memory does not grow with the count.

    Raises
    ------
    ParameterError
        If a sample is not a valid, physically possible scene (unknown keys at any level,
        impossible or totally reflecting port tilts, unknown presets, objects on the camera side
        of the port, an output the scene cannot have, ...): the message names the sample, its
        swept values and the offending key. Also for an index outside the sweep.
    FileFormatError
        If a base scene file is not UTF-8 text.
    """
    if not isinstance(spec, SweepSpec):
        raise ParameterError(f"spec must be a SweepSpec, got {spec!r}")
    digests = DigestCache() if digests is None else digests
    scenes: dict[str, tuple[Path, dict, dict]] = {}

    def base_scene(value: str) -> tuple[Path, dict, dict]:
        """The base scene file, its TOML, and its entry among the inputs."""
        if value not in scenes:
            path = _scene_file(SCENE_KEY, value, spec.base_dir)
            data = _read_toml(path, "scene")
            size, sha = digests.digest(path)
            scenes[value] = (path, data, {"bytes": size, "sha256": sha, "toml_sha256": _sha256(data)})
        return scenes[value]

    wanted = range(spec.size) if indices is None else indices
    total = spec.size if indices is None else None
    if total is None and hasattr(wanted, "__len__"):
        total = len(wanted)
    grid_keys = [k for k, _ in spec.grid]
    start = time.perf_counter()
    estimated = False
    with tqdm(total=total, desc="checking samples", unit="sample", disable=not progress) as bar:
        last = -1
        for index in wanted:
            if isinstance(index, bool) or not isinstance(index, int) or not last < index < spec.size:
                raise ParameterError(f"sample index {index!r} is not an increasing index in [0, {spec.size})")
            last = index
            seed = sample_seed(spec.seed, index)
            point = _grid_point(spec, index // spec.repeats)
            rejected: dict[str, int] = {}
            try:  # every refusal of a sample names the spec file first
                for draw in range(spec.max_draws):
                    params: dict[str, Any] = dict(zip(grid_keys, (copy.deepcopy(v) for v in point), strict=True))
                    for dist in spec.random:
                        params[dist.key] = dist.draw(key_rng(spec.seed, index, dist.key, draw))
                    try:
                        sample = _build_sample(spec, index, seed, params, base_scene, digests, rejected)
                        break
                    except _RefusedDrawError as refusal:
                        rejected[refusal.reason] = rejected.get(refusal.reason, 0) + 1
                        if not spec.random:
                            raise ParameterError(f"{refusal}; the sample has no [random] keys to draw again") from None
                else:
                    raise ParameterError(
                        f"sample {sample_id(index)}: none of {spec.max_draws} draws of its [random] keys was "
                        f"accepted (refused, by reason: {rejected}); widen the ranges, loosen [constraints] or raise "
                        "sweep.max_draws"
                    )
            except ParameterError as exc:
                raise ParameterError(f"sweep spec file {spec.source!r}: {exc}") from None
            yield sample
            bar.update()
            elapsed = time.perf_counter() - start
            if progress and not estimated and elapsed >= _ESTIMATE_AFTER_S and total:
                estimated = True
                whole = elapsed / bar.n * total
                if whole > _ESTIMATE_MIN_S:
                    bar.write(
                        f"checking {total} samples before any work: about {_duration(whole)} "
                        f"({elapsed / bar.n * 1e3:.1f} ms per sample)",
                        file=sys.stderr,
                    )


def _duration(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


def _grid_point(spec: SweepSpec, p: int) -> tuple:
    """Grid point ``p`` in ``itertools.product`` order (the first key varies slowest)."""
    values = []
    for _, choices in reversed(spec.grid):
        p, i = divmod(p, len(choices))
        values.append(choices[i])
    return tuple(reversed(values))


class _RefusedDrawError(Exception):
    """A draw of a sample that breaks a constraint (or, with ``redraw_impossible``, the geometry
    check): drawn again. ``reason``: the constraint's name, or ``"geometry"``."""

    def __init__(self, message: str, reason: str) -> None:
        super().__init__(message)
        self.reason = reason


def _build_sample(
    spec: SweepSpec, index: int, seed: int, params: dict, base_scene, digests: DigestCache, rejected: dict[str, int]
) -> SweepSample:
    sid = sample_id(index)
    where = f"sample {sid} ({_describe(params)})"
    scene_name = params.get(SCENE_KEY, spec.scene)
    path, base, scene_entry = base_scene(scene_name)
    data = copy.deepcopy(base)
    try:
        _unset(data, spec.unset)
        for option, key in ((spec.spp, "render.spp"), (spec.ideal_spp, "render.ideal_spp")):
            if option is not None:
                _assign(data, key, option)
        for key, value in spec.constants:
            _assign(data, key, _thaw(value))
        for key, value in params.items():
            if key != SCENE_KEY:
                _assign(data, key, copy.deepcopy(value))
        _assign(data, "render.seed", seed)
        data["name"] = f"{spec.name}/{sid}"
        for constraint in spec.constraints:
            if not constraint.holds(data):
                raise _RefusedDrawError(f"{where}: breaks [constraints] {constraint.name!r}", constraint.name)
        config = parse_scene(data, base_dir=path.parent, source=f"{spec.source}#{sid}")
    except ParameterError as exc:
        raise ParameterError(f"{where}: {exc}") from None
    try:
        check_geometry(config)
    except ParameterError as exc:
        if spec.redraw_impossible:
            raise _RefusedDrawError(f"{where}: {exc}", "geometry") from None
        raise ParameterError(f"{where}: {exc}") from None
    if config.port is None and "refraction_free" in spec.outputs:
        raise ParameterError(f"{where}: the scene has no [port], so it has no refraction-free image to write")
    if "views" in spec.outputs:
        try:
            _check_views(spec.views, config.camera)
        except ParameterError as exc:
            raise ParameterError(f"{where}: {exc}") from None
    # The base scene's content is in the hash as TOML (``data``: formatting and comments aside, as
    # for the spec); the files the scene names (meshes) by the SHA-256 of their bytes.
    inputs: dict[str, dict] = {str(path): scene_entry}
    content = []
    for location, file in scene_files(config):
        size, sha = digests.digest(file)
        inputs[str(file)] = {"bytes": size, "sha256": sha}
        content.append([location, sha])
    hashed = {"scene": data, "base_scene": scene_name, "outputs": list(spec.outputs),
              "synthesis": None if spec.synthesis is None else spec.synthesis.to_dict(),
              "views": spec.views.to_dict()}  # fmt: skip
    if content:  # (a sample without input files keeps the hash it had before inputs were hashed)
        hashed["inputs"] = content
    return SweepSample(
        id=sid,
        index=index,
        seed=seed,
        params=MappingProxyType(params),
        hash=_sha256(hashed),
        config=config,
        scene_data=_freeze(data),
        inputs=MappingProxyType({k: MappingProxyType(v) for k, v in inputs.items()}),
        rejected=MappingProxyType(dict(rejected)),
    )
