"""Sub-aperture view stacks in the layout of the HCI 4D light field benchmark."""

from __future__ import annotations

import json
import os
import zipfile
from collections.abc import Iterable
from pathlib import Path

import cv2
import numpy as np

from lfrefract import __version__
from lfrefract.errors import FileFormatError, ParameterError
from lfrefract.formats.exr import write_exr
from lfrefract.formats.jsonio import SCHEMA_VERSION, write_json
from lfrefract.formats.outputs import staged_directory
from lfrefract.formats.pfm import write_pfm
from lfrefract.optics.camera import LightFieldCamera
from lfrefract.optics.pinhole import PinholeCamera
from lfrefract.optics.ray_correction import correction_from_dict
from lfrefract.synthesis.views import ViewStack
from lfrefract.validate import file_problem, one_of, positive_float, positive_int

#: Image formats of :func:`write_view_stack`.
VIEW_STACK_FORMATS = ("png", "exr")

#: Percentile of the central view's finite values that the PNG encoding maps to white, by default.
PNG_WHITE_PERCENTILE = 99.5

_STACK_SIDECAR = "views.json"
_STACK_KIND = "lfrefract.view_stack"
_STACK_ARRAYS = "stack.npz"
_STACK_MASK = "valid_mask.png"
_STACK_PARAMETERS = "parameters.cfg"
_TRUTH_CENTRAL = "gt_disp_lowres.pfm"
_TRUTH_ARRAYS = "gt_disparity.npz"

__all__ = [
    "PNG_WHITE_PERCENTILE",
    "VIEW_STACK_FORMATS",
    "read_view_disparity",
    "read_view_stack",
    "view_file_names",
    "write_view_stack",
]


def view_file_names(grid: int, image_format: str) -> list[str]:
    """File names of a ``grid x grid`` view stack in the HCI layout, in row-major order.

    ``input_Cam000.png`` is view ``[0, 0]`` (top left), ``input_Cam{r * grid + c}`` view
    ``[r, c]``; numbers have three digits (the benchmark's 9 x 9 grids), more only for grids
    beyond 31 x 31, so that sorting the names keeps the order.
    """
    positive_int("grid", grid)
    one_of("image_format", image_format, VIEW_STACK_FORMATS)
    digits = max(3, len(str(grid * grid - 1)))
    return [f"input_Cam{i:0{digits}d}.{image_format}" for i in range(grid * grid)]


def _srgb_8bit(view: np.ndarray, white_level: float) -> np.ndarray:
    """``round(255 * srgb(clip(view / white_level, 0, 1)))`` as uint8, NaN written as 0."""
    x = np.clip(np.nan_to_num(view.astype(np.float64) / white_level, nan=0.0), 0.0, 1.0)
    encoded = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)
    return np.round(encoded * 255.0).astype(np.uint8)


def _write_png(path: Path, image: np.ndarray) -> None:
    """An 8-bit grey (H, W) or RGB (H, W, 3) image as PNG (OpenCV wants BGR)."""
    ok, data = cv2.imencode(".png", image if image.ndim == 2 else np.ascontiguousarray(image[..., ::-1]))
    if not ok:
        raise OSError(f"OpenCV could not encode {str(path)!r} as PNG")
    path.write_bytes(data.tobytes())


def _hci_parameters(stack: ViewStack) -> str:
    """``parameters.cfg`` text: the HCI benchmark's fields that the stack states truthfully."""
    out = stack.output
    max_res = max(out.width_px, out.height_px)
    lines = [
        "# Sub-aperture view stack written by lfrefract, in the layout of the HCI 4D light field benchmark",
        "# (Honauer et al., ACCV 2016). Views input_CamNNN, NNN = row * num_cams_x + column, row 0 at the top,",
        "# column 0 at the left. Every view has the same K and orientation; the disparity between neighbouring",
        "# views is f_px * baseline / depth, zero at infinity (the views are not shifted to a focus plane).",
        "# Fields of the benchmark left out: fstop (a view's aperture is one pixel's square footprint on the main",
        "# lens), the centre camera's pose (the camera frame is the reference) and the [meta] disparity ranges",
        "# and depth map scale (no ground truth here). *_px keys other than the resolution are lfrefract's.",
        "",
        "[intrinsics]",
    ]
    if stack.camera is not None:
        image_distance_m = stack.camera.lens_to_mla_m
        lines += [
            f"focal_length_mm = {image_distance_m * 1e3!r}",
            f"sensor_size_mm = {max_res * image_distance_m / out.focal_px * 1e3!r}",
        ]
    lines += [
        f"image_resolution_x_px = {out.width_px}",
        f"image_resolution_y_px = {out.height_px}",
        f"focal_length_px = {out.focal_px!r}",
        f"principal_point_x_px = {out.cx_px!r}",
        f"principal_point_y_px = {out.cy_px!r}",
        "",
        "[extrinsics]",
        f"num_cams_x = {stack.grid}",
        f"num_cams_y = {stack.grid}",
        f"baseline_mm = {stack.baseline_m * 1e3!r}",
        "focus_distance_m = inf",
        f"spacing_px = {stack.spacing_px!r}",
        "",
        "[meta]",
        f"generator = lfrefract {__version__}",
        f"schema_version = {SCHEMA_VERSION}",
        "",
    ]
    return "\n".join(lines)


