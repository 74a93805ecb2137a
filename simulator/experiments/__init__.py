"""The experiment harness: the paper's evaluation reproduced on the simulator's ground truth.

Run an experiment from Python with :func:`run_experiment`, or from the shell with
``lfsim experiment NAME --out DIR [--scale tiny|illum] [--methods ...] [--camera ...] ...``. An
experiment writes into its output directory (assembled in a staging directory, so it appears
complete or not at all; missing parents are created):

- ``table.csv`` and ``table.md``: one row per measured condition, columns with units in their
  names (:func:`write_table`);
- its figures (PNG), listed in the result;
- ``meta.json``: the experiment, scale, options, parameters and timings (kind ``lfsim.experiment``).

What can be changed is one frozen :class:`ExperimentOptions`, validated once when it is made;
each experiment declares which of its fields apply to it (:attr:`Experiment.options`) and a
field that does not apply is refused before any work. Scales (:data:`SCALES`): ``tiny`` runs in CI
in seconds to minutes on two cores; ``illum`` is the paper's size (the Lytro Illum preset) and takes
much longer.

The stereo experiments (``planes``, ``objects``) compare methods by name from the method registry
(:mod:`simulator.experiments.methods`: :func:`~simulator.experiments.methods.register_method`
and the ``lfrefract.methods`` entry-point group), read when the experiment runs. A method that
fails gives table rows with ``status = "failed"`` and its ``error``, not a failed run.

An experiment is registered with :func:`register`; its function is
``run(out_dir, options, *, progress) -> ExperimentResult``.
"""

from __future__ import annotations

import contextlib
import csv
import io
import math
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path

from lfrefract.calibration.camera import RAY_MODELS
from lfrefract.errors import ParameterError
from lfrefract.formats.capture import SIDECAR_NAME
from lfrefract.formats.jsonio import write_json, write_text_atomically
from lfrefract.optics.camera import LightFieldCamera
from lfrefract.optics.lens import LENS_PRESETS, LensPrescription
from lfrefract.optics.port import MAX_DISTANCE_M, MAX_THICKNESS_M, N_MAX, N_MIN
from lfrefract.optics.presets import camera_preset
from lfrefract.validate import bounded_float, finite_float, one_of, positive_float, shown
from simulator.config import THIN_LENS

__all__ = [
    "EXPERIMENTS",
    "OPTION_FLAGS",
    "SCALES",
    "Experiment",
    "ExperimentOptions",
    "ExperimentResult",
    "check_methods",
    "check_renders_dir",
    "check_scale",
    "complete_rows",
    "experiment_names",
    "load_experiments",
    "named_options",
    "register",
    "run_experiment",
    "write_table",
]

#: Problem sizes: ``tiny`` (CI) and ``illum`` (the paper's camera).
SCALES = ("tiny", "illum")

#: Each option of :class:`ExperimentOptions` (but ``scale``) and its ``lfsim experiment`` flag.
OPTION_FLAGS = {
    "methods": "--methods",
    "camera": "--camera",
    "port_distance_m": "--port-distance-m",
    "thickness_m": "--thickness-m",
    "tilts_deg": "--tilts-deg",
    "f_numbers": "--f-numbers",
    "lens": "--lens",
    "port_tilt_x_deg": "--port-tilt-x-deg",
    "port_tilt_y_deg": "--port-tilt-y-deg",
    "n_glass": "--n-glass",
    "n_water": "--n-water",
    "ray_model": "--ray-model",
}


def _floats(name: str, values, check: Callable[[str, float], float]) -> tuple[float, ...]:
    if isinstance(values, (str, bytes)) or not hasattr(values, "__iter__"):
        raise ParameterError(f"{name} must be a sequence of numbers, got {shown(values)}")
    out = tuple(check(f"{name}[{i}]", v) for i, v in enumerate(values))
    if not out:
        raise ParameterError(f"{name} must hold at least one value, got {shown(values)}")
    if len(set(out)) != len(out):
        raise ParameterError(f"{name} must not repeat a value, got {list(out)}")
    return out


