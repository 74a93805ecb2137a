"""``lfsim``: the simulator's command line.

    lfsim render [SCENE] --out DIR [--camera PRESET] [--spp N] [--seed S] [--overwrite]
    lfsim rig [RIG] --out DIR [--spp N] [--seed S] [--overwrite]
    lfsim experiment NAME --out DIR [--scale tiny|illum] [--overwrite]
    lfsim demo [--out DIR] [--overwrite]
    lfsim dataset run SPEC --out DIR [--workers N | --scheduler ADDRESS] [--threads T] [--retries R]
                          [--variant V] [--quiet]
    lfsim dataset check DIR [--sizes-only]
    lfsim scenes

SCENE is a TOML file or the name of an embedded scene (``default``, ``white``); without it the
embedded default scene is rendered. RIG is a stereo rig file (:mod:`simulator.rig`) or the name of
an embedded rig (``default``). SPEC is a sweep spec (:mod:`simulator.dataset.spec`) or the name of
an embedded sweep (``tilt``); ``dataset run`` completes an interrupted run of the same spec in DIR,
and exits with 1 if a sample failed; ``dataset check`` exits with 1 unless every sample is done and
intact (docs/datasets.md).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

from lfrefract import PRESETS, ParameterError, camera_preset
from lfrefract.errors import FileFormatError
from lfrefract.formats.outputs import terminate_cleanly
from simulator.config import PORT_MODELS, embedded_scenes, load_scene
from simulator.render import DEFAULT_MAX_BAND_PIXELS

__all__ = ["main"]


def _scene_path(arg: str | None) -> Path | None:
    if arg is None:
        return None
    embedded = embedded_scenes()
    if not Path(arg).exists() and arg in embedded:
        return embedded[arg]
    return Path(arg)


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="lfsim", description="Plenoptic camera behind a flat port, in Mitsuba 3.")
    sub = parser.add_subparsers(dest="command", required=True)
    render = sub.add_parser("render", help="render a scene with its ground truth")
    render.add_argument("scene", nargs="?", help="scene TOML file or embedded scene name (default: 'default')")
    render.add_argument("--out", required=True, type=Path, help="output directory (absent or empty)")
    render.add_argument("--camera", choices=sorted(PRESETS), help="camera preset replacing the scene's")
    render.add_argument("--spp", type=int, help="samples per pixel (default: the scene's)")
    render.add_argument("--seed", type=int, help="sampler seed (default: the scene's)")
    render.add_argument(
        "--port-model", choices=list(PORT_MODELS), help="how the port is rendered (default: the scene's)"
    )
    render.add_argument("--variant", choices=["llvm_ad_rgb", "cuda_ad_rgb"], help="Mitsuba variant")
    render.add_argument("--band-pixels", type=int, default=DEFAULT_MAX_BAND_PIXELS, help="pixels per render band")
    render.add_argument("--overwrite", action="store_true", help="replace an earlier render output (only that)")
    render.add_argument("--no-previews", action="store_true", help="skip the PNG previews")
    render.add_argument("--quiet", action="store_true", help="no progress bars")
    rig = sub.add_parser("rig", help="render every camera of a stereo rig behind one wall, with ground truth")
    rig.add_argument("rig", nargs="?", help="rig TOML file or embedded rig name (default: 'default')")
    rig.add_argument("--out", required=True, type=Path, help="output directory (absent or empty)")
    rig.add_argument("--spp", type=int, help="samples per pixel (default: the rig's)")
    rig.add_argument("--seed", type=int, help="sampler seed (default: the rig's)")
    rig.add_argument("--overwrite", action="store_true", help="replace an earlier rig output")
    rig.add_argument("--no-previews", action="store_true", help="skip the PNG previews")
    rig.add_argument("--quiet", action="store_true", help="no progress bars")
    exp = sub.add_parser("experiment", help="run one of the paper's experiments (table, figures)")
    exp.add_argument("name", help="experiment name (see docs/experiments.md)")
    exp.add_argument("--out", required=True, type=Path, help="output directory (absent or empty)")
    exp.add_argument("--scale", choices=["tiny", "illum"], default="tiny", help="problem size (default: tiny)")
    exp.add_argument("--overwrite", action="store_true", help="replace an earlier output of the experiment")
    exp.add_argument("--quiet", action="store_true", help="no progress bars")
    demo = sub.add_parser("demo", help="the main job: stereo behind a glass wall by every method, with a report")
    demo.add_argument("--out", type=Path, default=Path("demo"), help="output directory (default: demo/)")
    demo.add_argument("--overwrite", action="store_true", help="replace an earlier demo output")
    demo.add_argument("--quiet", action="store_true", help="no progress bars")
    dataset = sub.add_parser("dataset", help="datasets: sweeps over port tilt and conditions, on Dask")
    dsub = dataset.add_subparsers(dest="dataset_command", required=True)
    drun = dsub.add_parser("run", help="render every sample of a sweep spec (or complete an interrupted run)")
    drun.add_argument("spec", help="sweep spec TOML file or embedded sweep name (e.g. 'tilt')")
    drun.add_argument("--out", required=True, type=Path, help="dataset folder (absent, empty, or a run of SPEC)")
    where = drun.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, help="worker processes of the local Dask cluster (default 1)")
    where.add_argument("--scheduler", help="address of a running Dask scheduler, e.g. tcp://host:8786")
    drun.add_argument("--threads", type=int, help="render threads per worker (default: cores / workers locally)")
    drun.add_argument("--retries", type=int, default=2, help="extra attempts of a failing sample (default 2)")
    drun.add_argument("--variant", choices=["llvm_ad_rgb", "cuda_ad_rgb"], help="Mitsuba variant of the workers")
    drun.add_argument("--quiet", action="store_true", help="no progress bars")
    dcheck = dsub.add_parser("check", help="verify every sample of a dataset against its manifest")
    dcheck.add_argument("dir", type=Path, help="dataset folder")
    dcheck.add_argument("--sizes-only", action="store_true", help="compare file sizes, do not re-hash")
    sub.add_parser("scenes", help="list the embedded scenes, rigs and sweeps")
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
    from simulator.experiments import run_experiment

    result = run_experiment(args.name, args.out, scale=args.scale, progress=not args.quiet, overwrite=args.overwrite)
    if result.summary:
        print(result.summary)
    print(f"wrote {args.out}/: table.csv table.md meta.json {' '.join(p.name for p in result.figures)}")
    return 0


def _rig(args: argparse.Namespace) -> int:
    from simulator.rig import RigCamera, load_rig
    from simulator.rig_render import render_rig

    rig = load_rig(args.rig)
    given = {"spp": args.spp, "seed": args.seed}
    overrides = {key: value for key, value in given.items() if value is not None}
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


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    args = _parser().parse_args(argv)
    with terminate_cleanly("lfsim"):
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
        config = load_scene(_scene_path(args.scene))
        changes = {}
        if args.camera:
            changes["camera"] = camera_preset(args.camera)
        given = {"spp": args.spp, "seed": args.seed, "port_model": args.port_model}
        overrides = {key: value for key, value in given.items() if value is not None}
        if overrides:
            changes["render"] = dataclasses.replace(config.render, **overrides)
        if changes:
            config = config.with_overrides(**changes)
        from simulator.job import render_job

        result = render_job(
            config,
            args.out,
            variant=args.variant,
            max_band_pixels=args.band_pixels,
            overwrite=args.overwrite,
            progress=not args.quiet,
            write_previews=not args.no_previews,
        )
    except (ParameterError, FileFormatError, OSError) as exc:
        # OSError covers refusals (FileExistsError), missing files and failed writes (read-only, disk full):
        # one line naming the path; outputs are staged, so an earlier output is still in place.
        print(f"lfsim: error: {exc}", file=sys.stderr)
        return 2
    cam = config.camera
    print(
        f"rendered {config.name!r} with {cam.name} ({cam.sensor.width_px}x{cam.sensor.height_px} px, "
        f"{config.render.spp} spp) in {result.raw_seconds:.2f} s; ground truth in {result.ideal_seconds:.2f} s"
    )
    print(f"wrote {result.out_dir}/: raw.exr ideal.exr depth.exr lenses.npz meta.json previews/")
    return 0


if __name__ == "__main__":
    sys.exit(main())
