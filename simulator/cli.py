"""``lfsim``: the simulator's command line.

    lfsim render [SCENE] --out DIR [--camera PRESET] [--lens LENS] [--sensor PRESET] [--frames N] [--lfr]
                 [--rays] [--spp N] [--ideal-spp N] [--seed S] [--overwrite]
    lfsim rig [RIG] --out DIR [--spp N] [--seed S] [--overwrite]
    lfsim experiment NAME --out DIR [--scale tiny|illum] [--methods M1,M2] [--camera CAMERA] [--lens LENS]
                     [--port-distance-m D] [--thickness-m T] [--tilts-deg T1,T2] [--f-numbers N1,N2]
                     [--port-tilt-x-deg A] [--port-tilt-y-deg B] [--n-glass N] [--n-water N]
                     [--ray-model radial|polynomial] [--renders DIR] [--overwrite]
    lfsim whites --out DIR [--camera PRESET] [--sensor PRESET] [--lens LENS] [--focal-lengths-mm F1,F2]
                 [--focus-m D1,inf] [--frames N] [--spp N] [--seed S] [--overwrite]
    lfsim demo [--out DIR] [--overwrite]
    lfsim dataset run SPEC --out DIR [--workers N | --scheduler ADDRESS] [--threads T] [--retries R]
                          [--variant V] [--quiet]
    lfsim dataset check DIR [--sizes-only]
    lfsim scenes

SCENE is a TOML file or the name of an embedded scene (``default``, ``white``); without it the
embedded default scene is rendered. LENS is ``thin``, a lens preset (``lfsim lenses``) or a lens file
(TOML or JSON; ``scenes/lenses/`` holds a family of published designs), scaled to the camera's focal
length and stopped to its f-number. RIG is a stereo rig file (:mod:`simulator.rig`) or the name of
an embedded rig (``default``). SPEC is a sweep spec (:mod:`simulator.dataset.spec`) or the name of
an embedded sweep (``tilt``); ``dataset run`` completes an interrupted run of the same spec in DIR,
and exits with 1 if a sample failed; ``dataset check`` exits with 1 unless every sample is done and
intact (docs/datasets.md). ``experiment`` runs one of :func:`simulator.experiments.experiment_names`
(docs/experiments.md); an option that does not apply to it is refused. ``lfsim --version`` prints the
version; every command's ``--help`` shows its defaults.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.metadata
import math
import sys
from pathlib import Path

from lfrefract import PRESETS, ParameterError, __version__, camera_preset
from lfrefract.errors import FileFormatError
from lfrefract.formats.outputs import MANIFEST_NAME, terminate_cleanly
from lfrefract.optics.lens import LENS_PRESETS
from lfrefract.validate import fields_by_flag, named, positive_int
from simulator.config import (
    DEFAULT_IDEAL_SPP,
    PORT_MODELS,
    THIN_LENS,
    RenderSettings,
    SceneConfig,
    SensorSettings,
    embedded_scenes,
    lens_option,
    load_scene,
    main_lens,
    sensor_model,
)
from simulator.detector import DETECTOR_PRESETS
from simulator.render import DEFAULT_MAX_BAND_PIXELS

__all__ = ["main"]

#: ``lfsim render --sensor none``: no sensor model (raw.exr only), whatever the scene says.
NO_SENSOR = "none"
#: What every ``--lens`` takes (:func:`simulator.config.lens_option`).
LENS_HELP = (
    f"'{THIN_LENS}', a lens preset ({', '.join(sorted(LENS_PRESETS))}: lfsim lenses) or a lens file (TOML or "
    "JSON, e.g. scenes/lenses/tessar.toml: docs/lenses.md), scaled to the camera's focal length and stopped to "
    "its f-number (a design slower than that f-number has its axial beam cut by its own rims)"
)


def _scene_path(arg: str | None) -> Path | None:
    if arg is None:
        return None
    embedded = embedded_scenes()
    if not Path(arg).exists() and arg in embedded:
        return embedded[arg]
    return Path(arg)


def _scene_changed(config: SceneConfig, changes: dict[str, object], flags: list[str]) -> SceneConfig:
    """``config`` with ``changes`` (from ``flags``), and its geometry checked, before any render:
    errors name the scene file and the options that changed it."""
    from simulator.geometry import check_geometry

    where = f"scene file {config.source!r}" + (f" with {', '.join(flags)}" if flags else "")
    with named(where):
        if changes:
            config = config.with_overrides(**changes)
        check_geometry(config)
    return config


class _DefaultsFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """``--help`` with every option's default, except those that have none (``None``, off flags)."""

    def _get_help_string(self, action: argparse.Action) -> str:
        if action.default in (None, False) or action.default is argparse.SUPPRESS:
            return action.help or ""
        return super()._get_help_string(action)