def _tilt_deg(name: str, value) -> float:
    tilt = finite_float(name, value)
    if not -90.0 < tilt < 90.0:  # the port must face the camera
        raise ParameterError(f"{name} must lie in (-90, 90) deg, got {shown(value)}")
    return tilt


@dataclass(frozen=True, kw_only=True)
class ExperimentOptions:
    """What a run of an experiment may change; ``None`` keeps the experiment's own choice.

    Validated when made; which fields apply depends on the experiment (:attr:`Experiment.options`,
    ``lfsim experiment --help``), and :func:`run_experiment` refuses one that does not.

    Attributes
    ----------
    scale : str
        One of :data:`SCALES`.
    methods : tuple of str, optional
        Methods to compare, by registered name (:func:`simulator.experiments.methods.method_names`),
        in table order; default every registered method. ``planes``, ``objects``.
    camera : LightFieldCamera or str, optional
        The light-field camera (a preset name is turned into the preset), replacing the scale's:
        the fov camera, the averaging scene's camera, every camera of a stereo rig.
    port_distance_m : float, optional
        Perpendicular distance of the port's air-side face from the main-lens centre, metres
        (a rig's wall: the offset of its air-side plane, ``normal . X = d``), in (0, 100].
    thickness_m : float, optional
        Glass thickness of the port (or wall), metres, in [0, 1] (0: a single air/water interface;
        a rig's wall needs glass).
    tilts_deg : tuple of float, optional
        Port tilts about the camera x axis that ``fov`` sweeps (normal turned up), degrees, each in
        (-90, 90).
    f_numbers : tuple of float, optional
        Main-lens f-numbers that ``fov`` evaluates (each checked against the camera when it runs:
        the image-side f-number may not fall below the microlenses').
    lens : str or LensPrescription, optional
        The main lens every camera of a stereo rig renders through: ``"thin"``, a lens preset
        (``lfsim lenses``) or a design (a lens file's, :func:`simulator.config.lens_option`), scaled
        and stopped to the camera; ``meta.json`` records a design by its table. The core is not told:
        it keeps its thin-lens model of the camera (what ``planes`` and ``objects`` then measure is
        the cost of that assumption).
    port_tilt_x_deg, port_tilt_y_deg : float, optional
        The tilts of a rig's wall, degrees, each in (-90, 90): its normal (into the water, world frame)
        is ``R_y(tilt_y) R_x(tilt_x) (0, 0, 1)``, the port's convention (docs/conventions.md), so a
        positive ``tilt_x`` turns it up and a positive ``tilt_y`` right; one left out keeps the rig's
        own. Each camera sees the wall through its own pose (its port's tilts differ from the wall's).
    n_glass, n_water : float, optional
        Refractive indices of a rig's wall glass and of the water behind it, each in [1, 5].
    ray_model : str, optional
        The camera ray model a data-only chain calibrates (``lfrefract calibrate camera --ray-model``;
        one of :data:`lfrefract.calibration.camera.RAY_MODELS`); default ``"radial"``.
    """

    scale: str = "tiny"
    methods: tuple[str, ...] | None = None
    camera: LightFieldCamera | None = None
    port_distance_m: float | None = None
    thickness_m: float | None = None
    tilts_deg: tuple[float, ...] | None = None
    f_numbers: tuple[float, ...] | None = None
    lens: str | LensPrescription | None = None
    port_tilt_x_deg: float | None = None
    port_tilt_y_deg: float | None = None
    n_glass: float | None = None
    n_water: float | None = None
    ray_model: str | None = None

    def __post_init__(self) -> None:
        one_of("scale", self.scale, SCALES)
        if self.methods is not None:
            methods = (self.methods,) if isinstance(self.methods, str) else self.methods
            if not hasattr(methods, "__iter__"):
                raise ParameterError(f"methods must be a sequence of method names, got {shown(self.methods)}")
            methods = tuple(methods)
            if not methods or not all(isinstance(m, str) and m.strip() for m in methods):
                raise ParameterError(f"methods must be one or more non-empty names, got {shown(self.methods)}")
            if len(set(methods)) != len(methods):
                raise ParameterError(f"methods must not repeat a name, got {list(methods)}")
            object.__setattr__(self, "methods", methods)
        if isinstance(self.camera, str):
            object.__setattr__(self, "camera", camera_preset(self.camera))
        if self.camera is not None and not isinstance(self.camera, LightFieldCamera):
            raise ParameterError(f"camera must be a LightFieldCamera or a preset name, got {shown(self.camera)}")
        if self.port_distance_m is not None:
            distance = bounded_float(
                "port_distance_m", self.port_distance_m, 0.0, MAX_DISTANCE_M, low_open=True, unit="m"
            )
            object.__setattr__(self, "port_distance_m", distance)
        if self.thickness_m is not None:
            thickness = bounded_float("thickness_m", self.thickness_m, 0.0, MAX_THICKNESS_M, unit="m")
            object.__setattr__(self, "thickness_m", thickness)
        if self.tilts_deg is not None:
            object.__setattr__(self, "tilts_deg", _floats("tilts_deg", self.tilts_deg, _tilt_deg))
        if self.f_numbers is not None:
            object.__setattr__(self, "f_numbers", _floats("f_numbers", self.f_numbers, positive_float))
        if self.lens is not None and not isinstance(self.lens, LensPrescription):
            one_of("lens", self.lens, (THIN_LENS, *sorted(LENS_PRESETS)))
        for name in ("port_tilt_x_deg", "port_tilt_y_deg"):
            if getattr(self, name) is not None:
                object.__setattr__(self, name, _tilt_deg(name, getattr(self, name)))
        for name in ("n_glass", "n_water"):
            if getattr(self, name) is not None:
                object.__setattr__(self, name, bounded_float(name, getattr(self, name), N_MIN, N_MAX))
        if self.ray_model is not None:
            one_of("ray_model", self.ray_model, RAY_MODELS)

    def given(self) -> tuple[str, ...]:
        """Names of the fields set (not ``None``), ``scale`` left out."""
        return tuple(f.name for f in fields(self) if f.name != "scale" and getattr(self, f.name) is not None)

    def to_dict(self) -> dict:
        """Plain data for ``meta.json`` (the camera, and a lens design, as their tables)."""
        out = {f.name: getattr(self, f.name) for f in fields(self)}
        out["camera"] = None if self.camera is None else self.camera.to_dict()
        if isinstance(self.lens, LensPrescription):
            out["lens"] = self.lens.to_dict()
        return {k: list(v) if isinstance(v, tuple) else v for k, v in out.items()}

    @classmethod
    def from_dict(cls, data: dict) -> ExperimentOptions:
        """The options :meth:`to_dict` wrote (e.g. a run's ``meta.json`` ``options``): the camera's
        and a lens design's tables read back; validated as any options are.

        Examples
        --------
        >>> options = ExperimentOptions(scale="tiny", lens="double-gauss", port_tilt_y_deg=10.0)
        >>> ExperimentOptions.from_dict(options.to_dict()) == options
        True
        """
        if not isinstance(data, dict):
            raise ParameterError(f"experiment options must be a table, got {shown(data)}")
        values = dict(data)
        if isinstance(values.get("camera"), dict):
            values["camera"] = LightFieldCamera.from_dict(values["camera"])
        if isinstance(values.get("lens"), dict):
            values["lens"] = LensPrescription.from_dict(values["lens"])
        unknown = sorted(set(values) - {f.name for f in fields(cls)})
        if unknown:
            raise ParameterError(f"experiment options: unknown keys {unknown}")
        return cls(**values)


