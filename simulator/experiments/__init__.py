"""The experiment harness: the paper's evaluation reproduced on the simulator's ground truth.

Each experiment is a function ``run(out_dir, *, scale, progress) -> ExperimentResult`` registered in
:data:`EXPERIMENTS` under its name; ``lfsim experiment NAME --scale tiny|illum --out DIR`` runs it.
An experiment writes into ``out_dir`` (assembled in a staging directory, so it appears complete or
not at all):

- ``table.csv`` and ``table.md``: one row per measured condition, columns with units in their
  names (:func:`write_table`);
- its figures (PNG), listed in the result;
- ``meta.json``: the experiment, scale, parameters and timings (kind ``lfsim.experiment``).

Scales (:data:`SCALES`): ``tiny`` runs in CI in seconds to minutes on two cores; ``illum`` is the
paper's size (the Lytro Illum preset) and takes much longer.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from lfrefract import ParameterError
from lfrefract.formats.jsonio import write_text_atomically
from lfrefract.validate import one_of

__all__ = ["EXPERIMENTS", "SCALES", "ExperimentResult", "load_experiments", "register", "run_experiment", "write_table"]

#: Problem sizes: ``tiny`` (CI) and ``illum`` (the paper's camera).
SCALES = ("tiny", "illum")


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

#: Registered experiments by name (filled by :func:`register`; see :func:`load_experiments`).
EXPERIMENTS: dict[str, ExperimentFunction] = {}


def register(name: str) -> Callable[[ExperimentFunction], ExperimentFunction]:
    """Decorator: register ``run(out_dir, *, scale, progress)`` as experiment ``name``."""

    def wrap(function: ExperimentFunction) -> ExperimentFunction:
        if name in EXPERIMENTS:
            raise ValueError(f"experiment {name!r} registered twice")
        EXPERIMENTS[name] = function
        return function

    return wrap


def check_scale(scale: str) -> str:
    """``scale`` if it is one of :data:`SCALES`, else :class:`ParameterError` naming it."""
    return one_of("scale", scale, SCALES)


def _cell(value) -> str:
    if isinstance(value, float):
        return "nan" if math.isnan(value) else f"{value:.6g}"
    return str(value)


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
    lines += ["| " + " | ".join(_cell(row[k]) for k in keys) + " |" for row in rows]
    md_path = write_text_atomically(Path(out_dir) / f"{stem}.md", "\n".join(lines) + "\n")
    return csv_path, md_path


def load_experiments() -> dict[str, ExperimentFunction]:
    """Import the experiment modules (which register themselves) and return :data:`EXPERIMENTS`."""
    from simulator.experiments import averaging, fov, objects, planes  # noqa: F401  (registration)

    return EXPERIMENTS


def run_experiment(
    name: str, out_dir: str | Path, *, scale: str = "tiny", progress: bool = True, overwrite: bool = False
) -> ExperimentResult:
    """Run experiment ``name`` at ``scale`` into ``out_dir``: its figures, ``table.csv``, ``table.md``
    and ``meta.json``, assembled in a staging directory (nothing half-written on failure).

    Raises
    ------
    ParameterError
        For an unknown experiment or scale (before any work).
    FileExistsError
        If ``out_dir`` is not empty (and not an earlier output with ``overwrite``).
    """
    import time

    from lfrefract.formats.jsonio import write_json
    from lfrefract.formats.outputs import staged_directory

    experiments = load_experiments()
    function = experiments[one_of("experiment", name, tuple(sorted(experiments)))]
    check_scale(scale)
    start = time.perf_counter()
    with staged_directory(out_dir, kind=f"lfsim.experiment.{name}", overwrite=overwrite) as stage:
        result = function(stage, scale=scale, progress=progress)
        write_table(result.rows, stage)
        write_json(
            stage / "meta.json",
            {
                "kind": "lfsim.experiment",
                "experiment": name,
                "scale": scale,
                "parameters": result.parameters,
                "figures": [p.name for p in result.figures],
                "summary": result.summary,
                "seconds": time.perf_counter() - start,
            },
        )
    out = Path(out_dir)
    return ExperimentResult(
        name=result.name,
        scale=result.scale,
        rows=result.rows,
        figures=tuple(out / p.name for p in result.figures),
        summary=result.summary,
        parameters=result.parameters,
    )