def _version() -> str:
    """The package version, and the installed distribution's if it differs (an older install)."""
    try:
        installed = importlib.metadata.version("lfrefract")
    except importlib.metadata.PackageNotFoundError:
        return f"{__version__} (not installed as a distribution)"
    return __version__ if installed == __version__ else f"{__version__} (installed distribution: {installed})"


def _names(text: str) -> tuple[str, ...]:
    """A comma-separated list of names (``--methods``)."""
    names = tuple(part.strip() for part in text.split(","))
    if not all(names):
        raise argparse.ArgumentTypeError(f"expected names separated by commas, got {text!r}")
    return names


def _numbers(text: str) -> tuple[float, ...]:
    """A comma-separated list of numbers (``--tilts-deg``, ``--f-numbers``)."""
    try:
        return tuple(float(part) for part in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected numbers separated by commas, got {text!r}") from None


def _experiment_help() -> str:
    import textwrap

    from simulator.experiments import OPTION_FLAGS, load_experiments

    lines = ["experiments, and the options each takes:"]
    for name, experiment in sorted(load_experiments().items()):
        takes = ", ".join(OPTION_FLAGS[o] for o in experiment.options) or "no options"
        lines += textwrap.wrap(
            f"{name}: {experiment.description}", width=78, initial_indent="  ", subsequent_indent="    "
        )
        lines += textwrap.wrap(f"options: {takes}", width=76, initial_indent="    ", subsequent_indent="      ")
    return "\n".join(lines)


class _ExperimentFormatter(_DefaultsFormatter, argparse.RawDescriptionHelpFormatter):
    """Defaults shown, and the list of experiments (the epilog) kept as it is written."""


class _ExperimentParser(argparse.ArgumentParser):
    """The ``experiment`` command: its list of experiments is read from the registry when help is
    shown (importing every experiment is not needed for the other commands)."""

    def format_help(self) -> str:
        self.epilog = _experiment_help()
        return super().format_help()


def _command(sub, name: str, *, parser_class: type | None = None, **kwargs) -> argparse.ArgumentParser:
    """A subcommand of ``sub`` whose ``--help`` shows its defaults (optionally of its own parser class)."""
    kwargs.setdefault("formatter_class", _DefaultsFormatter)
    if parser_class is None:
        return sub.add_parser(name, **kwargs)
    previous, sub._parser_class = sub._parser_class, parser_class
    try:
        return sub.add_parser(name, **kwargs)
    finally:
        sub._parser_class = previous


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="lfsim",
        description="Plenoptic camera behind a flat port, in Mitsuba 3.",
        formatter_class=_DefaultsFormatter,
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = parser.add_subparsers(dest="command", required=True)
    render = _command(sub, "render", help="render a scene with its ground truth")
    render.add_argument("scene", nargs="?", help="scene TOML file or embedded scene name (default: 'default')")
    render.add_argument("--out", required=True, type=Path, help="output directory (absent or empty)")
    render.add_argument("--camera", choices=sorted(PRESETS), help="camera preset replacing the scene's")
    render.add_argument("--spp", type=int, help="samples per pixel of the raw image (default: the scene's)")
    render.add_argument(
        "--ideal-spp",
        type=int,
        help="samples per pixel of the ideal (ground-truth) image (default: the scene's render.ideal_spp, "
        f"else {DEFAULT_IDEAL_SPP})",
    )
    render.add_argument("--seed", type=int, help="sampler seed (default: the scene's)")
    render.add_argument("--lens", metavar="LENS", help=f"main lens replacing the scene's camera.lens: {LENS_HELP}")
    render.add_argument(
        "--rays",
        action="store_true",
        help="also write rays.npz: the object-space chief ray of every raw pixel (float32, 24 bytes a pixel)",
    )
    render.add_argument(
        "--sensor",
        choices=[NO_SENSOR, *sorted(DETECTOR_PRESETS)],
        help="sensor model replacing the scene's [sensor]: a detector preset (its pixel pitch and microlens "
        "f-number the camera's), or 'none'; with one, mosaic.npz holds the sensor's integer counts",
    )
    render.add_argument(
        "--frames",
        type=int,
        help="exposures the sensor averages into mosaic.npz (default: the scene's sensor.frames, else 1; "
        "64 for a white image as Lytro ships it)",
    )
    render.add_argument(
        "--lfr",
        action="store_true",
        help="also write the Lytro file of the sensor's bit depth: capture.lfr (10 bits, Illum) or "
        "capture.raw + capture.json (12 bits, F01)",
    )
    render.add_argument(
        "--port-model", choices=list(PORT_MODELS), help="how the port is rendered (default: the scene's)"
    )
    render.add_argument("--variant", choices=["llvm_ad_rgb", "cuda_ad_rgb"], help="Mitsuba variant")
    render.add_argument("--band-pixels", type=int, default=DEFAULT_MAX_BAND_PIXELS, help="pixels per render band")
    render.add_argument("--overwrite", action="store_true", help="replace an earlier render output (only that)")
    render.add_argument("--no-previews", action="store_true", help="skip the PNG previews")
    render.add_argument("--quiet", action="store_true", help="no progress bars")
    rig = _command(sub, "rig", help="render every camera of a stereo rig behind one wall, with ground truth")
    rig.add_argument("rig", nargs="?", help="rig TOML file or embedded rig name (default: 'default')")
    rig.add_argument("--out", required=True, type=Path, help="output directory (absent or empty)")
    rig.add_argument("--spp", type=int, help="samples per pixel (default: the rig's)")
    rig.add_argument("--seed", type=int, help="sampler seed (default: the rig's)")
    rig.add_argument("--overwrite", action="store_true", help="replace an earlier rig output")
    rig.add_argument("--no-previews", action="store_true", help="skip the PNG previews")
    rig.add_argument("--quiet", action="store_true", help="no progress bars")
    exp = _command(
        sub,
        "experiment",
        help="run one of the paper's experiments (table, figures)",
        description="Run one of the paper's experiments; it writes table.csv, table.md, meta.json and its "
        "figures into --out (docs/experiments.md). An option that does not apply to the experiment is refused.",
        formatter_class=_ExperimentFormatter,
        parser_class=_ExperimentParser,
    )
    exp.add_argument("name", help="experiment name (listed below)")
    exp.add_argument("--out", required=True, type=Path, help="output directory (absent or empty; parents are created)")
    exp.add_argument("--scale", choices=["tiny", "illum"], default="tiny", help="problem size")
    exp.add_argument(
        "--methods",
        type=_names,
        help="methods to compare, by name, separated by commas, e.g. 'proposed,approx near' "
        "(default: every registered method)",
    )
    exp.add_argument("--camera", help="camera preset or camera file (TOML or JSON) replacing the experiment's")
    exp.add_argument("--port-distance-m", type=float, help="perpendicular port (wall) distance, metres")
    exp.add_argument("--thickness-m", type=float, help="port (wall) glass thickness, metres (0: no glass)")
    exp.add_argument(
        "--tilts-deg",
        type=_numbers,
        help="port tilts about x, degrees, separated by commas (a negative first one: --tilts-deg=-10,0)",
    )
    exp.add_argument("--f-numbers", type=_numbers, help="main-lens f-numbers, separated by commas")
    exp.add_argument(
        "--port-tilt-x-deg",
        type=float,
        metavar="DEG",
        help="the rig wall's tilt about x, degrees (positive: its normal turned up; default: the rig's)",
    )
    exp.add_argument(
        "--port-tilt-y-deg",
        type=float,
        metavar="DEG",
        help="the rig wall's tilt about y, degrees (positive: its normal turned right; default: the rig's)",
    )
    exp.add_argument("--n-glass", type=float, help="refractive index of the rig wall's glass (default: the rig's)")
    exp.add_argument("--n-water", type=float, help="refractive index of the water (default: the rig's)")
    exp.add_argument(
        "--ray-model",
        metavar="MODEL",
        help="the camera ray model the data-only chain calibrates: radial or polynomial (lfrefract calibrate "
        "camera --ray-model; default: radial)",
    )
    exp.add_argument(
        "--lens",
        metavar="LENS",
        help=(
            "main lens every rig camera renders through (planes, objects: the core assumes a thin lens; "
            f"pipeline: the data-only chain calibrates its ray model): {LENS_HELP}"
        ),
    )
    exp.add_argument(
        "--renders",
        type=Path,
        help="keep the experiment's renders in this folder (outside --out) and reuse those that match on a later "
        "run, so that an interrupted run resumes where it stopped (experiments that render: pipeline, planes)",
    )
    exp.add_argument("--overwrite", action="store_true", help="replace an earlier output of the experiment")
    exp.add_argument("--quiet", action="store_true", help="no progress bars")
    whites = _command(
        sub,
        "whites",
        help="white images per zoom/focus setting through the sensor model, as a Lytro camera ships them",
        description="Render the white image (uniform radiance, no port) at every focal length x focus distance, "
        "through the sensor model with --frames exposures averaged, and write each as the camera does: Illum "
        ".raw + .txt (10-bit sensor) or F01 .raw + .json (12-bit), with its true micro-image centres "
        "(.lenses.npz) and an index, whites.json (docs/simulator.md, 'White images').",
    )
    whites.add_argument("--out", required=True, type=Path, help="output directory (absent or empty)")
    whites.add_argument("--camera", choices=sorted(PRESETS), default="illum", help="camera preset")
    whites.add_argument(
        "--sensor", choices=sorted(DETECTOR_PRESETS), help="detector preset (default: the camera's name)"
    )
    whites.add_argument("--lens", metavar="LENS", default=THIN_LENS, help=f"main lens: {LENS_HELP}")
    whites.add_argument(
        "--focal-lengths-mm", type=_numbers, help="zoom settings, focal lengths in mm (default: the camera's)"
    )
    whites.add_argument(
        "--focus-m", type=_numbers, default=(float("inf"),), help="focus distances from the lens, metres ('inf')"
    )
    whites.add_argument("--frames", type=int, default=64, help="exposures averaged into each white image")
    whites.add_argument("--spp", type=int, default=64, help="samples per pixel of each white render")
    whites.add_argument("--seed", type=int, default=0, help="render seed of the first setting (then +1 each)")
    whites.add_argument("--variant", choices=["llvm_ad_rgb", "cuda_ad_rgb"], help="Mitsuba variant")
    whites.add_argument("--overwrite", action="store_true", help="replace an earlier white-image set (only that)")
    whites.add_argument("--quiet", action="store_true", help="no progress bars")
    demo = _command(sub, "demo", help="the main job: stereo behind a glass wall by every method, with a report")
    demo.add_argument("--out", type=Path, default=Path("demo"), help="output directory")
    demo.add_argument("--overwrite", action="store_true", help="replace an earlier demo output")
    demo.add_argument("--quiet", action="store_true", help="no progress bars")
    dataset = _command(sub, "dataset", help="datasets: sweeps over port tilt and conditions, on Dask")
    dsub = dataset.add_subparsers(dest="dataset_command", required=True)
    drun = _command(dsub, "run", help="render every sample of a sweep spec (or complete an interrupted run)")
    drun.add_argument("spec", help="sweep spec TOML file or embedded sweep name (e.g. 'tilt')")
    drun.add_argument("--out", required=True, type=Path, help="dataset folder (absent, empty, or a run of SPEC)")
    where = drun.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, help="worker processes of the local Dask cluster (default 1)")
    where.add_argument("--scheduler", help="address of a running Dask scheduler, e.g. tcp://host:8786")
    drun.add_argument("--threads", type=int, help="render threads per worker (default: cores / workers locally)")
    drun.add_argument("--retries", type=int, default=2, help="extra attempts of a failing sample")
    drun.add_argument("--variant", choices=["llvm_ad_rgb", "cuda_ad_rgb"], help="Mitsuba variant of the workers")
    drun.add_argument("--quiet", action="store_true", help="no progress bars")
    dcheck = _command(dsub, "check", help="verify every sample of a dataset against its manifest")
    dcheck.add_argument("dir", type=Path, help="dataset folder")
    dcheck.add_argument("--sizes-only", action="store_true", help="compare file sizes, do not re-hash")
    _command(sub, "scenes", help="list the embedded scenes, rigs and sweeps")
    _command(
        sub,
        "lenses",
        help="list the main-lens presets (published multi-element designs)",
        description="List the main-lens presets, one per line: name, focal length and f-number as tabulated "
        "(lfrefract.optics.lens_preset(name, focal_length_m=...) scales one to a camera's), surface count, "
        "source (docs/lenses.md).",
    )
    return parser