@dataclass(frozen=True)
class ExperimentResult:
    """What an experiment measured.

    Attributes
    ----------
    name : str
        The experiment's name (its key in :data:`EXPERIMENTS`).
    scale : str
        One of :data:`SCALES`.
    rows : tuple of dict
        The table: one dict per row, the same keys in every row (units in the key names).
    figures : tuple of Path
        Figures written (PNG), inside the output directory.
    summary : str
        A few lines for the terminal and the report (markdown).
    parameters : dict
        What the experiment was run with (for ``meta.json``).
    """

    name: str
    scale: str
    rows: tuple[dict, ...]
    figures: tuple[Path, ...] = ()
    summary: str = ""
    parameters: dict = field(default_factory=dict)


ExperimentFunction = Callable[..., ExperimentResult]


@dataclass(frozen=True)
class Experiment:
    """A registered experiment.

    Attributes
    ----------
    name : str
    run : callable
        ``run(out_dir, options, *, progress) -> ExperimentResult``; with ``keeps_renders`` also the
        keyword ``renders_dir`` (a folder or None).
    options : tuple of str
        The :class:`ExperimentOptions` fields (but ``scale``) that apply to it.
    description : str
        One line, for ``lfsim experiment --help``.
    keeps_renders : bool
        Whether it can keep its renders in a folder of the caller's and reuse those that match on a
        later run (``lfsim experiment --renders``).
    """

    name: str
    run: ExperimentFunction
    options: tuple[str, ...]
    description: str
    keeps_renders: bool = False

    def check(self, options: ExperimentOptions) -> None:
        """Refuse an option that does not apply (:class:`ParameterError` naming it and its flag)."""
        for name in options.given():
            if name not in self.options:
                takes = ", ".join(f"{OPTION_FLAGS[o]}" for o in self.options) or "none"
                raise ParameterError(
                    f"option {OPTION_FLAGS[name]} ({name}={shown(getattr(options, name))}) does not apply to "
                    f"experiment {self.name!r}; its options: {takes}"
                )


