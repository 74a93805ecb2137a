"""``lfrefract``: the core's command line, working on files and presets (no renderer).

    lfrefract describe (PRESET | CAMERA.toml | META.json) [--json]
    lfrefract synth RAW.exr --out OUT.exr [--k K] [--supersample S] [--lambda L] [--map-cache DIR]
                    [--camera PRESET|FILE] [--port PORT.toml|.json|.txt] [--mla MLA.json] [--nonfinite refuse|mask]
                    [--method proposed|depth-aware] [--depth-range MIN MAX] [--depth-steps N]
                    [--aggregation-radius R] [--occlusion-aware] [--overwrite]
    lfrefract naive RAW.exr --out OUT.exr [--kind central|full] [--camera PRESET|FILE] [--nonfinite refuse|mask]
                    [--overwrite]
    lfrefract views RAW.exr --out DIR [--grid 9] [--spacing-px S] [--format png|exr] [--overwrite]
                    [--camera PRESET|FILE] [--nonfinite refuse|mask]
    lfrefract calibrate mla WHITE.exr --out MLA.json [--grid hex|square] [--camera PRESET|FILE] [--overwrite]
    lfrefract calibrate port BOARD.exr... --squares C R --square-size-m S --out PORT.json [--camera PRESET|FILE]
                    [--overwrite]
    lfrefract calibrate approx BOARD.exr... --squares C R --square-size-m S --out APPROX.json [--camera PRESET|FILE]
                    [--overwrite]

Every command refuses an existing output unless ``--overwrite`` is given, and then replaces only an
output of the same kind (docs/conventions.md, "Outputs and --overwrite"); no output may be one of
the command's inputs (the raw image, the ``meta.json`` beside it, a ``--camera``, ``--port`` or
``--mla`` file). ``lfrefract COMMAND --help`` shows every option with its default (taken from the
code it configures: :class:`SynthesisOptions`, :func:`naive_view`, ...); ``lfrefract --version``
the version; ``python -m lfrefract`` is the same command line.

``describe`` prints a camera's derived optics and the default refraction-free image geometry.
``synth`` reads the camera and port from the ``meta.json`` beside ``RAW.exr`` and writes the
refraction-free image ``OUT.exr``, its sidecar ``OUT.json`` (method, K, size, pose, options, coverage
statistics), the coverage map ``OUT.coverage.exr``, the classes ``OUT.filled.exr`` (2 exact, 1
approximated, 0 empty: NaN in ``OUT.exr``) and a figure ``OUT.png``. ``--method proposed`` (the
default) is the warp map alone. ``--method depth-aware`` keeps the warp map's exact pixels and
renders each pixel outside them, where it can, from the recorded rays that see the pixel's scene
point at the depth that a plane sweep over the light field itself finds (no other source of depth):
class 3 in ``OUT.filled.exr``, exact given that depth. It also writes the depth, ``OUT.depth.exr``
(camera-frame z in metres, NaN where none), and its confidence, ``OUT.confidence.exr`` (0 to 1);
``--depth-range``, ``--depth-steps``, ``--aggregation-radius`` and ``--occlusion-aware`` are its
options (:class:`DepthAwareOptions`), refused with the other method. ``naive`` writes the
conventional view with no refraction handling, for comparison. ``views`` writes a regular grid of
sub-aperture views (no refraction handling either) in the HCI 4D light field benchmark layout that
light-field depth-estimation methods read (``lfrefract.formats.viewstack.write_view_stack``).

``calibrate`` estimates what the pipeline would otherwise be told: ``mla`` the microlens lattice
and every micro-image centre from a white image; ``port`` the port's normal and distance from
underwater chessboard captures (corners found in their central views; the glass thickness and
refractive indices are known, from the options or the first capture's ``meta.json``), also written
in the Refractive COLMAP / calibmar flat-port layout (``PORT.txt``); ``approx`` the approximation
baseline (a pinhole with distortion from views at one depth). ``synth --port PORT.json
--mla MLA.json`` uses the estimates instead of the capture's ``meta.json``.

Every command reads its captures with :func:`lfrefract.formats.capture.read_capture`: the raw image and the
``meta.json`` beside it, whose ``camera``, ``port``, ``ideal`` and ``pose`` are checked (a missing or
malformed key is an error naming the file and the key). A bare raw image without ``meta.json``
works too, given ``--camera`` (a preset, or a JSON file with a ``camera`` table such as
``lfrefract describe PRESET --json`` prints) and, for ``synth``, ``--port``. Raw images holding NaN,
infinite or negative values are refused with their count; ``--nonfinite mask`` treats those pixels
as unrecorded instead (no weight in the output; the output says how many). Sizes whose estimated
memory exceeds the memory available are refused before anything is allocated.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import inspect
import json
import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from lfrefract import (
    PRESETS,
    FlatPort,
    LightFieldCamera,
    ParameterError,
    PinholeCamera,
    __version__,
    camera_preset,
    virtual_camera_for,
)
from lfrefract._memory import available_cpus, depth_aware_bytes, require_memory, warp_map_bytes
from lfrefract.calibration import calibrate_approx, calibrate_mla, calibrate_port, calibrate_port_and_camera
from lfrefract.calibration.advice import PortAdvice, advise_port_views
from lfrefract.calibration.approx import KIND as APPROX_KIND
from lfrefract.calibration.approx import MIN_PATTERN_SIDE, MIN_PX_PER_SQUARE, PART_MIN_CORNERS, square_size
from lfrefract.calibration.camera import CAMERA_CALIBRATION_KIND, RAY_MODELS, calibrate_camera, corrected_view
from lfrefract.calibration.camera import MIN_VIEWS as CAMERA_MIN_VIEWS
from lfrefract.calibration.joint import JointCalibration
from lfrefract.calibration.port import (
    CORNER_METHODS,
    MIN_BOARD_CORNERS,
    PORT_CALIBRATION_KIND,
    BoardView,
    PortCalibration,
    PortUndeterminedError,
    board_view_from_light_field,
)
from lfrefract.calibration.port import MIN_VIEWS as PORT_MIN_VIEWS
from lfrefract.errors import CalibrationError, FileFormatError
from lfrefract.figures import save_figure, synth_figure, synth_setup
from lfrefract.formats.capture import (
    NONFINITE_POLICIES,
    RAW_NAME,
    SIDECAR_NAME,
    Capture,
    CaptureParameters,
    apply_depth_aware,
    camera_model_from_option,
    capture_parameters,
    check_lens_modelled,
    check_port_ray_model,
    mask_warp_map,
    mla_from_file,
    port_from_file,
    read_capture,
    read_sidecar,
)
from lfrefract.formats.exr import write_exr
from lfrefract.formats.flatport import write_flat_port
from lfrefract.formats.jsonio import SCHEMA_VERSION, read_json, write_json
from lfrefract.formats.outputs import ExpectedKind, atomic_file, prepare_output_files, terminate_cleanly
from lfrefract.formats.paramfile import MLA_CALIBRATION_KIND, read_camera_file
from lfrefract.formats.viewstack import VIEW_STACK_FORMATS, write_view_stack
from lfrefract.formats.whites import is_lytro_file
from lfrefract.methods import ConventionalView
from lfrefract.optics.camera import GRID_TYPES
from lfrefract.optics.camera_model import BOARD_COLOURS, CameraModel
from lfrefract.optics.ray_correction import PARAMETERS, Correction, RayCorrection
from lfrefract.synthesis.depth_aware import (
    FILLED_EXACT_GIVEN_DEPTH,
    DepthAwareOptions,
    DepthAwareResult,
    DepthAwareSynthesis,
    render_chunks,
    trace_scene_rays,
)
from lfrefract.synthesis.views import VIEW_KINDS, finite_pixels, naive_view, subaperture_stack, view_stack_bytes
from lfrefract.synthesis.warp_map import (
    BLOCK_PIXELS,
    FILLED_APPROXIMATED,
    FILLED_EMPTY,
    FILLED_EXACT,
    PAPER_K,
    SEARCH_METHODS,
    SynthesisOptions,
    WarpMap,
    apply_cfa,
    build_warp_map,
    uses_kdtree,
    warp_map_key,
)
from lfrefract.validate import fields_by_flag, positive_float

#: How ``synth`` takes the colours of a Lytro capture: from the demosaiced image, or from each
#: colour's own Bayer sites. Demosaicing first is the default: on the tiny camera's capture it
#: scored 23.2 dB against 22.1-22.6 dB (docs/cli.md, "Lytro files"): each colour's nearest rays
#: among its own sites lie farther apart than among all pixels, and the colours no longer share them.
COLOUR_MODES = BOARD_COLOURS  # one registry: how a Lytro capture's colours are read
DEFAULT_COLOUR_MODE = "demosaic"
#: How each board command reads a Lytro capture by default (docs/calibration.md, "Board captures from
#: a Lytro file"): ``calibrate port`` on the devignetted mosaic as one grey light field,
#: ``calibrate camera`` as its ray model measured best: the polynomial model as the port's boards
#: (:data:`POLYNOMIAL_BOARD_COLOUR`), the radial one on the demosaiced image; ``calibrate approx``
#: (OpenCV on the central view) on the demosaiced image.
DEFAULT_BOARD_COLOUR = {"port": "cfa", "camera": "demosaic", "approx": "demosaic"}
#: ``calibrate camera --ray-model polynomial`` reads the boards as ``calibrate port`` does, so that the
#: model is fitted to the light-field corners as the port calibration sees them (double-Gauss renders:
#: port normal 0.02 deg from the truth, against 0.75 with the in-air boards demosaiced). The radial
#: model, which does not follow a real lens's rays that closely, measured the other way (0.12-0.17 deg
#: demosaiced, 0.36-0.37 read alike, refined with the port).
POLYNOMIAL_BOARD_COLOUR = "cfa"

#: The methods of ``synth --method``: ``proposed``, the warp map alone (exact inside its coverage,
#: the nearby rays' approximation outside it); ``depth-aware``, the warp map's exact coverage with,
#: outside it, each pixel rendered from the rays that see its point at the depth the light field
#: itself gives (:mod:`lfrefract.synthesis.depth_aware`). The first is the default.
SYNTH_METHODS = ("proposed", "depth-aware")
#: EXR roles of the depth-aware outputs ``OUT.depth.exr`` and ``OUT.confidence.exr``. The depth is
#: an estimate, so not of the role ``depth`` of a render's ground truth (``--overwrite`` never
#: replaces one with the other).
SYNTH_DEPTH_ROLE = "estimated_depth"
SYNTH_CONFIDENCE_ROLE = "confidence"

#: Kinds of the JSON files the commands write (their ``kind``; ``--overwrite`` replaces only these).
SYNTH_KIND = "lfrefract.synth"
MLA_KIND = MLA_CALIBRATION_KIND

__all__ = [
    "CALIBRATE_COMMANDS",
    "COMMANDS",
    "SYNTHESIS_DEFAULTS",
    "Command",
    "build_parser",
    "calibrate_approx_command",
    "calibrate_mla_command",
    "calibrate_port_command",
    "describe",
    "describe_command",
    "main",
    "naive",
    "synth",
    "views",
]


def describe(camera: LightFieldCamera, port: FlatPort | None = None) -> dict:
    """Derived figures of a camera (and port), as plain data."""
    virtual = virtual_camera_for(camera)
    half_w = camera.sensor.size_m[0] / 2 / camera.micro_image_scale
    out = {
        "camera": camera.to_dict(),
        "aperture_radius_m": camera.aperture_radius_m,
        "image_side_f_number": camera.image_side_f_number,
        "mla_f_number": camera.mla.f_number,
        "micro_image_pitch_px": camera.micro_image_pitch_px,
        "micro_image_radius_px": camera.micro_image_radius_px,
        "lens_count": len(camera.lens_indices_on_sensor()),
        "horizontal_fov_in_air_deg": math.degrees(2 * math.atan(half_w / camera.lens_to_mla_m)),
        "refraction_free_image": virtual.to_dict(),
    }
    if port is not None:
        out["port"] = port.to_dict()
        out["port_clearance_m"] = port.clearance_m(camera.aperture_radius_m)
    return out


def _given_model(args: argparse.Namespace) -> CameraModel | None:
    """The camera model of ``--camera``, if given (its file read once: a command reads it here only)."""
    return camera_model_from_option(args.camera) if args.camera is not None else None


def _camera_of(model: CameraModel | None) -> LightFieldCamera | None:
    """The camera of a given model (None: none given, a capture's own camera is used)."""
    return None if model is None else model.camera


def _masked_note(capture: Capture) -> str:
    """What the printed line says about masked raw values (nothing when none were)."""
    if capture.recorded is None:
        return ""
    return f"; masked {capture.unrecorded.describe()} as unrecorded"


def _option_files(args: argparse.Namespace) -> list[Path]:
    """The files named by ``--camera`` (unless a preset), ``--port`` and ``--mla``: inputs too."""
    given = [getattr(args, "camera", None), getattr(args, "port", None), getattr(args, "mla", None)]
    return [Path(v) for v in given if v is not None and not (v in PRESETS and not Path(v).exists())]


def _read_capture(path: str | Path, **options: Any) -> Capture:
    """:func:`read_capture`, saying on stderr which white image developed a Lytro capture (and how far its
    micro-images lie from the capture's), and which files of a white folder were passed over and why."""
    capture = read_capture(path, **options)
    lytro = (capture.sidecar or {}).get("lytro", {}) if capture.developed is not None else {}
    white = lytro.get("white")
    if white is not None:
        for item in white["passed_over"]:
            print(f"{path}: white {item['file']} not used: {item['reason']}", file=sys.stderr)
        print(
            f"{path}: white image {white['file']} (zoom step {white['zoom_step']}, focus step {white['focus_step']}; "
            f"the capture's {lytro['zoom_step']}, {lytro['focus_step']}; its micro-image centres within "
            f"{white['micro_image_shift_px']:.2f} px of the capture's)",
            file=sys.stderr,
        )
    return capture


def _capture_files(path: str | Path) -> list[Path]:
    """A raw image and the sidecar beside it: what a command reads of a capture (given as the raw
    image or as its folder, as :func:`read_capture` takes it; a Lytro ``.raw`` with its metadata)."""
    raw = Path(path) / RAW_NAME if Path(path).is_dir() else Path(path)
    if is_lytro_file(raw):
        return [raw, raw.with_suffix(".json"), raw.with_suffix(".txt")]
    return [raw, raw.parent / SIDECAR_NAME]


def _exr_out(args: argparse.Namespace) -> Path:
    out = Path(args.out)
    if out.suffix.lower() != ".exr":
        raise ParameterError(f"--out must name an .exr file, got {args.out!r}")
    return out


def synth_outputs(out: Path, method: str = SYNTH_METHODS[0]) -> dict[Path, ExpectedKind]:
    """The files ``lfrefract synth --out OUT.exr --method METHOD`` writes, with what each must be to
    be replaced. Only ``depth-aware`` writes (and so claims) ``OUT.depth.exr`` and ``OUT.confidence.exr``."""
    if method not in SYNTH_METHODS:
        raise ParameterError(f"method must be one of {', '.join(SYNTH_METHODS)}, got {method!r}")
    sidecar = out.with_suffix(".json")
    outputs = {
        out: ExpectedKind(exr_role="refraction_free"),
        out.with_suffix(".coverage.exr"): ExpectedKind(exr_role="coverage"),
        out.with_suffix(".filled.exr"): ExpectedKind(exr_role="filled"),
    }
    if method == "depth-aware":
        outputs[out.with_suffix(".depth.exr")] = ExpectedKind(exr_role=SYNTH_DEPTH_ROLE)
        outputs[out.with_suffix(".confidence.exr")] = ExpectedKind(exr_role=SYNTH_CONFIDENCE_ROLE)
    return {
        **outputs,
        sidecar: ExpectedKind(json_kind=SYNTH_KIND),
        out.with_suffix(".png"): ExpectedKind(listed_in=sidecar, listed_kind=SYNTH_KIND),
    }


_Options = TypeVar("_Options")


def _depth_aware_options(args: argparse.Namespace) -> DepthAwareOptions | None:
    """The :class:`DepthAwareOptions` of ``synth --method depth-aware`` (None for another method).

    Raises
    ------
    ParameterError
        If a depth-aware option is given with another method, or a value is invalid (naming the option).
    """
    given: dict[str, dict[str, Any]] = {}  # option -> the DepthAwareOptions fields it sets
    if args.depth_range is not None:
        given["--depth-range"] = {"depth_min_m": args.depth_range[0], "depth_max_m": args.depth_range[1]}
    if args.depth_steps is not None:
        given["--depth-steps"] = {"depth_steps": args.depth_steps}
    if args.aggregation_radius is not None:
        given["--aggregation-radius"] = {"aggregation_radius_px": args.aggregation_radius}
    if args.occlusion_aware:
        given["--occlusion-aware"] = {"occlusion_aware": True}
    if args.method != "depth-aware":
        if given:
            raise ParameterError(
                f"{' and '.join(given)} {'applies' if len(given) == 1 else 'apply'} to --method depth-aware only "
                f"(--method is {args.method})"
            )
        return None
    return _options_by_flag(DepthAwareOptions, given)


def _options_by_flag(kind: type[_Options], given: dict[str, dict[str, Any]]) -> _Options:
    """``kind(**fields)`` of the options given on the command line, each flag's value checked alone so
    that its error names the flag (:func:`lfrefract.validate.fields_by_flag`)."""
    return kind(**fields_by_flag(kind, given))


def _synthesis_options(args: argparse.Namespace) -> SynthesisOptions:
    """The :class:`SynthesisOptions` of ``synth``'s flags (without the ray model), each value checked
    against its flag before anything is read."""
    return _options_by_flag(
        SynthesisOptions,
        {
            "--k": {"k": args.k},
            "--supersample": {"supersample": args.supersample},
            "--lambda": {"lambda_m_per_rad": args.lam},
            "--search": {"search": args.search},
        },
    )


def synth(args: argparse.Namespace) -> int:
    """``lfrefract synth``: refraction-free image of a raw capture."""
    out = _exr_out(args)
    depth_options = _depth_aware_options(args)
    flag_options = _synthesis_options(args)
    given = _given_model(args)
    capture = _read_capture(
        args.raw,
        camera=_camera_of(given),
        port=port_from_file(args.port) if args.port is not None else None,
        nonfinite=args.nonfinite,
        white=args.white,
    )
    camera = _known(capture.camera, capture.raw_path)
    if args.mla:
        camera = mla_from_file(args.mla).calibrated_camera(camera)
    port = capture.port
    if port is None:
        where = (
            f"its sidecar {str(capture.sidecar_path)!r} has no port" if capture.sidecar_path else "it has no meta.json"
        )
        raise ParameterError(f"{args.raw!r}: {where}, and no --port was given; nothing to remove")
    by_cfa = _colour_by_cfa(args, capture)
    model = _capture_model(given, capture, camera)
    if args.port is not None:
        check_port_ray_model(args.port, model)
    if depth_options is not None:
        _depth_aware_takes(by_cfa)
    inputs = [*_capture_files(args.raw), *_option_files(args)]
    prepare_output_files(synth_outputs(out, args.method), inputs=inputs, overwrite=args.overwrite)  # before the map
    options = dataclasses.replace(flag_options, ray_correction=model.correction)
    output = capture.output
    developed = capture.developed
    result: DepthAwareResult | None = None
    rays_seconds = 0.0
    if by_cfa and developed is not None:
        # One map per colour, each gathering from that colour's raw pixels of the developed mosaic.
        per_colour = {
            colour: dataclasses.replace(options, cfa_pattern=developed.cfa_pattern, cfa_colour=colour)
            for colour in "RGB"
        }
        start = time.perf_counter()
        built = {colour: _synth_map(args, camera, port, output, opts, 1) for colour, opts in per_colour.items()}
        map_seconds = time.perf_counter() - start
        how = "; ".join(f"{colour}: {h}" for colour, (_, h) in built.items())
        compile_seconds = built["G"][0].compile_for(developed.values)  # the colours' maps share the gather
        start = time.perf_counter()
        maps = {colour: mask_warp_map(w, ~developed.flagged) for colour, (w, _) in built.items()}
        image = np.maximum(apply_cfa(maps, developed.values) @ developed.color_matrix.T, 0.0).astype(np.float32)
        apply_seconds = time.perf_counter() - start
        warp = maps["G"]  # the colours share the coverage (it is the necessary rays'); G for the figures
        nonzeros = float(np.mean([len(m.indices) / max(1, len(m.gain)) for m in maps.values()]))
        keys: str | dict = {colour: w.key for colour, (w, _) in built.items()}
        classes = warp.filled_classes
        for colour_map in maps.values():  # a pixel some colour has no ray for has no value
            classes[~colour_map.filled] = FILLED_EMPTY
    else:
        if depth_options is not None:  # before the map is built
            require_memory(
                f"synth --method depth-aware: {depth_options.depth_steps} depth planes of a {output.width_px} x "
                f"{output.height_px} px image from {camera.sensor.width_px} x {camera.sensor.height_px} raw pixels",
                depth_aware_bytes(
                    raw_pixels=camera.sensor.width_px * camera.sensor.height_px,
                    output_pixels=output.width_px * output.height_px,
                    channels=capture.channels,
                    depth_steps=depth_options.depth_steps,
                    threads=available_cpus(),
                    render_chunks=render_chunks(),
                ),
                reduce="fewer --depth-steps (or a smaller image: --supersample)",
            )
        start = time.perf_counter()
        warp, how = _synth_map(args, camera, port, output, options, capture.channels)
        map_seconds = time.perf_counter() - start
        if depth_options is not None:
            start = time.perf_counter()
            rays = trace_scene_rays(
                model,
                port,
                rim_margin_px=depth_options.rim_margin_px,
                compensate_port=depth_options.compensate_port,
            )
            rays_seconds = time.perf_counter() - start
        compile_seconds = warp.compile_for(capture.raw)  # numba's first compilation, apart from the apply
        start = time.perf_counter()
        warp = mask_warp_map(warp, capture.recorded)  # unrecorded raw pixels: no weight (the cache keeps the full map)
        if depth_options is None:
            image = warp.apply(capture.raw)
            classes = warp.filled_classes
        else:
            synthesis = DepthAwareSynthesis(warp=warp, rays=rays, options=depth_options)
            result = apply_depth_aware(synthesis, capture)
            image, classes = result.image, result.classes
        apply_seconds = time.perf_counter() - start
        nonzeros = float(len(warp.indices) / max(1, len(warp.gain)))
        keys = warp.key
    image[classes == FILLED_EMPTY] = np.nan  # the project's "no value" (docs/conventions.md)
    if result is None:
        stats = {
            "exact_fraction": float(np.mean(classes == FILLED_EXACT)),
            "filled_fraction": float(np.mean(classes != FILLED_EMPTY)),
        }
    else:
        stats = result.coverage
    stats = {**stats, "mean_coverage": float(warp.coverage.mean()), "nonzeros_per_pixel": nonzeros}
    figure = out.with_suffix(".png")
    files = {
        "image": out.name,
        "coverage": out.with_suffix(".coverage.exr").name,
        "filled": out.with_suffix(".filled.exr").name,
    }
    filled_classes = {"empty": FILLED_EMPTY, "approximated": FILLED_APPROXIMATED, "exact": FILLED_EXACT}
    extra: dict[str, Any] = {}  # the depth-aware method's own keys
    seconds = {"map": map_seconds, "compile": compile_seconds, "apply": apply_seconds}
    write_exr(out, image, role="refraction_free")
    write_exr(out.with_suffix(".coverage.exr"), warp.coverage.astype(np.float32), role="coverage")
    write_exr(out.with_suffix(".filled.exr"), classes, role="filled")
    if result is not None and depth_options is not None:  # the depth-aware method
        write_exr(out.with_suffix(".depth.exr"), result.depth.depth_m.astype(np.float32), role=SYNTH_DEPTH_ROLE)
        write_exr(
            out.with_suffix(".confidence.exr"), result.depth.confidence.astype(np.float32), role=SYNTH_CONFIDENCE_ROLE
        )
        files.update(depth=out.with_suffix(".depth.exr").name, confidence=out.with_suffix(".confidence.exr").name)
        filled_classes["exact_given_depth"] = FILLED_EXACT_GIVEN_DEPTH
        extra = {"depth_options": depth_options.to_dict()}
        seconds = {"map": map_seconds, "rays": rays_seconds, "compile": compile_seconds, "apply": apply_seconds}
    write_json(
        out.with_suffix(".json"),
        {
            "kind": SYNTH_KIND,
            "method": args.method,
            "source": str(args.raw),
            "K": warp.output.K.tolist(),
            "width_px": warp.output.width_px,
            "height_px": warp.output.height_px,
            "pose": None if capture.pose is None else capture.pose.to_dict(),
            "camera": camera.to_dict(),
            "port": port.to_dict(),
            "options": options.to_dict(),
            **extra,
            "colour": "cfa" if by_cfa else ("demosaic" if developed is not None else "raw"),
            "unrecorded_raw": _unrecorded_summary(capture, by_cfa),
            "map_key": keys,
            "coverage": stats,
            "seconds": seconds,
            "files": {**files, "figure": figure.name},
            "filled_classes": filled_classes,
        },
    )
    if result is None or depth_options is None:  # the proposed method
        _figure(figure, image, warp, camera=camera, port=port, method=args.method)
        print(
            f"{how} warp map ({map_seconds:.2f} s), compiled in {compile_seconds * 1e3:.0f} ms (first run only: "
            f"numba caches it), applied in {apply_seconds * 1e3:.1f} ms; exact coverage "
            f"{stats['exact_fraction']:.1%}, filled {stats['filled_fraction']:.1%}{_masked_note(capture)}; wrote {out}"
        )
        return 0
    _figure(figure, image, warp, camera=camera, port=port, method=args.method, result=result, options=depth_options)
    print(
        f"{how} warp map ({map_seconds:.2f} s), rays traced in {rays_seconds:.2f} s, depth-aware synthesis in "
        f"{apply_seconds:.2f} s; exact coverage {stats['exact_fraction']:.1%}, exact given depth "
        f"{stats['exact_given_depth_fraction']:.1%}, filled {stats['filled_fraction']:.1%}{_masked_note(capture)}; "
        f"wrote {out}"
    )
    return 0


def _depth_aware_takes(by_cfa: bool) -> None:
    """Refuse what ``synth --method depth-aware`` cannot take: a Lytro capture's colours from their own
    Bayer sites (``--colour cfa``)."""
    if by_cfa:
        raise ParameterError(
            "--colour cfa does not apply to --method depth-aware: it searches the depth and renders on the "
            "demosaiced image (use --colour demosaic)"
        )


def _unrecorded_summary(capture: Capture, by_cfa: bool) -> dict | None:
    """What ``synth`` gave no weight: the masked raw values, or with ``--colour cfa`` the flagged
    pixels of the mosaic themselves (no demosaicing spread them)."""
    developed = capture.developed
    if not by_cfa or developed is None:
        return capture.masked_summary()
    if not developed.flagged.any():
        return None
    return {
        "policy": "masked as unrecorded (a Lytro capture's saturated pixels, its white image's bad pixels and the "
        "pixels the white does not light)",
        "pixels": int(developed.flagged.sum()),
    }


def _colour_by_cfa(args: argparse.Namespace, capture: Capture) -> bool:
    """Whether ``synth`` gathers each colour from its own CFA pixels (``--colour cfa``) rather than
    from the demosaiced image (the default for a Lytro capture)."""
    if capture.developed is None:
        if args.colour is not None:
            raise ParameterError(
                f"--colour {args.colour} applies to a Lytro capture (its Bayer mosaic); {args.raw!r} is a linear "
                "raw image already"
            )
        return False
    return (args.colour or DEFAULT_COLOUR_MODE) == "cfa"


def _synth_map(
    args: argparse.Namespace, camera: LightFieldCamera, port, output, options: SynthesisOptions, channels: int
) -> tuple[WarpMap, str]:
    """The warp map of ``options``: loaded from ``--map-cache`` if it holds it, else built (and cached)."""
    key = warp_map_key(camera, port, output, options)
    cached = Path(args.map_cache) / f"{key}.npz" if args.map_cache else None
    building = cached is None or not cached.is_file()
    require_memory(
        f"synth: the warp map of a {output.width_px} x {output.height_px} px refraction-free image "
        f"(supersample {options.supersample}, k {options.k})",
        warp_map_bytes(
            output_pixels=output.width_px * output.height_px,
            raw_pixels=camera.sensor.width_px * camera.sensor.height_px,
            channels=channels,
            supersample=options.supersample,
            k=options.k,
            kdtree=building and uses_kdtree(camera, options),
            workers=available_cpus() if building else 0,
            block_pixels=BLOCK_PIXELS,
        ),
        reduce="a smaller --supersample or --k",
    )
    if cached is not None and cached.is_file():
        return WarpMap.load(cached, expected_key=key), f"loaded {cached}"
    warp = build_warp_map(camera, port, output=output, options=options, progress=not args.quiet)
    if cached is None:
        return warp, "built"
    warp.save(cached)
    return warp, f"built, cached as {cached}"


def _figure(
    path: Path,
    image: np.ndarray,
    warp: WarpMap,
    *,
    camera: LightFieldCamera,
    port: FlatPort,
    method: str,
    result: DepthAwareResult | None = None,
    options: DepthAwareOptions | None = None,
) -> None:
    """The figure of ``synth`` (:func:`lfrefract.figures.synth_figure`): the image with the edge of
    its exact coverage and, for ``--method depth-aware``, the depth found in the light field beside it."""
    fig = synth_figure(
        image,
        warp.coverage,
        setup=synth_setup(camera, port, warp.output, method=method),
        depth_m=None if result is None else result.depth.depth_m,
        depth_range_m=None if options is None else (options.depth_min_m, options.depth_max_m),
    )
    with atomic_file(path) as tmp:
        save_figure(fig, tmp)


def naive(args: argparse.Namespace) -> int:
    """``lfrefract naive``: conventional view with no refraction handling."""
    out = _exr_out(args)
    given = _given_model(args)
    capture = _read_capture(args.raw, camera=_camera_of(given), nonfinite=args.nonfinite, white=args.white)
    prepare_output_files(
        {out: ExpectedKind(exr_role=f"naive_{args.kind}")},
        inputs=[*_capture_files(args.raw), *_option_files(args)],
        overwrite=args.overwrite,
    )
    image = naive_view(
        _capture_model(given, capture),
        capture.raw,
        output=capture.output,
        kind=args.kind,
        recorded=capture.recorded,
    )
    write_exr(out, image, role=f"naive_{args.kind}")
    print(f"wrote {args.out}{_masked_note(capture)}")
    return 0


def views(args: argparse.Namespace) -> int:
    """``lfrefract views``: a grid of sub-aperture views in the HCI benchmark layout."""
    if not (args.grid >= 3 and args.grid % 2):  # before the capture is read, named as the option
        raise ParameterError(f"--grid must be an odd integer >= 3 (a central view with neighbours), got {args.grid}")
    given = _given_model(args)
    capture = _read_capture(args.raw, camera=_camera_of(given), nonfinite=args.nonfinite, white=args.white)
    camera, output = _known(capture.camera, capture.raw_path), capture.output
    require_memory(
        f"views: a {args.grid} x {args.grid} stack of {output.width_px} x {output.height_px} px views "
        f"with {capture.channels} channel(s), and its export",
        view_stack_bytes(camera, output, grid=args.grid, channels=capture.channels, exported=True),
        reduce="a smaller --grid",
    )
    stack = subaperture_stack(
        _capture_model(given, capture),
        capture.raw,
        grid=args.grid,
        spacing_px=args.spacing_px,
        output=output,
        recorded=capture.recorded,
    )
    out = write_view_stack(
        Path(args.out),
        stack,
        overwrite=args.overwrite,
        image_format=args.format,
        inputs=[*_capture_files(args.raw), *_option_files(args)],
        metadata={
            "source": str(args.raw),
            "pose": None if capture.pose is None else capture.pose.to_dict(),
            "unrecorded_raw": capture.masked_summary(),
        },
    )
    print(
        f"{stack.grid} x {stack.grid} views of {output.width_px} x {output.height_px} px, spacing "
        f"{stack.spacing_px:.4g} px, baseline {stack.baseline_m * 1e3:.4g} mm, disparity "
        f"{output.focal_px * stack.baseline_m:.4g} px m / depth{_masked_note(capture)}; wrote {out}"
    )
    return 0


def calibrate_mla_command(args: argparse.Namespace) -> int:
    """``lfrefract calibrate mla``."""
    out = Path(args.out)
    # Read with its unrecorded values masked, to refuse them here: a white image must record every pixel,
    # and calibrate mla has no --nonfinite to offer.
    capture = read_capture(args.white, camera=_camera_of(_given_model(args)), camera_required=False, nonfinite="mask")
    if capture.unrecorded.values:
        raise ParameterError(
            f"{str(args.white)!r} has {capture.unrecorded.describe()}: a white image must record every pixel "
            "(calibrate mla takes none unrecorded); give a white image without them"
        )
    prepare_output_files(
        {out: ExpectedKind(json_kind=MLA_KIND)},
        inputs=[*_capture_files(args.white), *_option_files(args)],
        overwrite=args.overwrite,
    )
    try:
        result = calibrate_mla(capture.raw, grid=args.grid)
    except ParameterError as exc:  # the library names the image "white": the user gave a file
        raise type(exc)(f"{str(args.white)!r}: {exc}") from None
    data = {"kind": MLA_KIND, "source": str(args.white), "mla": result.to_dict()}
    if capture.camera is not None:  # from --camera or the meta.json beside the white image
        data["camera"] = result.calibrated_camera(capture.camera).to_dict()
    write_json(out, data)
    counts = result.status_counts()
    print(
        f"{result.grid} lattice, pitch {result.pitch_px:.4f} px, rotation {math.degrees(result.rotation_rad):.4f} deg; "
        f"{counts.get('used', 0)} micro-images used, residual {result.residual_rms_px:.4f} px RMS; wrote {args.out}"
    )
    return 0


def _known(camera: LightFieldCamera | None, where: object) -> LightFieldCamera:
    """The camera of a capture or sidecar read with ``camera_required`` (the default), which has one."""
    if camera is None:
        raise ParameterError(f"{str(where)!r}: no camera was given and its sidecar has none")
    return camera


def _board_parameters(args: argparse.Namespace, given: CameraModel | None) -> CaptureParameters:
    """The parameters of the first board capture, after every capture's sidecar is checked (before
    any raw image is read) and found to have the same camera (or ``--camera`` is given)."""
    if min(args.squares) < MIN_PATTERN_SIDE + 1:
        raise ParameterError(
            f"--squares must be at least {MIN_PATTERN_SIDE + 1} x {MIN_PATTERN_SIDE + 1} ({MIN_PATTERN_SIDE} x "
            f"{MIN_PATTERN_SIDE} inner corners, the fewest the detector finds), got {args.squares!r}"
        )
    for size in args.square_size_m if isinstance(args.square_size_m, list) else [args.square_size_m]:
        square_size("--square-size-m", size)
    _distinct_captures(args.boards)
    found = [capture_parameters(path, camera=_camera_of(given)) for path in args.boards]
    for path, other in zip(args.boards, found, strict=True):
        if other.camera != found[0].camera:
            raise ParameterError(f"{path!r} was taken with another camera than {args.boards[0]!r}")
    camera = found[0].camera
    if camera is not None:  # the board is located in the central view: one pixel per microlens
        view = virtual_camera_for(camera)
        if max(args.squares) * MIN_PX_PER_SQUARE > max(view.width_px, view.height_px):
            raise ParameterError(
                f"--squares {args.squares[0]} {args.squares[1]}: a board of that many squares cannot be located in "
                f"the {view.width_px} x {view.height_px} px central view of {camera.name!r} (a square needs at least "
                f"{MIN_PX_PER_SQUARE} px there); give the board's own count of squares"
            )
    return found[0]


def _capture_model(
    given: CameraModel | None, capture: Capture | CaptureParameters, camera: LightFieldCamera | None = None
) -> CameraModel:
    """The camera model a command uses on ``capture``: the ray model of ``--camera`` (``given``; None:
    the thin lens) on the capture's camera (or on ``camera``: an MLA calibration's), once a capture
    taken through a real main lens that the thin lens would stand for is refused
    (:func:`check_lens_modelled`)."""
    check_lens_modelled(capture, given)
    camera = _known(capture.camera if camera is None else camera, capture.raw_path)
    return CameraModel(camera=camera) if given is None else given.with_camera(camera)


def _boards_lens_modelled(args: argparse.Namespace, given: CameraModel | None) -> None:
    """:func:`check_lens_modelled` for every board capture, before any raw image is read."""
    for path in args.boards:
        check_lens_modelled(capture_parameters(path, camera=_camera_of(given)), given)


def _distinct_captures(paths: list[str]) -> None:
    """Refuse a board capture given twice: the same file, a link to it or a copy of it (equal content),
    before any is read (:mod:`lfrefract.calibration.distinct` refuses two of one pose after detection)."""
    seen: dict[tuple[int, bytes], str] = {}
    for path in paths:
        file = Path(path)
        if not file.is_file():
            continue  # read_capture names a missing file
        digest = hashlib.sha256()
        with file.open("rb") as stream:
            for block in iter(lambda: stream.read(1 << 24), b""):
                digest.update(block)
        key = (file.stat().st_size, digest.digest())
        if key in seen:
            raise CalibrationError(
                f"{seen[key]!r} and {path!r} are the same capture (the same file, a link to it or a copy of it): "
                "give each capture once, and captures of the board in other poses"
            )
        seen[key] = path


def _board_inputs(args: argparse.Namespace) -> list[Path]:
    return [f for path in args.boards for f in _capture_files(path)] + _option_files(args)


def _board_raw(
    path: str,
    camera: LightFieldCamera,
    white: str | None = None,
    colour: str | None = None,
    *,
    command: str,
    nonfinite: str = NONFINITE_POLICIES[0],
) -> np.ndarray:
    """One board capture's raw image, checked (read one at a time: an Illum raw image is 0.5 GB): for
    a Lytro capture its grey mosaic (``colour`` ``"cfa"``) or its demosaiced image (``"demosaic"``,
    :meth:`DevelopedCapture.measured`), NaN where its white gives no light; None: ``command``'s
    default (:data:`DEFAULT_BOARD_COLOUR`)."""
    return _board_image(path, camera, white, colour, default=DEFAULT_BOARD_COLOUR[command], nonfinite=nonfinite)[0]


def _board_image(
    path: str,
    camera: LightFieldCamera,
    white: str | None,
    colour: str | None,
    *,
    default: str,
    nonfinite: str,
) -> tuple[np.ndarray, str | None]:
    """:func:`_board_raw`'s image and how it was read (``colour``, else ``default``: ``"cfa"`` or
    ``"demosaic"``; None: a linear raw image, read as it is)."""
    capture = _read_capture(path, camera=camera, white=white, nonfinite=nonfinite)
    if capture.developed is None:
        if colour is not None:
            raise ParameterError(
                f"--colour {colour} applies to a Lytro capture (its Bayer mosaic); {path!r} is a linear raw "
                "image already"
            )
        if capture.recorded is not None:  # --nonfinite mask: unrecorded pixels as NaN, left out of the views
            mask = capture.recorded if capture.raw.ndim == 2 else capture.recorded[..., None]
            return np.where(mask, capture.raw, np.nan), None
        return capture.raw, None
    reading = colour or default
    if reading == "cfa":
        return capture.developed.grey(), reading
    return capture.developed.measured(), reading  # what the white does not light is no black sample of the board


def calibrate_port_command(args: argparse.Namespace) -> int:
    """``lfrefract calibrate port``: corners located in each capture's light field (or in its
    sub-aperture views), then :func:`calibrate_port`."""
    out = Path(args.out)
    if out.suffix.lower() != ".json":
        raise ParameterError(f"--out must name a .json file (the flat port goes beside it as .txt), got {args.out!r}")
    flat_port = out.with_suffix(".txt")
    in_air = _given_model(args)
    first = _board_parameters(args, in_air)
    _boards_lens_modelled(args, in_air)
    outputs = {
        out: ExpectedKind(json_kind=PORT_CALIBRATION_KIND),
        flat_port: ExpectedKind(listed_in=out, listed_kind=PORT_CALIBRATION_KIND),
    }
    prior = None
    if args.refine_camera is not None:
        refined_out = Path(args.refine_camera)
        if refined_out.suffix.lower() != ".json":
            raise ParameterError(f"--refine-camera must name a .json file, got {args.refine_camera!r}")
        if in_air is None:
            raise ParameterError("--refine-camera needs --camera: the camera calibration to refine")
        prior = in_air.estimate()
        outputs[refined_out] = ExpectedKind(json_kind=CAMERA_CALIBRATION_KIND)
    prepare_output_files(outputs, inputs=_board_inputs(args), overwrite=args.overwrite)
    camera = _known(first.camera, first.raw_path)
    known = first.port  # the first capture's port, if its meta.json has one
    view = virtual_camera_for(camera)
    given = {"thickness_m": args.thickness_m, "n_glass": args.n_glass, "n_water": args.n_water}
    missing = [name for name, value in given.items() if value is None and known is None]
    if missing:
        raise ParameterError(
            f"{' and '.join('--' + name.replace('_', '-') for name in missing)} needed: the first capture "
            f"({args.boards[0]!r}) has no port in a meta.json to take them from"
        )
    n_air = known.n_air if known is not None else 1.0
    values = {name: value if value is not None else getattr(known, name) for name, value in given.items()}
    thickness, n_glass, n_water = values["thickness_m"], values["n_glass"], values["n_water"]
    try:  # checked now, not after minutes of corner detection: a port with these (any distance)
        FlatPort(distance_m=1.0, thickness_m=thickness, n_air=n_air, n_glass=n_glass, n_water=n_water)
    except ParameterError as exc:
        raise ParameterError(f"--thickness-m / --n-glass / --n-water: {exc}") from None
    positive_float("--max-normal-std-deg", args.max_normal_std_deg)
    positive_float("--max-distance-std-m", args.max_distance_std_m)
    target_normal = positive_float("--target-normal-std-deg", args.target_normal_std_deg)
    target_distance = positive_float("--target-distance-std-m", args.target_distance_std_m)

    def advice_on(calibration: PortCalibration) -> PortAdvice:
        """What ``calibration`` leaves poorly determined and which views would fix it (the views'
        board geometry from the aperture points: the candidates' information needs no more; the in-air
        model for what added views make of its part, where the calibration propagated it)."""
        return advise_port_views(
            view,
            calibration,
            boards.views,
            target_normal_std_deg=target_normal,
            target_distance_std_m=target_distance,
            camera_model=in_air,
        )

    pattern = (args.squares[0] - 1, args.squares[1] - 1)
    step = args.subaperture_offset_px
    if step != 0 and args.corners != "views":
        raise ParameterError(f"--subaperture-offset-px={step!r} needs --corners views")
    offsets = ((0.0, 0.0),) if step == 0 else ((0.0, 0.0), (step, 0.0), (-step, 0.0), (0.0, step), (0.0, -step))
    boards = _board_views(
        args,
        camera,
        view,
        pattern,
        default_colour=DEFAULT_BOARD_COLOUR["port"],
        minimum=PORT_MIN_VIEWS,
        method=args.corners,
        offsets_px=offsets,
        in_air=in_air,
    )
    views = boards.views
    glass = {
        "thickness_m": thickness,
        "n_air": n_air,
        "n_glass": n_glass,
        "n_water": n_water,
        "distance_range_m": tuple(args.distance_range_m),
        "max_normal_std_deg": args.max_normal_std_deg,
        "max_distance_std_m": args.max_distance_std_m,
        "names": boards.sources,
    }
    joint = None
    correction: Correction | None
    try:
        if prior is not None:  # the port and the camera's ray model together, kept if held-back boards say so
            joint = calibrate_port_and_camera(view, views, prior=prior, **glass)
        if joint is not None and joint.accepted:
            result, correction, model_file = joint.port, joint.correction.correction, args.refine_camera
        else:  # the in-air model (--camera's), also where the refinement was rejected
            correction, model_file = None if in_air is None else in_air.correction, args.camera
            model_views: list[list[BoardView]] = []
            if in_air is not None and correction is not None:  # a calibrated camera: its rays, not the thin lens's
                # The camera model's uncertainty: the views as each direction of its spread would correct them.
                model_views = [[corrected_view(v, moved, view) for v in views] for moved in in_air.spread_corrections()]
                views = [corrected_view(v, correction, view) for v in views]
            result = calibrate_port(view, views, model_views=model_views, **glass)
    except PortUndeterminedError as exc:  # say which views would determine it
        raise CalibrationError("\n".join([str(exc), *advice_on(exc.calibration).lines()])) from None
    advice = advice_on(result)
    data = {
        "kind": PORT_CALIBRATION_KIND,
        **boards.to_dict(),
        "files": {"flat_port": flat_port.name},
        "ray_model": {"camera": model_file, "correction": None if correction is None else correction.to_dict()},
        **result.to_dict(),
    }
    data["advice"] = advice.to_dict()
    if joint is not None:
        data["joint_refinement"] = joint.to_dict()
        write_json(Path(args.refine_camera), _refined_camera(args, joint, out, boards))
    write_json(out, data)
    write_flat_port(flat_port, result.port)
    refined = ""
    if joint is not None and joint.accepted:
        refined = (
            f"; camera refined with it (moved {math.sqrt(joint.prior_chi2):.1f} sigma of its in-air estimate; "
            f"the port on the in-air model alone: distance {joint.sequential.port.distance_m * 1e3:.2f} mm; "
            f"kept: {joint.check.reason}), wrote {args.refine_camera}"
        )
    elif joint is not None:
        refined = (
            f"; the in-air camera model kept, its refinement with the port rejected ({joint.check.reason}); "
            f"wrote {args.refine_camera} as {args.camera} with the refinement's record"
        )
    model_share = ""
    if "camera_model" in result.covariance_parts and np.any(result.covariance_parts["camera_model"]):
        share = result.covariance_parts["camera_model"][2, 2] / max(result.covariance[2, 2], 1e-300)
        model_share = f"; the camera model's uncertainty makes {share:.0%} of the distance's variance"
    print(
        f"port normal {np.round(result.port.normal, 5).tolist()} (+- {result.normal_std_deg:.3f} deg), distance "
        f"{result.port.distance_m * 1e3:.2f} mm (+- {result.distance_std_m * 1e3:.2f}){model_share}, "
        f"residual {result.rms_px:.3f} px RMS over {len(views)} captures{boards.left_out_note()}{refined}; "
        f"wrote {out} and {out.with_suffix('.txt')}"
    )
    for line in advice.lines():
        print(line)
    return 0


def _refined_camera(args: argparse.Namespace, joint: JointCalibration, port_out: Path, boards: _BoardViews) -> dict:
    """The camera calibration of ``--camera`` with the ray model ``calibrate port --refine-camera``
    refined: the same file's data, its correction and covariance replaced, the in-air ones kept
    under ``refinement``; where the held-back check rejected the refinement, the same file's data
    unchanged, the rejected model and the reason under ``refinement``."""
    data = read_json(Path(args.camera))
    data.pop("schema_version", None)  # write_json stamps its own
    refined = joint.joint_correction
    record = {
        "by": "lfrefract calibrate port --refine-camera",
        "camera": str(args.camera),
        "port": str(port_out),
        **boards.to_dict(),
        "accepted": joint.accepted,
        "held_back": joint.check.to_dict(),
        "prior_chi2": joint.prior_chi2,
    }
    if not joint.accepted:
        data["refinement"] = {
            **record,
            "rejected_correction": refined.correction.to_dict(),
            "rejected_correction_covariance": refined.covariance_to_dict(),
            "note": "the refined ray model did not lower the error on held-back boards (held_back.reason): this "
            "file's ray model is the in-air one of camera, unchanged",
        }
        return data
    data["correction"] = refined.correction.to_dict()
    data["correction_std"] = dict(zip(PARAMETERS, refined.std.tolist(), strict=True))
    data["correction_covariance"] = refined.covariance_to_dict()
    data["refinement"] = {
        **record,
        "in_air_correction": joint.prior.correction.to_dict(),
        "in_air_correction_covariance": joint.prior.covariance_to_dict(),
        "note": "ray_rms_m, initial_ray_rms_m, per_view_rms_m, poses, correction_std_clustered and held are the "
        "in-air fit's, with in_air_correction",
    }
    return data


def calibrate_approx_command(args: argparse.Namespace) -> int:
    """``lfrefract calibrate approx``: the approximation baseline on the captures' central views."""
    out = Path(args.out)
    given = _given_model(args)
    first = _board_parameters(args, given)
    _boards_lens_modelled(args, given)
    camera = _known(first.camera, first.raw_path)
    prepare_output_files(
        {out: ExpectedKind(json_kind=APPROX_KIND)}, inputs=_board_inputs(args), overwrite=args.overwrite
    )
    conventional = ConventionalView(camera=_capture_model(given, first), view=virtual_camera_for(camera))

    def central_view(path: str) -> np.ndarray:
        raw = _board_raw(path, camera, args.white, args.colour, command="approx", nonfinite=args.nonfinite)
        return conventional.apply(raw, recorded=finite_pixels(raw))  # NaN: unrecorded (see _board_raw)

    images = [central_view(path) for path in args.boards]
    pattern = (args.squares[0] - 1, args.squares[1] - 1)
    result = calibrate_approx(images, pattern=pattern, square_size_m=args.square_size_m, names=list(args.boards))
    result.save(out)
    print(f"pinhole + distortion from {len(images)} views, {result.rms_px:.3f} px RMS; wrote {args.out}")
    return 0


def _square_sizes(args: argparse.Namespace) -> list[float]:
    """``--square-size-m``: one size for every board capture, or one per capture, as a list per capture."""
    sizes = list(args.square_size_m)
    if len(sizes) not in (1, len(args.boards)):
        raise ParameterError(
            f"--square-size-m takes one size for every capture or one per capture ({len(args.boards)}), "
            f"got {len(sizes)}"
        )
    return sizes * len(args.boards) if len(sizes) == 1 else sizes


#: Why a board capture is left out of a calibration (``left_out`` of its JSON file).
NOT_LOCATED = (
    "no chessboard of {cols} x {rows} inner corners, nor a part of one with "
    f"{PART_MIN_CORNERS} or more, found in its central view, or under {MIN_BOARD_CORNERS} located"
)


@dataclass(frozen=True)
class _BoardViews:
    """The board captures of a calibration: those whose board was located, and those left out."""

    views: list[BoardView]
    sources: list[str]  # the capture of each view
    left_out: list[dict[str, str]]  # {"source": capture, "reason": why}
    colour: str | None  # how the Lytro captures were read ("cfa", "demosaic"); None: linear raw images

    def to_dict(self) -> dict:
        return {"sources": self.sources, "left_out": self.left_out, "board_colour": self.colour}

    def left_out_note(self) -> str:
        return f" ({len(self.left_out)} left out, named above)" if self.left_out else ""


def _check_board_colour(in_air: CameraModel | None, reading: str, *, option: str | None) -> None:
    """Warn where Lytro board captures are read as ``reading`` but the polynomial ray model ``in_air``
    was fitted to boards read otherwise, or its file does not say how they were read."""
    if in_air is None or in_air.ray_model != "polynomial" or in_air.board_colour == reading:
        return  # the radial model's own error is larger than the readings' difference (POLYNOMIAL_BOARD_COLOUR)
    how = f"--colour {option}" if option is not None else f"read as {reading!r} by default"
    if in_air.board_colour is None:
        said = (
            f"{in_air.source} does not say how its board captures were read (board_colour; written before it "
            f"was recorded, it read them demosaiced by default); these are {how}"
        )
    else:
        said = (
            f"{in_air.source}'s ray model was fitted to board captures read as {in_air.board_colour!r}, these are {how}"
        )
    print(
        f"warning: {said}: the light-field corners differ between the two readings and the port absorbs the "
        "difference (a double-Gauss camera, polynomial model: 0.75 deg off against 0.02 read alike); read both "
        "alike (--colour of calibrate camera and calibrate port)",
        file=sys.stderr,
    )


def _board_views(
    args: argparse.Namespace,
    camera: LightFieldCamera,
    view: PinholeCamera,
    pattern: tuple[int, int],
    *,
    default_colour: str,
    minimum: int,
    method: str = "light-field",
    offsets_px: tuple[tuple[float, float], ...] = ((0.0, 0.0),),
    in_air: CameraModel | None = None,
) -> _BoardViews:
    """The corners of every board capture of ``args.boards`` (:func:`board_view_from_light_field`),
    each with its square size. A capture where the board is not located is left out and named on
    stderr (and in the output's ``left_out``); fewer than ``minimum`` located is an error. Lytro
    captures read otherwise than ``in_air``'s calibration boards were (its ``board_colour``) are
    warned about at the first (the polynomial model: fitted to corners read one way, it does not fit
    those read the other)."""
    views, sources, left_out = [], [], []
    first_reading: str | None = None  # how the captures were read; None: linear raw images (--white takes no mix)
    reason = NOT_LOCATED.format(cols=pattern[0], rows=pattern[1])
    for k, (path, size) in enumerate(zip(args.boards, _square_sizes(args), strict=True)):
        image, reading = _board_image(
            path, camera, args.white, args.colour, default=default_colour, nonfinite=args.nonfinite
        )
        if k == 0:
            first_reading = reading
            if reading is not None:
                _check_board_colour(in_air, reading, option=args.colour)
        board_view = board_view_from_light_field(
            camera,
            image,
            pattern=pattern,
            square_size_m=size,
            view=view,
            method=method,
            offsets_px=offsets_px,
            name=str(path),
        )
        if board_view is None:
            print(f"{path}: left out: {reason}", file=sys.stderr)
            left_out.append({"source": str(path), "reason": reason})
            continue
        views.append(board_view)
        sources.append(str(path))
    if len(views) < minimum:
        named = f" (left out: {', '.join(repr(item['source']) for item in left_out)}: {reason})" if left_out else ""
        raise CalibrationError(
            f"the board was located in {len(views)} of {len(args.boards)} captures, under the {minimum} needed{named}"
        )
    return _BoardViews(views=views, sources=sources, left_out=left_out, colour=first_reading)


def calibrate_camera_command(args: argparse.Namespace) -> int:
    """``lfrefract calibrate camera``: the camera's ray model from in-air chessboard light fields."""
    out = Path(args.out)
    if out.suffix.lower() != ".json":
        raise ParameterError(f"--out must name a .json file, got {args.out!r}")
    first = _board_parameters(args, _given_model(args))
    camera = _known(first.camera, first.raw_path)
    prepare_output_files(
        {out: ExpectedKind(json_kind=CAMERA_CALIBRATION_KIND)}, inputs=_board_inputs(args), overwrite=args.overwrite
    )
    view = virtual_camera_for(camera)
    pattern = (args.squares[0] - 1, args.squares[1] - 1)
    colour = POLYNOMIAL_BOARD_COLOUR if args.ray_model == "polynomial" else DEFAULT_BOARD_COLOUR["camera"]
    boards = _board_views(args, camera, view, pattern, default_colour=colour, minimum=CAMERA_MIN_VIEWS)
    views = boards.views
    result = calibrate_camera(
        camera,
        views,
        view=view,
        names=boards.sources,
        ray_model=args.ray_model,
        progress=lambda line: print(line, file=sys.stderr),
    )
    write_json(out, {**result.to_dict(), **boards.to_dict()})
    c = result.correction
    if isinstance(c, RayCorrection):
        slope = (
            "held at 1 (the captures do not determine it)" if "slope_scale" in result.held else f"{c.slope_scale:.5f}"
        )
        terms = f"pupil scale {c.pupil_scale:.5f}, slope scale {slope}, k1 {c.k1:.4g}, k2 {c.k2:.4g}"
    else:
        chosen = next(s for s in result.capacity_scores if s.capacity == c.capacity)
        terms = (
            f"{c.name} ({len(c.exponents)} terms), chosen by the held-back captures' error "
            f"{chosen.held_back_rms_m * 1e3:.4f} mm"
        )
    print(
        f"ray model from {len(views)} captures{boards.left_out_note()}: {terms}; corners "
        f"{result.ray_rms_m * 1e3:.4f} mm RMS from their rays (thin lens: {result.initial_ray_rms_m * 1e3:.4f} mm); "
        f"wrote {args.out}"
    )
    return 0


def describe_command(args: argparse.Namespace) -> int:
    """``lfrefract describe``: a preset's, a camera file's or a ``meta.json``'s camera (and port), as text or JSON."""
    if args.source in PRESETS:
        info = describe(camera_preset(args.source))
    elif Path(args.source).suffix.lower() == ".toml":
        info = describe(read_camera_file(args.source))
    else:
        sidecar = read_sidecar(args.source)
        info = describe(_known(sidecar.camera, args.source), sidecar.port)
    if args.json:
        # A camera file: `lfrefract describe PRESET --json > CAMERA.json` is a --camera of the other commands.
        print(json.dumps({"schema_version": SCHEMA_VERSION, "kind": "lfrefract.describe", **info}, indent=2))
        return 0
    print("\n".join(describe_lines(info)))
    return 0


#: The unit of a value, by its key's suffix (the project's convention), as ``describe`` prints it.
_KEY_UNITS = {"_m": "m", "_deg": "deg", "_rad": "rad", "_px": "px"}
#: Keys whose unit their name does not carry.
_NAMED_UNITS = {"K": "px"}


def format_value(value: object, *, digits: int = 6) -> str:
    """A value as printed for people: floats to ``digits`` significant digits (``1.8``, not
    ``1.7999999999999998``), lists element by element, everything else as ``str``."""
    if isinstance(value, bool) or value is None:
        return str(value)
    if isinstance(value, float):
        return f"{value:.{digits}g}"
    if isinstance(value, list | tuple):
        return "[" + ", ".join(format_value(v, digits=digits) for v in value) + "]"
    return str(value)


def describe_lines(info: dict, *, indent: int = 0) -> list[str]:
    """:func:`describe`'s data as the lines ``lfrefract describe`` prints: ``key: value unit``, a
    nested table indented by two spaces under its key, floats to six significant digits, and the unit
    each key's suffix names (``_m``, ``_deg``, ``_rad``, ``_px``) after the value."""
    lines = []
    for key, value in info.items():
        if isinstance(value, dict):
            lines.append(f"{' ' * indent}{key}:")
            lines += describe_lines(value, indent=indent + 2)
            continue
        unit = _NAMED_UNITS.get(key) or next((u for s, u in _KEY_UNITS.items() if key.endswith(s)), None)
        shown = format_value(value)
        lines.append(f"{' ' * indent}{key}: {shown}" + (f" {unit}" if unit and value is not None else ""))
    return lines


# ----------------------------------------------------------------------------- the parser
#: Defaults of the synthesis options, from :class:`SynthesisOptions` itself (``synth --k`` etc.).
SYNTHESIS_DEFAULTS = {f.name: f.default for f in dataclasses.fields(SynthesisOptions)}
#: Defaults of the depth-aware options, from :class:`DepthAwareOptions` itself (``synth --depth-steps`` etc.).
DEPTH_AWARE_DEFAULTS = {f.name: f.default for f in dataclasses.fields(DepthAwareOptions)}


def _default_of(function: Callable, parameter: str) -> Any:
    """The default value of ``function``'s keyword ``parameter`` (so the CLI cannot drift from it)."""
    return inspect.signature(function).parameters[parameter].default


class _HelpFormatter(argparse.RawDescriptionHelpFormatter, argparse.ArgumentDefaultsHelpFormatter):
    """Shows each option's default after its help, unless it has none (None, a flag) or the help
    already says what it is."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if "default" in text or action.default is None or isinstance(action.default, bool):
            return text
        return super()._get_help_string(action) or text


def _camera_option(
    parser: argparse.ArgumentParser, default: str = "(default: the meta.json beside each raw image)"
) -> None:
    parser.add_argument(
        "--camera",
        metavar="PRESET|FILE",
        help=f"the camera: a preset ({', '.join(sorted(PRESETS))}), a camera file (CAMERA.toml, or JSON with a "
        f"camera table such as `lfrefract describe PRESET --json` output or a render's meta.json) {default}",
    )


def _capture_options(parser: argparse.ArgumentParser) -> None:
    _camera_option(parser, "(default: the meta.json beside the raw image)")
    parser.add_argument(
        "--nonfinite",
        choices=NONFINITE_POLICIES,
        default=NONFINITE_POLICIES[0],
        help=f"raw images with NaN, infinite or negative values: {NONFINITE_POLICIES[0]} them (default), or "
        "mask those pixels as unrecorded (no weight in the output; the output says how many)",
    )
    _white_option(parser)


def _white_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--white",
        metavar="FILE|FOLDER",
        help="for a Lytro capture (.lfr, or .raw with its .json/.txt): its white image, or a folder of them "
        "(the one of the nearest zoom and focus steps is taken), to devignette it; without one the capture is "
        "only black-subtracted",
    )


def _describe_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "source", help=f"a preset ({', '.join(sorted(PRESETS))}), a camera file (CAMERA.toml) or a meta.json file"
    )
    parser.add_argument("--json", action="store_true", help="print JSON")


def _synth_arguments(parser: argparse.ArgumentParser) -> None:
    defaults = SYNTHESIS_DEFAULTS
    parser.add_argument("raw", help="raw lenslet image (EXR) with meta.json in its directory")
    parser.add_argument("--out", required=True, help="output EXR")
    parser.add_argument(
        "--k",
        type=int,
        default=defaults["k"],
        help=f"captured rays averaged per necessary ray; {defaults['k']} scored best on the tiny, f01 and illum "
        f"cameras, the paper used {PAPER_K} (docs/synthesis.md)",
    )
    parser.add_argument(
        "--supersample", type=int, default=defaults["supersample"], help="necessary rays per pixel along each axis"
    )
    parser.add_argument(
        "--lambda",
        dest="lam",
        type=float,
        default=defaults["lambda_m_per_rad"],
        help="angle weight of D, metres per radian",
    )
    parser.add_argument("--search", choices=SEARCH_METHODS, default=defaults["search"], help="candidate search")
    parser.add_argument(
        "--colour",
        choices=COLOUR_MODES,
        help="for a Lytro capture: gather from the demosaiced image (demosaic, the default) or each colour from "
        "its own Bayer sites (cfa: nothing is interpolated across a micro-image's edge)",
    )
    parser.add_argument(
        "--method",
        choices=SYNTH_METHODS,
        default=SYNTH_METHODS[0],
        help="proposed: the warp map alone (exact inside its coverage, approximated from nearby rays outside "
        "it); depth-aware: outside the exact coverage, each pixel rendered from the rays that see its point at "
        "the depth found in the light field itself (also writes OUT.depth.exr and OUT.confidence.exr)",
    )
    depth = DEPTH_AWARE_DEFAULTS
    parser.add_argument(
        "--depth-range",
        type=float,
        nargs=2,
        metavar=("MIN", "MAX"),
        help="with --method depth-aware: nearest and farthest depth searched, camera-frame z, metres "
        f"(default: {depth['depth_min_m']} {depth['depth_max_m']})",
    )
    parser.add_argument(
        "--depth-steps",
        type=int,
        metavar="N",
        help=f"with --method depth-aware: depth planes searched, uniform in 1/z, at least 3 (default: "
        f"{depth['depth_steps']})",
    )
    parser.add_argument(
        "--aggregation-radius",
        type=int,
        metavar="R",
        help="with --method depth-aware: the depth costs are averaged over (2 R + 1) x (2 R + 1) output pixels; "
        f"0 for none (default: {depth['aggregation_radius_px']})",
    )
    parser.add_argument(
        "--occlusion-aware",
        action="store_true",
        help="with --method depth-aware: score and render each pixel with the most consistent of the whole "
        "aperture's rays and each aperture half's (which sees past an occluder that hides the point from the "
        "other half); default: the whole aperture's (docs/synthesis.md measures both)",
    )
    parser.add_argument("--map-cache", help="directory of warp maps, keyed by their parameters")
    parser.add_argument("--quiet", action="store_true", help="no progress bar while building the map")
    parser.add_argument(
        "--port",
        help="port file: PORT.toml, PORT.json or the flat-port PORT.txt of `lfrefract calibrate port` (default: the "
        "capture's meta.json)",
    )
    parser.add_argument("--mla", help="MLA from `lfrefract calibrate mla` (default: the capture's meta.json)")
    parser.add_argument("--overwrite", action="store_true", help="replace an earlier synth output of the same name")
    _capture_options(parser)


def _naive_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("raw", help="raw lenslet image (EXR) with meta.json in its directory")
    parser.add_argument("--out", required=True, help="output EXR")
    parser.add_argument(
        "--kind", choices=VIEW_KINDS, default=_default_of(naive_view, "kind"), help="which view (see naive_view)"
    )
    parser.add_argument("--overwrite", action="store_true", help="replace an earlier naive view of this kind in --out")
    _capture_options(parser)


def _views_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("raw", help="raw lenslet image (EXR) with meta.json in its directory")
    parser.add_argument("--out", required=True, help="output directory")
    parser.add_argument(
        "--grid", type=int, default=_default_of(subaperture_stack, "grid"), help="views per row and column, odd >= 3"
    )
    parser.add_argument(
        "--spacing-px", type=float, help="sensor offset between neighbouring views (default: the largest that fits)"
    )
    parser.add_argument(
        "--format",
        choices=VIEW_STACK_FORMATS,
        default=_default_of(write_view_stack, "image_format"),
        help="view images",
    )
    parser.add_argument("--overwrite", action="store_true", help="replace an earlier view stack in --out")
    _capture_options(parser)


def _calibrate_mla_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("white", help="white image (EXR)")
    parser.add_argument("--out", required=True, help="output JSON")
    parser.add_argument("--grid", choices=GRID_TYPES, help="lattice type (default: detected)")
    _camera_option(parser, "(default: the meta.json beside the white image, if any: its calibrated camera is written)")
    parser.add_argument("--overwrite", action="store_true", help="replace an earlier MLA calibration in --out")


def _default_board_colour_said(target: str) -> str:
    """``--colour``'s default for the board command ``target``, in words."""
    if target == "camera":
        return f"{POLYNOMIAL_BOARD_COLOUR} with --ray-model polynomial, else {DEFAULT_BOARD_COLOUR['camera']}"
    return DEFAULT_BOARD_COLOUR[target]


def _board_arguments(parser: argparse.ArgumentParser, target: str, *, sizes_per_capture: bool = False) -> None:
    parser.add_argument(
        "boards", nargs="+", help="raw captures of a chessboard (EXR with meta.json beside them, or Lytro files)"
    )
    parser.add_argument("--squares", type=int, nargs=2, required=True, metavar=("C", "R"), help="squares of the board")
    if sizes_per_capture:
        parser.add_argument(
            "--square-size-m",
            type=float,
            nargs="+",
            required=True,
            help="edge of a square, metres: one for every capture, or one per capture (boards of several sizes)",
        )
    else:
        parser.add_argument("--square-size-m", type=float, required=True, help="edge of a square, metres")
    parser.add_argument("--out", required=True, help="output JSON")
    parser.add_argument("--overwrite", action="store_true", help=f"replace an earlier {target} calibration in --out")
    _camera_option(parser)
    _white_option(parser)
    parser.add_argument(
        "--nonfinite",
        choices=NONFINITE_POLICIES,
        default=NONFINITE_POLICIES[0],
        help=f"board captures with NaN, infinite or negative values: {NONFINITE_POLICIES[0]} them (default), or "
        "mask those pixels as unrecorded (left out of the views the board is located in)",
    )
    parser.add_argument(
        "--colour",
        choices=COLOUR_MODES,
        help="for Lytro captures: locate the board on the devignetted Bayer mosaic read as one grey light field "
        "(cfa: nothing is interpolated across a micro-image's edge; for a black and white board) or on the "
        f"demosaiced image (demosaic) (default: {_default_board_colour_said(target)}; read a camera's in-air "
        "and underwater boards alike)",
    )


def _calibrate_port_arguments(parser: argparse.ArgumentParser) -> None:
    _board_arguments(parser, "port", sizes_per_capture=True)
    parser.add_argument("--thickness-m", type=float, help="glass thickness (default: the first capture's meta.json)")
    parser.add_argument("--n-glass", type=float, help="glass index (default: meta.json)")
    parser.add_argument("--n-water", type=float, help="water index (default: meta.json)")
    parser.add_argument(
        "--distance-range-m",
        type=float,
        nargs=2,
        metavar=("MIN", "MAX"),
        default=list(_default_of(calibrate_port, "distance_range_m")),
        help="range searched for the port's distance (its air-side face along its normal), metres",
    )
    parser.add_argument(
        "--max-normal-std-deg",
        type=float,
        default=_default_of(calibrate_port, "max_normal_std_deg"),
        help="refuse a port whose normal's standard deviation (noise and the camera model's uncertainty) exceeds "
        "this, degrees",
    )
    parser.add_argument(
        "--max-distance-std-m",
        type=float,
        default=_default_of(calibrate_port, "max_distance_std_m"),
        help="refuse a port whose distance's standard deviation exceeds this, metres",
    )
    parser.add_argument(
        "--target-normal-std-deg",
        type=float,
        default=_default_of(advise_port_views, "target_normal_std_deg"),
        help="how well the normal should be known, degrees: beyond it the command says which board views to add",
    )
    parser.add_argument(
        "--target-distance-std-m",
        type=float,
        default=_default_of(advise_port_views, "target_distance_std_m"),
        help="how well the distance should be known, metres: beyond it the command says which board views to add",
    )
    corners = _default_of(board_view_from_light_field, "method")
    parser.add_argument(
        "--corners",
        choices=CORNER_METHODS,
        default=corners,
        help=f"locate corners on every raw pixel around them ({corners}, the default), or in sub-aperture views",
    )
    parser.add_argument(
        "--subaperture-offset-px",
        type=float,
        default=0.0,
        help="with --corners views: also the four sub-aperture views this far from the micro-image centres "
        "(0: the central view only)",
    )
    parser.add_argument(
        "--refine-camera",
        metavar="CAMERA_OUT.json",
        help="refine the ray model of --camera (a camera calibration) together with the port, within its in-air "
        "uncertainty, and write the refined camera calibration here; synthesize with it and the port",
    )


def _calibrate_approx_arguments(parser: argparse.ArgumentParser) -> None:
    _board_arguments(parser, "approx")


def _calibrate_camera_arguments(parser: argparse.ArgumentParser) -> None:
    _board_arguments(parser, "camera", sizes_per_capture=True)
    parser.add_argument(
        "--ray-model",
        choices=RAY_MODELS,
        default="radial",
        help="the camera's ray model: radial (five parameters: pupil and slope scales, two radial terms, pupil "
        "drift) or polynomial (a generic model for any lens, its capacity chosen by the error on held-back "
        "captures; slower). Default: radial",
    )


@dataclass(frozen=True)
class Command:
    """One ``lfrefract`` command: what runs it, what it takes, and its one-line help."""

    handler: Callable[[argparse.Namespace], int]  #: runs the command; returns the exit status
    arguments: Callable[[argparse.ArgumentParser], None]  #: adds the command's arguments to its parser
    help: str


#: The commands, by name; ``calibrate`` dispatches on :data:`CALIBRATE_COMMANDS`.
COMMANDS: dict[str, Command] = {
    "describe": Command(describe_command, _describe_arguments, "optics of a preset, a camera file or a meta.json"),
    "synth": Command(synth, _synth_arguments, "refraction-free image of a raw capture (meta.json beside it)"),
    "naive": Command(naive, _naive_arguments, "conventional view with no refraction handling"),
    "views": Command(views, _views_arguments, "grid of sub-aperture views in the HCI 4D light field benchmark layout"),
}

#: ``lfrefract calibrate TARGET``, by target.
CALIBRATE_COMMANDS: dict[str, Command] = {
    "mla": Command(
        calibrate_mla_command, _calibrate_mla_arguments, "microlens lattice and micro-image centres from a white image"
    ),
    "port": Command(
        calibrate_port_command,
        _calibrate_port_arguments,
        "port normal and distance from underwater chessboard captures",
    ),
    "approx": Command(
        calibrate_approx_command,
        _calibrate_approx_arguments,
        "pinhole + distortion at one depth from chessboard captures",
    ),
    "camera": Command(
        calibrate_camera_command,
        _calibrate_camera_arguments,
        "the camera's ray model (pupil scale, slope scale, radial terms) from in-air chessboard captures",
    ),
}


def _add_commands(sub: argparse._SubParsersAction, table: dict[str, Command]) -> None:
    for name, command in table.items():
        parser = sub.add_parser(
            name,
            help=command.help,
            description=f"{command.help[0].upper()}{command.help[1:]}.",
            formatter_class=_HelpFormatter,
        )
        command.arguments(parser)
        parser.set_defaults(handler=command.handler)


def build_parser() -> argparse.ArgumentParser:
    """The ``lfrefract`` argument parser (every command, defaults shown in ``--help``)."""
    parser = argparse.ArgumentParser(
        prog="lfrefract", description="Refraction-free light-field imaging (core).", formatter_class=_HelpFormatter
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    _add_commands(sub, COMMANDS)
    cal = sub.add_parser(
        "calibrate",
        help="estimate the MLA, the camera's ray model, the port or the approximation baseline",
        formatter_class=_HelpFormatter,
    )
    _add_commands(cal.add_subparsers(dest="target", required=True), CALIBRATE_COMMANDS)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    args = build_parser().parse_args(argv)
    with terminate_cleanly("lfrefract"):
        return _run(args)


def _run(args: argparse.Namespace) -> int:
    try:
        return args.handler(args)
    except (ParameterError, FileFormatError, OSError) as exc:
        # OSError: refusals (FileExistsError), missing files, failed writes (read-only, disk full): one
        # line naming the path; every file is written atomically, so earlier outputs are as they were.
        print(f"lfrefract: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