def _dataset(args: argparse.Namespace) -> int:
    from simulator.dataset import check_dataset, run_dataset

    if args.dataset_command == "check":
        report = check_dataset(args.dir, hashes=not args.sizes_only)
        for problem in report.problems:
            print(f"{problem.id}: {problem.kind}: {problem.detail}")
        if report.leftovers:
            print(f"leftovers of interrupted writes (the next run removes them): {', '.join(report.leftovers)}")
        if report.inputs_gone:
            print(f"input files not found here (their samples are not checked against them): {report.inputs_gone}")
        print(report.summary())
        return 0 if report.ok else 1
    from simulator.dataset.run import check_run_options

    fields_by_flag(
        check_run_options,
        {
            "--workers": {"workers": args.workers},
            "--threads": {"threads_per_worker": args.threads},
            "--retries": {"retries": args.retries},
        },
    )
    report = run_dataset(
        args.spec,
        args.out,
        workers=args.workers,
        scheduler=args.scheduler,
        threads_per_worker=args.threads,
        retries=args.retries,
        variant=args.variant,
        progress=not args.quiet,
    )
    for sid, error, attempts in report.failed:
        print(f"{sid}: failed after {attempts} attempt(s): {error}", file=sys.stderr)
    rate = report.rendered / report.seconds * 60.0 if report.seconds > 0 else 0.0
    print(
        f"dataset {report.out_dir}: {report.total} samples; {report.rendered} rendered now ({rate:.1f} per minute), "
        f"{report.skipped} already done, {len(report.failed)} failed; {report.seconds:.1f} s"
    )
    if report.verification:
        print(report.verification)
    return 0 if report.ok else 1