#: Registered experiments by name (filled by :func:`register`; see :func:`load_experiments`).
EXPERIMENTS: dict[str, Experiment] = {}


def register(
    name: str, *, options: Sequence[str] = (), keeps_renders: bool = False
) -> Callable[[ExperimentFunction], ExperimentFunction]:
    """Decorator: register ``run(out_dir, options, *, progress)`` as experiment ``name``.

    Parameters
    ----------
    name : str
        The experiment's name (``lfsim experiment NAME``).
    options : sequence of str
        The :class:`ExperimentOptions` fields (but ``scale``) it reads; any other one given is refused.
    keeps_renders : bool
        ``run`` also takes the keyword ``renders_dir`` (:attr:`Experiment.keeps_renders`).
    """
    unknown = sorted(set(options) - set(OPTION_FLAGS))
    if unknown:
        raise ParameterError(f"experiment {name!r}: unknown options {unknown}; known: {sorted(OPTION_FLAGS)}")

    def wrap(function: ExperimentFunction) -> ExperimentFunction:
        if name in EXPERIMENTS:
            raise ValueError(f"experiment {name!r} registered twice")
        doc = (function.__doc__ or "").strip().splitlines()
        EXPERIMENTS[name] = Experiment(name, function, tuple(options), doc[0] if doc else "", keeps_renders)
        return function

    return wrap


def check_scale(scale: str) -> str:
    """``scale`` if it is one of :data:`SCALES`, else :class:`ParameterError` naming it."""
    return one_of("scale", scale, SCALES)


def _cell(value) -> str:
    if isinstance(value, float):
        return "nan" if math.isnan(value) else f"{value:.6g}"
    return str(value)


def complete_rows(rows: Sequence[dict]) -> tuple[dict, ...]:
    """Rows with the same keys: those of the longest row first, then any others in order of
    appearance; a key a row lacks (a failed method's measures) is NaN there."""
    if not rows:
        return ()
    keys = list(max(rows, key=len))
    for row in rows:
        keys += [k for k in row if k not in keys]
    return tuple({k: row.get(k, math.nan) for k in keys} for row in rows)