def write_view_stack(
    out_dir: str | os.PathLike,
    stack: ViewStack,
    *,
    overwrite: bool = False,
    image_format: str = "png",
    white_level: float | None = None,
    metadata: dict | None = None,
    inputs: Iterable[str | os.PathLike] = (),
    disparity_px: tuple[np.ndarray, np.ndarray] | None = None,
) -> Path:
    """Write a sub-aperture view stack in the HCI 4D light field benchmark layout, atomically.

    The directory holds, for a ``grid x grid`` stack (``docs/synthesis.md``, "Sub-aperture view
    stacks"):

    * ``input_Cam000.<ext>`` ... one file per view in row-major order (:func:`view_file_names`):
      ``Cam000`` is view ``[0, 0]``, the top-left centre of projection (camera frame -x, -y),
      the central view is ``Cam{h * grid + h}``;
    * ``parameters.cfg``: the benchmark's INI fields that can be stated (resolution, number of
      cameras, baseline, focal length in mm and pixels, sensor size, focus distance ``inf``);
    * ``valid_mask.png``: 255 where every view has a finite value in every channel, else 0;
    * ``stack.npz``: ``views`` (float32, NaN kept), ``offsets_px``, ``centres_m``, ``K``, the
      camera and its ray correction as JSON (empty when none), ``schema_version`` (:func:`read_view_stack`);
    * ``views.json``: the sidecar (layout, ordering, encoding, disparity relation, geometry);
    * with ``disparity_px``, the ground truth: ``gt_disp_lowres.pfm`` (the central view's) and
      ``gt_disp_lowres_Cam000.pfm`` ... (every view's) horizontal disparity as the benchmark's
      PFM files (:mod:`lfrefract.formats.pfm`), and ``gt_disparity.npz`` with both stacks,
      ``disparity_x_px`` and ``disparity_y_px`` (:func:`read_view_disparity`).

    PNG views are 8-bit sRGB: ``round(255 * srgb(clip(value / white_level, 0, 1)))`` with the
    IEC 61966-2-1 transfer curve, one ``white_level`` for all views (so they stay photometrically
    consistent), NaN written as 0. EXR views are float32 linear, NaN kept (:func:`write_exr`).

    Parameters
    ----------
    out_dir : path-like
        The directory to create (assembled beside it and renamed into place).
    stack : ViewStack
        Grey views or views with 1 or 3 channels.
    overwrite : bool
        Replace an earlier view stack that holds only its own files
        (:func:`lfrefract.formats.outputs.staged_directory`).
    image_format : {"png", "exr"}
    white_level : float, optional
        Linear value written as white in PNG views, > 0. Default: the
        :data:`PNG_WHITE_PERCENTILE` th percentile of the central view's finite values, or 1.0
        if that is not positive (a black view). Recorded in ``views.json``.
    metadata : dict, optional
        Plain data stored under ``"metadata"`` in ``views.json`` (e.g. the source raw image).
    inputs : iterable of path-like
        Files the caller read the stack from: ``out_dir`` may not hold one.
    disparity_px : (ndarray, ndarray), optional
        The stack's true disparity, pixels, float, each of shape (grid, grid, height, width):
        horizontal (``u - u'`` with ``u'`` where view ``[r, c + 1]`` shows the same surface point)
        and vertical (``v - v'`` towards view ``[r + 1, c]``), NaN where a view pixel sees nothing;
        behind a tilted port the two differ (``simulator.view_truth``).

    Returns
    -------
    Path
        ``out_dir``.

    Raises
    ------
    ParameterError
        If ``stack`` is not a ViewStack, has another number of channels, or an option is invalid.
    FileExistsError
        See :func:`lfrefract.formats.outputs.staged_directory`.
    """
    if not isinstance(stack, ViewStack):
        raise ParameterError(f"stack must be a ViewStack, got {type(stack).__name__}")
    one_of("image_format", image_format, VIEW_STACK_FORMATS)
    views = stack.views
    if views.ndim == 5:
        if views.shape[4] not in (1, 3):
            raise ParameterError(
                f"stack.views must be grey or have 1 or 3 channels for image files, got {views.shape[4]} channels"
            )
        if views.shape[4] == 1:
            views = views[..., 0]
    if metadata is not None and not isinstance(metadata, dict):
        raise ParameterError(f"metadata must be a dict or None, got {type(metadata).__name__}")
    disparity = _checked_disparity(disparity_px, stack)
    finite = stack.central_view[np.isfinite(stack.central_view)]
    if white_level is None:
        white = float(np.percentile(finite, PNG_WHITE_PERCENTILE)) if finite.size else 0.0
        rule = f"{PNG_WHITE_PERCENTILE}th percentile of the central view's finite values"
        if not white > 0.0:
            white, rule = 1.0, "1.0 (the central view has no positive values)"
    else:
        white, rule = positive_float("white_level", white_level), "given"
    valid = np.all(np.isfinite(views), axis=(0, 1) if views.ndim == 4 else (0, 1, 4))
    names = view_file_names(stack.grid, image_format)
    grid, h = stack.grid, stack.centre_index
    if image_format == "png":
        encoding = {
            "bits": 8,
            "transfer": "sRGB (IEC 61966-2-1)",
            "formula": "round(255 * srgb(clip(value / white_level, 0, 1))); NaN written as 0 (see valid_mask.png)",
            "white_level": white,
            "white_level_rule": rule,
        }
    else:
        encoding = {"type": "float32 OpenEXR, linear radiance as in the raw image", "nan": "kept (no value)"}
    out = Path(out_dir)
    with staged_directory(out, kind=_STACK_KIND, overwrite=overwrite, inputs=inputs) as stage:
        for index, name in enumerate(names):
            view = views[index // grid, index % grid]
            if image_format == "png":
                _write_png(stage / name, _srgb_8bit(view, white))
            else:
                write_exr(stage / name, view, role="subaperture_view")
        _write_png(stage / _STACK_MASK, valid.astype(np.uint8) * 255)
        truth_files = {}
        if disparity is not None:
            dx, dy = disparity
            truth_files = {"central": _TRUTH_CENTRAL, "views": _truth_names(grid), "arrays": _TRUTH_ARRAYS}
            write_pfm(stage / _TRUTH_CENTRAL, dx[h, h])
            for index, name in enumerate(truth_files["views"]):
                write_pfm(stage / name, dx[index // grid, index % grid])
            with (stage / _TRUTH_ARRAYS).open("wb") as fh:
                np.savez_compressed(fh, disparity_x_px=dx, disparity_y_px=dy)
        (stage / _STACK_PARAMETERS).write_text(_hci_parameters(stack))
        with (stage / _STACK_ARRAYS).open("wb") as fh:
            np.savez(
                fh,
                views=stack.views,
                offsets_px=stack.offsets_px,
                centres_m=stack.centres_m,
                K=stack.K,
                camera=np.asarray(json.dumps(stack.camera.to_dict()) if stack.camera is not None else ""),
                ray_correction=np.asarray(
                    json.dumps(stack.ray_correction.to_dict()) if stack.ray_correction is not None else ""
                ),
                schema_version=np.asarray(SCHEMA_VERSION),
            )
        write_json(
            stage / _STACK_SIDECAR,
            {
                "kind": _STACK_KIND,
                "layout": "HCI 4D light field benchmark (Honauer et al., ACCV 2016)",
                "ordering": (
                    "input_CamNNN, NNN = row * grid + column; row 0 at the top (camera frame -y), column 0 at the "
                    "left (-x); stack.npz views[row, column]"
                ),
                "grid": grid,
                "central_view": names[h * grid + h],
                "files": {
                    "views": names,
                    "mask": _STACK_MASK,
                    "parameters": _STACK_PARAMETERS,
                    "arrays": _STACK_ARRAYS,
                },
                "image_format": image_format,
                "encoding": encoding,
                "valid_fraction": float(valid.mean()),
                "K": stack.K,
                "width_px": stack.output.width_px,
                "height_px": stack.output.height_px,
                "spacing_px": stack.spacing_px,
                "baseline_m": stack.baseline_m,
                "disparity": {
                    "rule": (
                        "between neighbouring views d = focal_px * baseline_m / depth_m pixels, depth the camera-frame "
                        "z; views[r, c + 1] at (u - d, v) and views[r + 1, c] at (u, v - d) show what views[r, c] "
                        "shows at (u, v); zero at infinity"
                    ),
                    "focal_px_times_baseline_m": stack.output.focal_px * stack.baseline_m,
                    "ground_truth": truth_files or None,
                },
                "offsets_px": stack.offsets_px,
                "centres_m": stack.centres_m,
                "camera": stack.camera.to_dict() if stack.camera is not None else None,
                "ray_correction": stack.ray_correction.to_dict() if stack.ray_correction is not None else None,
                "metadata": metadata,
            },
        )
    return out


def _truth_names(grid: int) -> list[str]:
    """``gt_disp_lowres_Cam000.pfm`` ...: the per-view truth files, numbered as the views."""
    return [
        f"gt_disp_lowres_{name.rsplit('.', 1)[0].removeprefix('input_')}.pfm" for name in view_file_names(grid, "exr")
    ]


def _checked_disparity(disparity_px: object, stack: ViewStack) -> tuple[np.ndarray, np.ndarray] | None:
    """``disparity_px`` as two float32 arrays of the stack's (grid, grid, height, width), or raise."""
    if disparity_px is None:
        return None
    shape = (stack.grid, stack.grid, stack.output.height_px, stack.output.width_px)
    if not isinstance(disparity_px, (tuple, list)) or len(disparity_px) != 2:
        raise ParameterError(f"disparity_px must be a pair of arrays (horizontal, vertical), got {type(disparity_px)}")
    out = []
    for name, value in zip(("horizontal", "vertical"), disparity_px, strict=True):
        arr = np.asarray(value)
        if arr.shape != shape or not np.issubdtype(arr.dtype, np.floating):
            raise ParameterError(
                f"disparity_px's {name} array must be float of shape {shape}, got {arr.dtype} {arr.shape}"
            )
        out.append(arr.astype(np.float32))
    return out[0], out[1]


def read_view_disparity(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray] | None:
    """The true disparity of a view stack directory (``gt_disparity.npz``), or None without one.

    Returns
    -------
    (ndarray, ndarray) or None
        Horizontal and vertical disparity, pixels, float32, (grid, grid, height, width) each (see
        :func:`write_view_stack`).

    Raises
    ------
    FileFormatError
        If the file is there but does not hold both arrays.
    """
    file = Path(path) / _TRUTH_ARRAYS
    if not file.is_file():
        return None
    try:
        with np.load(file, allow_pickle=False) as npz:
            return npz["disparity_x_px"], npz["disparity_y_px"]
    except (OSError, ValueError, KeyError) as exc:
        raise FileFormatError(f"{str(file)!r} is not a view stack's disparity file: {exc}") from None


def read_view_stack(path: str | os.PathLike) -> ViewStack:
    """Read the :class:`ViewStack` of a directory written by :func:`write_view_stack` (its ``stack.npz``).

    Raises
    ------
    FileFormatError
        If ``stack.npz`` is missing, unreadable, of another schema version, lacks an array, or
        does not hold a valid view stack.
    """
    path = Path(path)
    file = path / _STACK_ARRAYS if path.is_dir() else path
    if (problem := file_problem(file)) is not None:
        raise FileFormatError(problem)
    try:
        # Our own handle: np.load leaks the one it opens when the zip directory is unreadable.
        with file.open("rb") as fh, np.load(fh, allow_pickle=False) as data:
            arrays = {key: data[key] for key in data.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise FileFormatError(f"{str(file)!r} is not a readable .npz file: {exc}") from None
    missing = sorted({"views", "offsets_px", "centres_m", "K", "camera", "schema_version"} - set(arrays))
    if missing:
        raise FileFormatError(f"{str(file)!r} is not a view stack: it lacks {missing}")
    version = arrays["schema_version"]
    if version.shape != () or version.dtype.kind not in "iu" or int(version) != SCHEMA_VERSION:
        raise FileFormatError(
            f"{str(file)!r} has schema version {version.tolist()!r}, this lfrefract reads {SCHEMA_VERSION}"
        )
    views = arrays["views"]
    try:
        if views.ndim not in (4, 5):
            raise ParameterError(f"views must have 4 or 5 dimensions, got shape {views.shape}")
        camera_text = str(arrays["camera"])
        camera = LightFieldCamera.from_dict(json.loads(camera_text)) if camera_text else None
        # Optional: stacks written before calibrated cameras were read have none (the thin lens's rays).
        correction_text = str(arrays["ray_correction"]) if "ray_correction" in arrays else ""
        correction = correction_from_dict(json.loads(correction_text)) if correction_text else None
        output = PinholeCamera.from_K(arrays["K"], int(views.shape[3]), int(views.shape[2]))
        return ViewStack(
            views=views,
            offsets_px=arrays["offsets_px"],
            centres_m=arrays["centres_m"],
            output=output,
            camera=camera,
            ray_correction=correction,
        )
    except (ValueError, TypeError) as exc:  # ParameterError, JSONDecodeError, a K of strings
        raise FileFormatError(f"{str(file)!r} does not hold a valid view stack: {exc}") from None