def _experiment(args: argparse.Namespace) -> int:
    from lfrefract.formats.capture import camera_model_from_option
    from simulator.experiments import (
        OPTION_FLAGS,
        ExperimentOptions,
        check_methods,
        check_renders_dir,
        load_experiments,
        run_experiment,
    )

    given = {
        "methods": args.methods,
        "port_distance_m": args.port_distance_m,
        "thickness_m": args.thickness_m,
        "tilts_deg": args.tilts_deg,
        "f_numbers": args.f_numbers,
        "lens": None if args.lens is None else lens_option(args.lens),
        "port_tilt_x_deg": args.port_tilt_x_deg,
        "port_tilt_y_deg": args.port_tilt_y_deg,
        "n_glass": args.n_glass,
        "n_water": args.n_water,
        "ray_model": args.ray_model,
    }
    # read here, so that a bad --camera is named by its flag
    camera = None if args.camera is None else camera_model_from_option(args.camera).described_camera
    options = ExperimentOptions(
        scale=args.scale,
        camera=camera,
        **fields_by_flag(ExperimentOptions, {OPTION_FLAGS[key]: {key: value} for key, value in given.items()}),
    )
    experiment = load_experiments().get(args.name)
    if experiment is not None:  # else run_experiment names the experiments there are
        experiment.check(options)  # an option that does not apply, by its flag
        if options.methods is not None:
            with named("--methods"):
                check_methods(options.methods)
        if args.renders is not None:
            check_renders_dir(args.name, args.renders, args.out, names=("--renders", "--out"))
    result = run_experiment(
        args.name,
        out=args.out,
        options=options,
        progress=not args.quiet,
        overwrite=args.overwrite,
        renders_dir=args.renders,
    )
    if result.summary:
        print(result.summary)
    print(f"wrote {args.out}/: table.csv table.md meta.json {' '.join(p.name for p in result.figures)}")
    return 0