def write_table(rows: Sequence[dict], out_dir: Path, stem: str = "table") -> tuple[Path, Path]:
    """Write ``rows`` as ``stem.csv`` and ``stem.md`` (a markdown table) into ``out_dir``, atomically.

    Raises
    ------
    ParameterError
        If there are no rows or the rows do not share the same keys.
    """
    if not rows:
        raise ParameterError("an experiment table needs at least one row")
    keys = list(rows[0])
    for i, row in enumerate(rows):
        if list(row) != keys:
            raise ParameterError(f"row {i} has keys {list(row)}, expected {keys}")
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(keys)
    writer.writerows([[_cell(row[k]) for k in keys] for row in rows])
    csv_path = write_text_atomically(Path(out_dir) / f"{stem}.csv", buffer.getvalue())
    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    lines += ["| " + " | ".join(_cell(row[k]).replace("|", "\\|") for k in keys) + " |" for row in rows]
    md_path = write_text_atomically(Path(out_dir) / f"{stem}.md", "\n".join(lines) + "\n")
    return csv_path, md_path


@contextlib.contextmanager
def named_options(options: ExperimentOptions, *names: str) -> Iterator[None]:
    """Errors of the block start with the flags (:data:`OPTION_FLAGS`) of those of ``names`` that
    ``options`` gives: an experiment checks what its options make (a port, a rig, a camera at an
    f-number) when it runs, and the user is told which options made it.

    Parameters
    ----------
    options : ExperimentOptions
    *names : str
        The fields the checked values derive from; those left at ``None`` (the experiment's own
        choice) are not named, and with none given the error passes unchanged.
    """
    given = [OPTION_FLAGS[name] for name in names if getattr(options, name) is not None]
    try:
        yield
    except ParameterError as exc:
        if not given:
            raise
        raise ParameterError(f"{', '.join(given)}: {exc}") from None


def check_renders_dir(
    name: str, renders: str | Path, out: str | Path, *, names: tuple[str, str] = ("renders_dir", "out")
) -> Path:
    """``renders`` as the folder of kept renders of experiment ``name`` writing into ``out``.

    Parameters
    ----------
    name : str
        A registered experiment.
    renders, out : path-like
        The folder of kept renders and the experiment's output (see :func:`run_experiment`).
    names : tuple of str
        What ``renders`` and ``out`` are called in messages (``lfsim experiment``: ``--renders``,
        ``--out``).

    Raises
    ------
    ParameterError
        If the experiment keeps no renders, or either folder holds the other.
    """
    experiment = load_experiments()[name]
    renders, out = Path(renders), Path(out)
    if not experiment.keeps_renders:
        keeping = sorted(e.name for e in EXPERIMENTS.values() if e.keeps_renders)
        raise ParameterError(
            f"{names[0]} ({str(renders)!r}) does not apply to experiment {experiment.name!r}: it keeps no renders "
            f"(those that do: {', '.join(keeping)})"
        )
    here, there = renders.resolve(), out.resolve()
    if here == there or here.is_relative_to(there) or there.is_relative_to(here):
        raise ParameterError(
            f"{names[0]} ({str(renders)!r}) and {names[1]} ({str(out)!r}) must not hold one another: the output is "
            "replaced as a whole, the renders are kept"
        )
    return renders


def check_methods(methods: Sequence[str]) -> tuple[str, ...]:
    """``methods`` if every one is a registered method
    (:func:`simulator.experiments.methods.method_names`), else :class:`ParameterError` naming it."""
    from simulator.experiments.methods import method_names

    registered = method_names()
    return tuple(one_of("method", method, registered) for method in methods)


def load_experiments() -> dict[str, Experiment]:
    """Import the experiment modules (which register themselves) and return :data:`EXPERIMENTS`."""
    from simulator.experiments import averaging, fov, objects, pipeline, planes  # noqa: F401  (registration)

    return EXPERIMENTS


def experiment_names() -> tuple[str, ...]:
    """The registered experiments' names, sorted."""
    return tuple(sorted(load_experiments()))