def _rig(args: argparse.Namespace) -> int:
    from simulator.rig import RigCamera, load_rig
    from simulator.rig_render import render_rig

    overrides = fields_by_flag(RenderSettings, {"--spp": {"spp": args.spp}, "--seed": {"seed": args.seed}})
    rig = load_rig(args.rig)
    if overrides:
        cameras = tuple(
            RigCamera(c.name, c.scene.with_overrides(render=dataclasses.replace(c.scene.render, **overrides)))
            for c in rig.cameras
        )
        rig = dataclasses.replace(rig, cameras=cameras)
    quiet, previews = args.quiet, not args.no_previews
    out = render_rig(rig, args.out, overwrite=args.overwrite, progress=not quiet, write_previews=previews)
    names = " ".join(f"{c.name}/" for c in rig.cameras)
    print(f"rendered rig {rig.name!r}: {len(rig.cameras)} cameras; wrote {out}/: {names} meta.json")
    return 0


def _whites(args: argparse.Namespace) -> int:
    from simulator.whites import WhiteSetting, check_white_seed, render_whites, white_settings

    camera = camera_preset(args.camera)
    sensor_name = args.sensor or args.camera
    if sensor_name not in DETECTOR_PRESETS:
        raise ParameterError(f"--sensor: camera {args.camera!r} has no detector preset of its name; pass --sensor NAME")
    base = sensor_model(sensor_name, camera)
    lens = lens_option(args.lens)
    with named("--frames"):
        sensor = SensorSettings(detector=base.detector, frames=args.frames)
    fields_by_flag(RenderSettings, {"--spp": {"spp": args.spp}, "--seed": {"seed": args.seed}})
    # Each zoom (given in mm) and each focus distance alone, as the camera takes them.
    zooms = None if args.focal_lengths_mm is None else [f * 1e-3 for f in args.focal_lengths_mm]
    for zoom_mm in args.focal_lengths_mm or ():
        with named(f"--focal-lengths-mm {zoom_mm:g} mm"):
            WhiteSetting(focal_length_m=zoom_mm * 1e-3, focus_distance_m=math.inf).camera(camera)
    for focus in args.focus_m:
        for zoom in zooms or [camera.focal_length_m]:
            at = "" if zooms is None else f" at --focal-lengths-mm {zoom * 1e3:g}"
            with named(f"--focus-m {focus:g}{at}"):
                WhiteSetting(focal_length_m=zoom, focus_distance_m=focus).camera(camera)
    with named("--focal-lengths-mm, --focus-m"):
        settings = white_settings(camera, focal_lengths_m=zooms, focus_distances_m=args.focus_m)
    with named("--seed"):
        check_white_seed(args.seed, len(settings))
    entries = render_whites(
        args.out,
        camera=camera,
        settings=settings,
        sensor=sensor,
        lens=None if lens == THIN_LENS else lens,
        spp=args.spp,
        seed=args.seed,
        variant=args.variant,
        overwrite=args.overwrite,
        progress=not args.quiet,
    )
    for entry in entries:
        print(
            f"{entry['file']}	zoom_step {entry['zoom_step']}	focus_step {entry['focus_step']}	"
            f"f = {entry['focal_length_m'] * 1e3:.3f} mm	lens-MLA {entry['lens_to_mla_m'] * 1e3:.4f} mm"
        )
    print(f"wrote {args.out}/: {len(entries)} white images, whites.json")
    return 0