def run_experiment(
    name: str,
    *,
    out: str | Path,
    scale: str | None = None,
    methods: Sequence[str] | None = None,
    camera: LightFieldCamera | str | None = None,
    port_distance_m: float | None = None,
    thickness_m: float | None = None,
    tilts_deg: Sequence[float] | None = None,
    f_numbers: Sequence[float] | None = None,
    options: ExperimentOptions | None = None,
    progress: bool = True,
    overwrite: bool = False,
    renders_dir: str | Path | None = None,
) -> ExperimentResult:
    """Run experiment ``name`` into ``out``: its figures, ``table.csv``, ``table.md`` and
    ``meta.json``, assembled in a staging directory (nothing half-written on failure).

    Parameters
    ----------
    name : str
        A registered experiment (:func:`experiment_names`).
    out : path-like
        Output directory: absent (it and its missing parents are created) or empty, or an earlier
        output of the same experiment with ``overwrite``.
    scale, methods, camera, port_distance_m, thickness_m, tilts_deg, f_numbers
        The fields of :class:`ExperimentOptions` (one is made of them; ``scale`` default ``"tiny"``);
        or give ``options``.
    options : ExperimentOptions, optional
        All of them at once (then none of the separate ones may be given).
    progress : bool
        Progress bars on the terminal.
    overwrite : bool
        Replace an earlier output of the same experiment (only that: see docs/conventions.md).
    renders_dir : path-like, optional
        For an experiment that keeps its renders (:attr:`Experiment.keeps_renders`): the folder to keep
        them in (created if absent); a later run reuses those that match its scenes, so an
        interrupted run resumes where it stopped. It must lie outside ``out``, and ``out`` outside it.
        Default: a temporary folder, deleted.

    Returns
    -------
    ExperimentResult
        Its figures' paths inside ``out``.

    Raises
    ------
    ParameterError
        Before any work: for an unknown experiment, scale or method, an invalid option, or one
        that does not apply to the experiment (naming it); for ``renders_dir`` given to an
        experiment that keeps no renders, or overlapping ``out``.
    FileExistsError
        If ``out`` is not empty (and not an earlier output with ``overwrite``).
    """
    from lfrefract.formats.outputs import staged_directory

    experiments = load_experiments()
    experiment = experiments[one_of("experiment", name, tuple(sorted(experiments)))]
    separate = {
        "scale": scale,
        "methods": methods,
        "camera": camera,
        "port_distance_m": port_distance_m,
        "thickness_m": thickness_m,
        "tilts_deg": tilts_deg,
        "f_numbers": f_numbers,
    }
    if options is None:
        options = ExperimentOptions(**{k: v for k, v in separate.items() if v is not None})
    else:
        if not isinstance(options, ExperimentOptions):
            raise ParameterError(f"options must be an ExperimentOptions, got {shown(options)}")
        both = sorted(k for k, v in separate.items() if v is not None)
        if both:
            raise ParameterError(f"give either options or {', '.join(both)}, not both")
    experiment.check(options)
    keep = {} if renders_dir is None else {"renders_dir": check_renders_dir(experiment.name, renders_dir, out)}
    if options.methods is not None:
        check_methods(options.methods)
    start = time.perf_counter()
    with staged_directory(out, kind=f"lfsim.experiment.{name}", overwrite=overwrite) as stage:
        result = experiment.run(stage, options, progress=progress, **keep)
        rows = complete_rows(result.rows)
        write_table(rows, stage)
        write_json(
            stage / SIDECAR_NAME,
            {
                "kind": "lfsim.experiment",
                "experiment": name,
                "scale": options.scale,
                "options": options.to_dict(),
                "parameters": result.parameters,
                "figures": [p.name for p in result.figures],
                "summary": result.summary,
                "renders_dir": None if renders_dir is None else str(renders_dir),
                "seconds": time.perf_counter() - start,
            },
        )
    out_dir = Path(out)
    return ExperimentResult(
        name=result.name,
        scale=result.scale,
        rows=rows,
        figures=tuple(out_dir / p.name for p in result.figures),
        summary=result.summary,
        parameters=result.parameters,
    )