def _lenses() -> int:
    from lfrefract.optics.lens import LENS_PRESETS

    for name, preset in LENS_PRESETS.items():
        lens = preset.build()
        first = lens.first_order()
        print(
            f"{name}\tf = {first.efl_m * 1e3:.2f} mm\tf/{first.f_number:.2f}\t{len(lens.surfaces)} surfaces\t"
            f"{lens.source}"
        )
    return 0


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    args = _parser().parse_args(argv)
    resumable = getattr(args, "dataset_command", None) == "run" or getattr(args, "renders", None) is not None
    with terminate_cleanly("lfsim", resumable=resumable):
        return _run(args)


def _run(args: argparse.Namespace) -> int:
    try:
        if args.command == "scenes":
            from simulator.rig import embedded_rigs

            for name, path in sorted(embedded_scenes().items()):
                print(f"{name}\t{path}")
            for name, path in sorted(embedded_rigs().items()):
                print(f"{name} (rig)\t{path}")
            from simulator.dataset.spec import embedded_sweeps

            for name, path in sorted(embedded_sweeps().items()):
                print(f"{name} (sweep)\t{path}")
            return 0
        if args.command == "lenses":
            return _lenses()
        if args.command == "whites":
            return _whites(args)
        if args.command == "dataset":
            return _dataset(args)
        if args.command == "rig":
            return _rig(args)
        if args.command == "experiment":
            return _experiment(args)
        if args.command == "demo":
            from simulator.demo import run_demo

            report = run_demo(args.out, progress=not args.quiet, overwrite=args.overwrite)
            print(report.read_text().split("![")[0].rstrip())
            print(f"\nwrote {report} (figures, table.csv, point clouds beside it)")
            return 0
        # Every option alone first, by its flag, before the scene is read and anything rendered.
        render_options = fields_by_flag(
            RenderSettings,
            {
                "--spp": {"spp": args.spp},
                "--ideal-spp": {"ideal_spp": args.ideal_spp},
                "--seed": {"seed": args.seed},
                "--port-model": {"port_model": args.port_model},
            },
        )
        with named("--band-pixels"):
            positive_int("max_band_pixels", args.band_pixels)
        config = load_scene(_scene_path(args.scene))  # its errors name the file
        changes: dict[str, object] = {}
        flags: list[str] = []
        if args.camera:
            changes["camera"] = camera_preset(args.camera)
            flags.append(f"--camera {args.camera}")
        lens_name = args.lens
        if lens_name is None and args.camera and config.lens is not None and config.lens.name in LENS_PRESETS:
            lens_name = config.lens.name  # the scene's preset lens, scaled to the new camera
        if lens_name is not None:
            lens = lens_option(lens_name)  # its errors name --lens (and the file)
            with named(f"scene file {config.source!r} with {', '.join([*flags, f'--lens {lens_name}'])}"):
                changes["lens"] = main_lens(lens, changes.get("camera", config.camera))
            if args.lens is not None:
                flags.append(f"--lens {args.lens}")
        sensor = config.sensor if args.sensor is None else None if args.sensor == NO_SENSOR else args.sensor
        if args.frames is not None:
            if sensor is None:
                raise ParameterError(f"--frames {args.frames} needs a sensor model: pass --sensor NAME")
            with named("--frames"):
                sensor = SensorSettings(detector=sensor_model(sensor, config.camera).detector, frames=args.frames)
            flags.append(f"--frames {args.frames}")
        if sensor is not None or args.sensor is not None:  # a preset name, or the scene's moved to --camera
            changes["sensor"] = None if sensor is None else sensor_model(sensor, changes.get("camera", config.camera))
            if args.sensor is not None:
                flags.append(f"--sensor {args.sensor}")
        if render_options:
            changes["render"] = dataclasses.replace(config.render, **render_options)
        config = _scene_changed(config, changes, flags)
        from simulator.job import render_job

        result = render_job(
            config,
            args.out,
            variant=args.variant,
            max_band_pixels=args.band_pixels,
            overwrite=args.overwrite,
            progress=not args.quiet,
            write_previews=not args.no_previews,
            write_rays=args.rays,
            write_lfr=args.lfr,
        )
    except (ParameterError, FileFormatError, OSError) as exc:
        # OSError covers refusals (FileExistsError), missing files and failed writes (read-only, disk full):
        # one line naming the path; outputs are staged, so an earlier output is still in place.
        print(f"lfsim: error: {exc}", file=sys.stderr)
        return 2
    cam = config.camera
    print(
        f"rendered {config.name!r} with {cam.name} ({cam.sensor.width_px}x{cam.sensor.height_px} px, "
        f"{THIN_LENS if config.lens is None else config.lens.name} main lens, "
        f"{config.render.spp} spp) in {result.raw_seconds:.2f} s; ground truth ({config.render.ideal_spp} spp) "
        f"in {result.ideal_seconds:.2f} s"
    )
    written = sorted(p.name + ("/" if p.is_dir() else "") for p in result.out_dir.iterdir() if p.name != MANIFEST_NAME)
    print(f"wrote {result.out_dir}/: {' '.join(written)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
