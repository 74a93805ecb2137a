"""Refraction-free image synthesis from a light field behind a flat port (paper sections 3.2, 4.1).

For every output (sub-)pixel of a virtual pinhole camera whose centre of projection is the
main-lens centre, the *necessary ray* is the straight line from that centre through the pixel,
continued into the water. The light that travels back along it is traced exactly through the
port (water, glass, air) to the air-side face: the *necessary air ray*, through point ``P`` on the
air-side face with direction ``r``. Among the captured rays (each raw pixel's ray through its
microlens centre, see :meth:`LightFieldCamera.captured_rays`) those closest to it by

    D = |P' - P| + lambda * angle(r', r)        (P' where the captured ray meets the face)

are averaged, the ``k`` nearest with weights ``1 / D``. Candidates come from an analytic search:
the necessary air ray is followed back through the thin main lens to the MLA (for a calibrated
camera, :attr:`SynthesisOptions.ray_correction`, its thin-lens twin: the thin-lens ray the
correction maps onto it; the candidates' D is measured on the corrected rays); the microlenses
around that point (``lens_rings`` rings) are candidates, and under each the pixels within
``window`` of the pixel whose chief ray passes through ``P``: the k nearest among those, which
is not always the k nearest of all rays (with ``lambda = 0`` rays of farther lenses can pass
closer to ``P``); a k-d tree over all captured rays gives the exact k nearest
(``search="kdtree"``, and where the analytic search does not apply). Sub-pixel necessary rays
(``supersample`` x ``supersample`` per output pixel) are averaged.

The result is a :class:`WarpMap`, a sparse weighted gather (CSR) from raw pixels to output pixels,
built once per camera, port, output geometry and options and applied per frame. Output pixels
whose necessary ray misses the usable main-lens aperture (paper section 6, the field-of-view
limitation) are reported in a coverage mask; they still get the nearest captured rays the search
finds, or nothing.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import time
import zipfile
import zlib
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numba
import numpy as np
from tqdm import tqdm

from lfrefract import __version__
from lfrefract.errors import FileFormatError, ParameterError
from lfrefract.formats.mosaic import CFA_PATTERNS
from lfrefract.formats.outputs import atomic_file
from lfrefract.optics.camera import LightFieldCamera, image_side_px
from lfrefract.optics.pinhole import PinholeCamera, virtual_camera_for
from lfrefract.optics.port import FlatPort
from lfrefract.optics.ray_correction import UNSTRUCTURED, Correction, RayCorrection
from lfrefract.synthesis._kernels import (
    THIN_LENS,
    AirFace,
    CameraScalars,
    Lattice,
    NecessaryRays,
    RayModel,
    SearchQuery,
    gather,
    merge_rows,
    select_candidates,
    sensor_to_plane_scale,
)
from lfrefract.synthesis._raytree import LazyRayTree
from lfrefract.synthesis.empty import masked_reason, output_geometry, require_a_value
from lfrefract.validate import non_negative_float, one_of, positive_int

__all__ = [
    "FILLED_APPROXIMATED",
    "FILLED_EMPTY",
    "FILLED_EXACT",
    "PAPER_K",
    "SEARCH_METHODS",
    "SynthesisOptions",
    "WarpMap",
    "apply_cfa",
    "build_cfa_warp_maps",
    "build_warp_map",
    "lens_plane_hits",
    "mla_points_img",
    "necessary_air_rays",
    "uses_kdtree",
    "warp_map_key",
]

#: Classes of :attr:`WarpMap.filled_classes`: no captured ray (no value), nearby rays standing in
#: for some necessary ray, every necessary ray recorded.
FILLED_EMPTY, FILLED_APPROXIMATED, FILLED_EXACT = 0, 1, 2

#: Version of the warp-map algorithm and file layout; part of every map's key.
WARP_MAP_VERSION = 4

#: Captured rays averaged per necessary ray in the paper (section 4.1); :class:`SynthesisOptions`
#: defaults to 8, which scored better on every preset measured.
PAPER_K = 32

#: Candidate searches of :class:`SynthesisOptions`.
SEARCH_METHODS = ("auto", "analytic", "kdtree")

#: Output pixels per block of the build (a block's buffers: BLOCK_PIXELS x s^2 x k entries).
BLOCK_PIXELS = 8192


@dataclass(frozen=True, kw_only=True)
class SynthesisOptions:
    """Options of the refraction-free synthesis.

    Parameters
    ----------
    k : int
        Captured rays averaged per necessary ray. The default 8 scored the best PSNR against the
        ideal image on the ``tiny``, ``f01`` and ``illum`` cameras (0.4 to 1.2 dB above the
        paper's 32: docs/synthesis.md, docs/experiments.md "averaging"); pass ``k=32`` for the
        paper's set-up (:data:`PAPER_K`).
    supersample : int
        Necessary rays per output pixel along each axis (paper: 2).
    lambda_m_per_rad : float
        Weight of the angle term of D, metres per radian. ``|P' - P| + lambda * angle`` is about
        how far the two rays are apart at ``lambda`` beyond the port, so a typical object distance
        is the natural value. The paper used 0 (position only); on the tiny camera behind
        0-30 deg ports, 0.3 m/rad raised PSNR against the ideal image from 18-25 dB to 22-29 dB
        and SSIM from 0.73-0.78 to 0.89-0.91 (docs/synthesis.md).
    lens_rings : int
        Rings of microlenses around the necessary ray's MLA point searched for candidates.
    window : int
        Half-size, in pixels, of the window searched under each candidate lens.
    rim_margin_px : float
        Raw pixels whose centre lies within this many pixels of their micro-image's rim are not
        used: part of their area is vignetted, so their value is not the radiance of their ray.
        With the sensor in the microlenses' focal plane each pixel sees its own footprint on the
        main lens, so half the pixel diagonal (0.707) is the geometric limit. On the tiny camera
        the default 0.71 scored within 0.4 dB of a 1 px margin with 9-160 % more exact coverage
        (more, the more the port is tilted; docs/synthesis.md).
    compensate_port : bool
        Divide by the port's radiometric factor along the necessary ray (Fresnel transmittance
        times ``(n_air / n_water)^2``), so the output is radiance in the water, comparable with
        the simulator's ideal image.
    cfa_pattern, cfa_colour : str or None
        Gather from one colour of a Bayer mosaic only: the pattern (``"GRBG"``, ``"RGGB"``,
        ``"GBRG"``, ``"BGGR"``, the upper-left 2 x 2 tile row by row) and the colour (``"R"``, ``"G"``
        or ``"B"``); both or neither (default: every raw pixel). The map then applies to the mosaic's
        values, one per pixel, and gives that colour without demosaicing
        (:func:`build_cfa_warp_maps`): no value of a pixel is interpolated from its neighbours, which
        at a micro-image's edge belong to the dark gap or to the next micro-image.
    ray_correction : RayCorrection or None
        The camera's calibrated departure from its thin-lens rays
        (:func:`lfrefract.calibration.calibrate_camera`): the candidates are then the corrected
        rays. Both searches apply: the analytic one predicts the pixels from each necessary ray's
        thin-lens twin (:meth:`RayCorrection.thin_lens_rays`) and measures D on the corrected rays;
        the exact coverage is judged on the twin, i.e. on the calibrated rays. Default None: the
        thin-lens rays.
    search : {"auto", "analytic", "kdtree"}
        How candidates are found. ``"analytic"``: the lens and pixel window search above (an
        error where the port's air-side face is conjugate to the MLA, so that every pixel of a
        lens sees the same point of the face). ``"kdtree"``: the exact k nearest by D among all
        captured rays, through a k-d tree (memory: about 60 bytes per raw pixel).
        ``"auto"``: analytic when the MLA sits in the main lens's focal plane (``f' = f``, every
        preset), where the rays of one microlens are parallel and the window around the pixel
        through ``P`` holds the nearest ones; otherwise the k-d tree (off the focal plane the
        rays of one microlens fan out, the angle term can favour pixels outside the window, and
        near a face conjugate to the MLA the prediction fails: measured on the tiny camera with
        ``f' = 1.05 f``, the analytic pick was the nearest for 15-67 % of the pixels). A
        ``ray_correction`` whose radial terms fold the field over leaves the rays beyond the fold
        without a thin-lens twin: ``"auto"`` searches those with the k-d tree, ``"analytic"``
        leaves them without candidates.
    """

    k: int = 8
    supersample: int = 2
    lambda_m_per_rad: float = 0.3
    lens_rings: int = 1
    window: int = 2
    rim_margin_px: float = 0.71
    compensate_port: bool = True
    search: str = "auto"
    cfa_pattern: str | None = None
    cfa_colour: str | None = None
    ray_correction: Correction | None = None

    def __post_init__(self) -> None:
        positive_int("k", self.k)
        positive_int("supersample", self.supersample)
        non_negative_float("lambda_m_per_rad", self.lambda_m_per_rad)
        positive_int("lens_rings", self.lens_rings)
        if isinstance(self.window, bool) or not isinstance(self.window, int) or self.window < 0:
            raise ParameterError(f"window must be a non-negative integer, got {self.window!r}")
        non_negative_float("rim_margin_px", self.rim_margin_px)
        if not isinstance(self.compensate_port, bool):
            raise ParameterError(f"compensate_port must be True or False, got {self.compensate_port!r}")
        one_of("search", self.search, SEARCH_METHODS)
        if (self.cfa_pattern is None) != (self.cfa_colour is None):
            raise ParameterError(
                f"cfa_pattern and cfa_colour go together, got cfa_pattern={self.cfa_pattern!r}, "
                f"cfa_colour={self.cfa_colour!r}"
            )
        if self.cfa_pattern is not None:
            one_of("cfa_pattern", self.cfa_pattern, CFA_PATTERNS)
            one_of("cfa_colour", self.cfa_colour, ("R", "G", "B"))
        if self.ray_correction is not None and not isinstance(self.ray_correction, (RayCorrection, *UNSTRUCTURED)):
            raise ParameterError(
                "ray_correction must be a RayCorrection, a PolynomialCorrection, a TracedLens or None, "
                f"got {self.ray_correction!r}"
            )
        if isinstance(self.ray_correction, UNSTRUCTURED) and self.search == "analytic":
            raise ParameterError(
                f"search='analytic' does not take the {self.ray_correction.name} ray model (its rays of one microlens "
                "are not parallel): use search='kdtree' or 'auto'"
            )
        lenses = 3 * self.lens_rings * (self.lens_rings + 1) + 1  # hexagonal rings around a lens
        if self.k > lenses * (2 * self.window + 1) ** 2:
            most = lenses * (2 * self.window + 1) ** 2
            raise ParameterError(
                f"k={self.k!r} exceeds the {most} candidates searched ({lenses} lenses x {(2 * self.window + 1) ** 2} "
                f"pixels): choose k at most {most} (--k on the command line), or raise lens_rings or window "
                "(SynthesisOptions, in Python)"
            )

    def to_dict(self) -> dict:
        """Plain data for sidecars and the map key (the CFA fields only when set, so that the maps
        of every raw pixel keep their keys)."""
        out = dataclasses.asdict(self)
        if self.cfa_pattern is None:
            del out["cfa_pattern"], out["cfa_colour"]
        if self.ray_correction is None:
            del out["ray_correction"]
        else:
            out["ray_correction"] = self.ray_correction.to_dict()
        return out

    @property
    def sites(self) -> np.ndarray:
        """(2, 2) bool: the raw pixels ``(u, v)`` used are those where ``sites[v % 2, u % 2]``."""
        if self.cfa_pattern is None:
            return np.ones((2, 2), dtype=bool)
        return np.array([letter == self.cfa_colour for letter in self.cfa_pattern]).reshape(2, 2)


def uses_kdtree(camera: LightFieldCamera, options: SynthesisOptions) -> bool:
    """Whether the build searches every sample with the k-d tree: ``search="kdtree"``, or
    ``"auto"`` with the MLA off the main lens's focal plane (``f' != f``) or with a polynomial or
    traced ray model (:data:`~lfrefract.optics.ray_correction.UNSTRUCTURED`: the rays of one
    microlens are not parallel)."""
    if options.search == "kdtree":
        return True
    return options.search == "auto" and (
        camera.lens_to_mla_m != camera.focal_length_m or isinstance(options.ray_correction, UNSTRUCTURED)
    )


def necessary_air_rays(
    port: FlatPort, directions_cam: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Trace the light arriving along pinhole lines of sight back through the port into the air.

    Parameters
    ----------
    port : FlatPort
    directions_cam : ndarray, shape (N, 3)
        Unit directions of the lines of sight from the main-lens centre, camera frame.

    Returns
    -------
    points_cam : ndarray, shape (N, 3)
        Where the light leaves the port's air-side face (P), metres.
    directions_out_cam : ndarray, shape (N, 3)
        Unit direction of the air ray pointing out of the camera (r); the light travels along -r.
    transmittance : ndarray, shape (N,)
        Fresnel transmittance of the port along the path (0 where invalid).
    valid : ndarray of bool, shape (N,)
        The line of sight reaches the port and its light is not totally internally reflected.
    """
    d = np.asarray(directions_cam, dtype=np.float64)
    n = port.normal
    water_face = port.distance_m + port.thickness_m
    cos = d @ n
    ok = cos > 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        q = d * np.where(ok, water_face / cos, np.nan)[:, None]
    trace = port.trace_from_water(np.where(ok[:, None], q, 0.0), np.where(ok[:, None], -d, n))
    valid = ok & trace.valid
    return trace.exit_points_cam, -trace.directions_cam, np.where(valid, trace.transmittance, 0.0), valid


def _lens_offsets(camera: LightFieldCamera, rings: int) -> np.ndarray:
    """Lattice offsets (M, 2) of the lenses within ``rings`` neighbour steps of a lens."""
    r = rings + 1
    ii, jj = np.meshgrid(np.arange(-2 * r, 2 * r + 1), np.arange(-2 * r, 2 * r + 1))
    idx = np.stack([ii.ravel(), jj.ravel()], axis=1)
    dist = np.linalg.norm(idx @ camera.mla.basis_m.T, axis=1) / camera.mla.pitch_m
    limit = rings * (math.sqrt(2.0) if camera.mla.grid == "square" else 1.0) + 1e-9
    keep = dist <= limit
    order = np.argsort(dist[keep], kind="stable")
    return idx[keep][order].astype(np.int64)


def warp_map_key(camera: LightFieldCamera, port: FlatPort, output: PinholeCamera, options: SynthesisOptions) -> str:
    """Hash identifying a warp map: every input that changes it, and the algorithm version."""
    payload = {
        "version": WARP_MAP_VERSION,
        "camera": camera.to_dict(),
        "port": {k: v for k, v in port.to_dict().items() if k not in ("normal", "total_tilt_deg")},
        "output": output.to_dict(),
        "options": options.to_dict(),
    }
    return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()[:32]


@dataclass(frozen=True, eq=False)
class WarpMap:
    """A sparse weighted gather from a raw lenslet image to a refraction-free image.

    Attributes
    ----------
    output : PinholeCamera
        Geometry of the refraction-free image (K, size).
    raw_shape : tuple of int
        ``(height, width)`` of the raw images it applies to.
    indptr, indices, weights : ndarray
        CSR rows, one per output pixel (row-major): raw flat indices (``v * W + u``) and weights
        (each non-empty row sums to 1).
    gain : ndarray, shape (n_pixels,)
        Radiometric factor applied after the gather (1, or the inverse port factor).
    coverage : ndarray, shape (height, width)
        Fraction of each output pixel's necessary rays that the camera records usably: they pass
        the main-lens aperture inside its usable radius (the aperture less ``rim_margin_px``,
        whose pixels are never used) and land on the sensor (1: exact; below 1: the
        field-of-view limitation of paper section 6).
    key : str
        :func:`warp_map_key` of its inputs.
    meta : dict
        Camera, port, output and options as plain data.

    Raises
    ------
    ParameterError
        If the arrays break the map's invariants (checked on construction, so that no kernel
        ever sees them): ``raw_shape`` two integers in [1, MAX_IMAGE_SIDE_PX]; ``indptr`` a
        native integer array of shape (width * height + 1,) starting at 0, non-decreasing and
        ending at ``len(indices)``; ``indices`` a native integer array of raw flat indices in
        [0, height * width of the raw); ``weights`` native float32/float64 of the same length,
        finite, non-negative, each non-empty row summing to 1 (within :data:`ROW_SUM_TOLERANCE`);
        ``gain`` native float32/float64 of shape (width * height,), finite and non-negative;
        ``coverage`` native float32/float64 of shape (height, width), in [0, 1]. An index outside
        the raw would make :meth:`apply` read outside the raw image (a crash of the process).
    """

    output: PinholeCamera
    raw_shape: tuple[int, int]
    indptr: np.ndarray
    indices: np.ndarray
    weights: np.ndarray
    gain: np.ndarray
    coverage: np.ndarray
    key: str
    meta: dict

    def __post_init__(self) -> None:
        _check_warp_map(self)

    @property
    def filled(self) -> np.ndarray:
        """Output pixels that received any captured ray, shape (height, width)."""
        return (np.diff(self.indptr) > 0).reshape(self.output.height_px, self.output.width_px)

    @property
    def exact(self) -> np.ndarray:
        """Output pixels whose every necessary ray the camera records usably, shape (height, width)."""
        return self.coverage >= 1.0

    @property
    def filled_classes(self) -> np.ndarray:
        """How each output pixel gets its value, uint8 (height, width): :data:`FILLED_EXACT` (every
        necessary ray recorded), :data:`FILLED_APPROXIMATED` (nearby rays stand in) or
        :data:`FILLED_EMPTY` (no captured ray: no value)."""
        filled = self.filled
        classes = np.full(filled.shape, FILLED_EMPTY, dtype=np.uint8)
        classes[filled] = FILLED_APPROXIMATED
        classes[filled & self.exact] = FILLED_EXACT
        return classes

    def apply(self, raw: np.ndarray) -> np.ndarray:
        """Synthesize the refraction-free image of one raw frame.

        Parameters
        ----------
        raw : ndarray, shape (H, W) or (H, W, C)
            Raw lenslet image, float or integer, of :attr:`raw_shape`.

        Returns
        -------
        ndarray, float32, shape (height, width) or (height, width, C)
            Zero where :attr:`filled` is False, which image-processing code (OpenCV's matchers and
            corner finders) takes as it is; files mark those pixels NaN, the project's "no value"
            (``lfrefract synth``, datasets), with :attr:`filled_classes`.

        Raises
        ------
        ParameterError
            For a raw image of another shape or type, and for a map with no entry (every row emptied by
            :func:`lfrefract.formats.capture.mask_warp_map`): an image with no value anywhere is refused,
            naming the masked pixels.
        """
        arr = self._checked_raw(raw)
        require_a_value(self.indptr[-1] > 0, what="the refraction-free image", because=self._why_empty)
        flat = self._flat(arr)
        out = np.empty((len(self.indptr) - 1, flat.shape[1]), dtype=np.float32)
        # Blocks of rows with equal shares of the entries, several per thread for balance.
        shares = np.linspace(0, self.indptr[-1], 16 * numba.get_num_threads() + 1)
        chunks = np.searchsorted(self.indptr, shares, side="right") - 1
        chunks[0], chunks[-1] = 0, len(self.indptr) - 1
        gather(np.unique(chunks), self.indptr, self.indices, self.weights, self.gain, flat, out)
        shape = (self.output.height_px, self.output.width_px)
        return out.reshape(shape) if arr.ndim == 2 else out.reshape(*shape, flat.shape[1])

    def compile_for(self, raw: np.ndarray) -> float:
        """Compile the gather of :meth:`apply` for ``raw``'s type and channels, on one pixel; seconds taken.

        numba compiles the gather on its first call for each type of raw image (a few seconds; then it
        loads it from its cache, in later processes too). Called before :meth:`apply`, it keeps that time
        out of the apply's, so that the two can be reported apart (``lfrefract synth``). ``raw`` is
        checked as :meth:`apply` checks it; only its first pixel is read.

        Parameters
        ----------
        raw : ndarray, shape (H, W) or (H, W, C)
            A raw image as :meth:`apply` takes it.

        Returns
        -------
        float
            Seconds the one-pixel gather took: the compilation (or the load from numba's cache) and a
            negligible gather.
        """
        arr = self._checked_raw(raw)
        one = self._flat(arr[:1, :1])  # the type the gather sees in apply, of one pixel
        start = time.perf_counter()
        gather(
            np.array([0, 1], dtype=np.intp),
            np.array([0, 1], dtype=self.indptr.dtype),
            np.zeros(1, dtype=self.indices.dtype),
            np.ones(1, dtype=self.weights.dtype),
            np.ones(1, dtype=self.gain.dtype),
            one,
            np.empty((1, one.shape[1]), dtype=np.float32),
        )
        return time.perf_counter() - start

    def _checked_raw(self, raw: np.ndarray) -> np.ndarray:
        """``raw`` as an array, checked against the map's raw shape and for a real type."""
        arr = np.asarray(raw)
        if arr.shape[:2] != tuple(self.raw_shape):
            raise ParameterError(f"raw must have shape {tuple(self.raw_shape)} (+ channels), got {arr.shape}")
        if arr.ndim not in (2, 3) or not (
            np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)
        ):
            raise ParameterError(f"raw must be a real (H, W) or (H, W, C) image, got shape {arr.shape}, {arr.dtype}")
        return arr

    @staticmethod
    def _flat(arr: np.ndarray) -> np.ndarray:
        """A checked raw image as the gather reads it: (H * W, C), float (integers as float32)."""
        flat = arr.reshape(arr.shape[0] * arr.shape[1], -1)
        return flat if np.issubdtype(flat.dtype, np.floating) else flat.astype(np.float32)

    def _why_empty(self) -> str:
        """Why the map has no entry: :func:`build_warp_map` refuses such a map, so its raw pixels were
        masked (:func:`lfrefract.formats.capture.mask_warp_map`), or it was made by other means."""
        unrecorded = self.meta.get("unrecorded_raw_pixels")
        if isinstance(unrecorded, int) and unrecorded > 0:
            return masked_reason(unrecorded, self.raw_shape[0] * self.raw_shape[1])
        return "the warp map has no entry (build it with build_warp_map, which says why a map would have none)"

    # ------------------------------------------------------------------ files
    def save(self, path: str | os.PathLike) -> Path:
        """Write the map as a compressed ``.npz`` (atomically)."""
        path = Path(path)
        with atomic_file(path) as tmp, tmp.open("wb") as fh:  # a handle: np.savez would append ".npz" to a name
            np.savez_compressed(
                fh,
                indptr=self.indptr,
                indices=self.indices,
                weights=self.weights,
                gain=self.gain,
                coverage=self.coverage,
                raw_shape=np.asarray(self.raw_shape),
                key=np.asarray(self.key),
                meta=np.asarray(json.dumps(self.meta)),
            )
        return path

    @classmethod
    def load(cls, path: str | os.PathLike, *, expected_key: str | None = None) -> WarpMap:
        """Read a map written by :meth:`save`.

        Parameters
        ----------
        path : path-like
            The ``.npz`` file.
        expected_key : str, optional
            The :func:`warp_map_key` the map must have; another key is a stale map.

        Returns
        -------
        WarpMap

        Raises
        ------
        FileFormatError
            Naming the file and what is wrong: missing, empty, truncated or not an ``.npz``
            archive, an array missing, or arrays that break the map's invariants (see
            :class:`WarpMap`), or a stale key.
        """
        path = Path(path)
        name = str(path)
        if not path.is_file():
            raise FileFormatError(f"no such file: {name!r}")
        problem = None
        try:
            with path.open("rb") as fh:
                loaded = np.load(fh, allow_pickle=False)
                if not isinstance(loaded, np.lib.npyio.NpzFile):
                    problem = "it holds a single array (.npy), not an .npz archive"
                else:
                    with loaded as data:
                        missing = [k for k in (*_WARP_MAP_ARRAYS, "key", "meta") if k not in data.files]
                        if missing:
                            problem = f"it lacks the array(s) {missing}"
                        else:
                            arrays = {k: data[k] for k in _WARP_MAP_ARRAYS}
                            key_array, meta_array = data["key"], data["meta"]
        except (OSError, EOFError, ValueError, KeyError, zipfile.BadZipFile, zlib.error) as exc:
            raise FileFormatError(f"{name!r} is not a warp map: {type(exc).__name__}: {exc}") from None
        if problem is not None:
            raise FileFormatError(f"{name!r} is not a warp map: {problem}")
        if key_array.shape != () or key_array.dtype.kind != "U":
            raise FileFormatError(f"{name!r} is not a warp map: 'key' is not a string")
        key = str(key_array[()])
        if expected_key is not None and key != expected_key:
            raise FileFormatError(f"{name!r} is a warp map for other parameters (key {key}, expected {expected_key})")
        try:
            meta = json.loads(str(meta_array[()])) if meta_array.shape == () and meta_array.dtype.kind == "U" else None
        except ValueError:
            meta = None
        if not isinstance(meta, dict) or "output" not in meta:
            raise FileFormatError(f"{name!r} is not a warp map: 'meta' is not a JSON object with an 'output'")
        raw_shape = arrays.pop("raw_shape")
        if raw_shape.shape != (2,) or raw_shape.dtype.kind not in "iu":
            raise FileFormatError(
                f"{name!r} is not a valid warp map: raw_shape must be 2 integers, got {raw_shape.dtype} "
                f"shape {raw_shape.shape}"
            )
        try:
            return cls(
                output=PinholeCamera.from_dict(meta["output"]),
                raw_shape=(int(raw_shape[0]), int(raw_shape[1])),
                key=key,
                meta=meta,
                **arrays,
            )
        except ParameterError as exc:
            raise FileFormatError(f"{name!r} is not a valid warp map: {exc}") from None


#: Arrays of a warp-map file besides its key and meta.
_WARP_MAP_ARRAYS = ("raw_shape", "indptr", "indices", "weights", "gain", "coverage")

#: Largest distance from 1 of the sum of a non-empty row's weights. Rows are normalised in float64
#: and stored in float32, which moves each weight by at most 2^-24 of itself and so the sum by at
#: most 6e-8 whatever the row's length; 1e-4 accepts every map this code builds and refuses rows
#: that were never normalised (or were scaled).
ROW_SUM_TOLERANCE = 1e-4


def _native(name: str, arr: object, kinds: str, ndim: int) -> np.ndarray:
    """``arr`` if it is a native-byte-order ndarray of a dtype kind in ``kinds`` with ``ndim``
    dimensions (float: float32/float64 only, what the gather kernel takes), else raise."""
    what = {"iu": "an integer", "f": "a float32/float64"}[kinds]
    if not isinstance(arr, np.ndarray):
        raise ParameterError(f"{name} must be {what} numpy array, got {type(arr).__name__}")
    ok = arr.dtype.kind in kinds and arr.dtype.isnative and arr.ndim == ndim
    if kinds == "f":
        ok = ok and arr.dtype in (np.float32, np.float64)
    if not ok:
        raise ParameterError(
            f"{name} must be {what} array ({ndim}-D, native byte order), got {arr.dtype} shape {arr.shape}"
        )
    return arr


def _check_warp_map(warp: WarpMap) -> None:
    """Raise ParameterError unless the map's fields meet the invariants of :class:`WarpMap`."""
    if not isinstance(warp.output, PinholeCamera):
        raise ParameterError(f"output must be a PinholeCamera, got {warp.output!r}")
    if not isinstance(warp.raw_shape, tuple) or len(warp.raw_shape) != 2:
        raise ParameterError(f"raw_shape must be a (height, width) tuple, got {warp.raw_shape!r}")
    raw_h = image_side_px("raw_shape[0]", warp.raw_shape[0])
    raw_w = image_side_px("raw_shape[1]", warp.raw_shape[1])
    if not isinstance(warp.key, str):
        raise ParameterError(f"key must be a string, got {warp.key!r}")
    if not isinstance(warp.meta, dict):
        raise ParameterError(f"meta must be a dict, got {type(warp.meta).__name__}")
    n_pixels = warp.output.width_px * warp.output.height_px
    indptr = _native("indptr", warp.indptr, "iu", 1)
    indices = _native("indices", warp.indices, "iu", 1)
    weights = _native("weights", warp.weights, "f", 1)
    gain = _native("gain", warp.gain, "f", 1)
    coverage = _native("coverage", warp.coverage, "f", 2)
    if indptr.shape != (n_pixels + 1,):
        raise ParameterError(
            f"indptr must have one entry per output pixel plus one ({n_pixels + 1} for "
            f"{warp.output.width_px} x {warp.output.height_px}), got {indptr.shape[0]}"
        )
    if weights.shape != indices.shape:
        raise ParameterError(f"weights must match indices in length, got {weights.shape[0]} and {indices.shape[0]}")
    if gain.shape != (n_pixels,):
        raise ParameterError(f"gain must have one entry per output pixel ({n_pixels}), got shape {gain.shape}")
    if coverage.shape != (warp.output.height_px, warp.output.width_px):
        raise ParameterError(
            f"coverage must have the output's shape {(warp.output.height_px, warp.output.width_px)}, "
            f"got {coverage.shape}"
        )
    if indptr[0] != 0 or indptr[-1] != indices.shape[0]:
        raise ParameterError(
            f"indptr must run from 0 to len(indices) = {indices.shape[0]}, got {int(indptr[0])} to {int(indptr[-1])}"
        )
    steps = np.diff(indptr)
    if np.any(steps < 0):
        row = int(np.argmax(steps < 0))
        raise ParameterError(
            f"indptr must be non-decreasing, falls from {int(indptr[row])} to {int(indptr[row + 1])} at row {row}"
        )
    if indices.size and (int(indices.min()) < 0 or int(indices.max()) >= raw_h * raw_w):
        bad = int(indices.min()) if int(indices.min()) < 0 else int(indices.max())
        raise ParameterError(f"indices must lie in [0, {raw_h * raw_w}) (raw {raw_h} x {raw_w}), got {bad}")
    for label, arr in (("weights", weights), ("gain", gain), ("coverage", coverage)):
        finite = np.isfinite(arr)
        if not finite.all():
            raise ParameterError(f"{label} must be finite, got {float(arr[~finite].ravel()[0])!r}")
        if arr.size and arr.min() < 0.0:
            raise ParameterError(f"{label} must be non-negative, got {float(arr.min())!r}")
    if coverage.size and coverage.max() > 1.0:
        raise ParameterError(f"coverage must lie in [0, 1], got {float(coverage.max())!r}")
    starts = indptr[:-1][steps > 0]
    if starts.size:
        sums = np.add.reduceat(weights, starts, dtype=np.float64)
        worst = int(np.argmax(np.abs(sums - 1.0)))
        if abs(sums[worst] - 1.0) > ROW_SUM_TOLERANCE:
            row = int(np.flatnonzero(steps > 0)[worst])
            raise ParameterError(
                f"the weights of each non-empty row must sum to 1, row {row} sums to {float(sums[worst])!r}"
            )


def lens_plane_hits(points_cam: np.ndarray, directions_cam: np.ndarray) -> np.ndarray:
    """Where air rays through ``points_cam`` (N, 3) along ``directions_cam`` (N, 3) cross the
    main-lens plane z = 0: (N, 2), camera frame, metres (NaN for rays parallel to it)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        tau = -points_cam[:, 2] / directions_cam[:, 2]
        return points_cam[:, :2] + tau[:, None] * directions_cam[:, :2]


def mla_points_img(hit: np.ndarray, dirs: np.ndarray, f: float, f_prime: float) -> np.ndarray:
    """Image-plane MLA points (N, 2) of air rays leaving the main lens at ``hit`` (N, 2) along
    ``dirs`` (N, 3) (thin lens backwards: slope behind the lens = slope in front + hit / f; the MLA
    is ``f_prime`` behind the lens)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return -(hit - (dirs[:, :2] / dirs[:, 2:3] + hit / f) * f_prime)


def _camera_scalars(camera: LightFieldCamera, rim_margin_px: float) -> CameraScalars:
    """The camera's scalars for the candidate search (pixels nearer the rim than ``rim_margin_px``
    are not used)."""
    cu, cv = camera.sensor.centre_px
    return CameraScalars(
        f_m=float(camera.focal_length_m),
        f_prime_m=float(camera.lens_to_mla_m),
        f_mla_m=float(camera.mla.focal_length_m),
        pixel_pitch_m=float(camera.sensor.pixel_pitch_m),
        cu_px=float(cu),
        cv_px=float(cv),
        usable_radius2_m2=float(camera.usable_aperture_radius_m(rim_margin_px) ** 2),
        width_px=int(camera.sensor.width_px),
        height_px=int(camera.sensor.height_px),
    )


def _lattice_scalars(camera: LightFieldCamera) -> Lattice:
    """The camera's microlens lattice: basis columns a1, a2 and lens (0, 0)'s centre, metres."""
    b = camera.mla.basis_m
    off_x, off_y = camera.mla.offset_m
    return Lattice(
        a1x_m=float(b[0, 0]),
        a1y_m=float(b[1, 0]),
        a2x_m=float(b[0, 1]),
        a2y_m=float(b[1, 1]),
        off_x_m=float(off_x),
        off_y_m=float(off_y),
    )


def _air_face(port: FlatPort) -> AirFace:
    """The port's air-side face: unit normal and distance from the main-lens centre."""
    n = port.normal
    return AirFace(nx=float(n[0]), ny=float(n[1]), nz=float(n[2]), d_m=float(port.distance_m))


def _ray_model(correction: Correction | None) -> RayModel:
    """The kernels' form of a ray correction (None: the thin lens; a polynomial model is searched by
    the k-d tree only, :func:`uses_kdtree`, and never reaches the kernels)."""
    if not isinstance(correction, RayCorrection):
        return THIN_LENS
    return RayModel(*(float(v) for v in correction.vector()))


@dataclass(frozen=True)
class _Block:
    """Rows of one block of output pixels."""

    counts: np.ndarray  # (n,) entries per row
    indices: np.ndarray  # (nnz,) int32
    weights: np.ndarray  # (nnz,) float32
    factor: np.ndarray  # (n,) mean port factor over the sub-samples that pass the port (0: none)
    coverage: np.ndarray  # (n,) fraction of sub-samples recorded by the camera


@dataclass(frozen=True)
class _Search:
    """Everything the blocks of one build share."""

    camera: LightFieldCamera
    port: FlatPort
    output: PinholeCamera
    options: SynthesisOptions
    query: SearchQuery
    camera_scalars: CameraScalars
    lattice: Lattice
    face: AirFace
    model: RayModel
    tree: LazyRayTree


def _build_block(search: _Search, first: int, stop: int) -> _Block:
    """Necessary rays, coverage and rows of output pixels ``first:stop`` (row-major)."""
    camera, port, output, options = search.camera, search.port, search.output, search.options
    s = options.supersample
    offsets = (np.arange(s) + 0.5) / s - 0.5
    pixel = np.arange(first, stop)
    sub_u = (pixel % output.width_px)[:, None, None] + offsets[None, None, :]
    sub_v = (pixel // output.width_px)[:, None, None] + offsets[None, :, None]
    uv = np.stack(np.broadcast_arrays(sub_u, sub_v), axis=-1).reshape(-1, 2)  # pixel-major, s*s each
    points, dirs, transmittance, valid = necessary_air_rays(port, output.pixel_directions(uv))

    # The camera model's ray through the necessary air ray is the corrected ray of a thin-lens
    # ray, its twin: the pixels that record the necessary ray are those that record the twin in the
    # thin-lens model, so coverage and the candidate search follow the twin (the ray itself where
    # the model is the thin lens). Follow it back through the thin main lens to the MLA.
    f, f_prime = camera.focal_length_m, camera.lens_to_mla_m
    if options.ray_correction is None:
        hit, twin_dirs, has_twin = lens_plane_hits(points, dirs), dirs, valid
    else:
        hit, twin_slopes, has_twin = options.ray_correction.thin_lens_rays(points, dirs)
        twin_dirs = np.column_stack([twin_slopes, np.ones(len(hit))])  # only slopes are used
        has_twin &= valid
    radius = np.hypot(hit[:, 0], hit[:, 1])
    # The camera records the necessary ray only inside the usable aperture: rays through its rim
    # (rim_margin_px) are vignetted, so their pixels are never used.
    r_ok = camera.usable_aperture_radius_m(options.rim_margin_px)
    covered = has_twin & (radius <= r_ok)
    # A necessary ray outside it has no captured ray along it: aim the search at the parallel ray through
    # the nearest usable point of the aperture instead (paper section 6: nearby rays stand in;
    # these pixels are outside the exact coverage).
    with np.errstate(invalid="ignore", divide="ignore"):
        shrink = np.where(radius > r_ok, r_ok / radius, 1.0)
        aim_hit = hit * shrink[:, None]
        twin_slopes = twin_dirs[:, :2] / twin_dirs[:, 2:3]
    mla_point_img = mla_points_img(aim_hit, twin_dirs, f, f_prime)
    aim_points = np.concatenate([aim_hit + twin_slopes * points[:, 2:3], points[:, 2:3]], axis=1)
    usable = has_twin & np.all(np.isfinite(mla_point_img), axis=1)
    lens0 = np.zeros((len(uv), 2), dtype=np.int64)
    lens0[usable] = camera.mla.nearest_indices(mla_point_img[usable])
    # The camera records the necessary ray only if it also lands on the sensor (its MLA point's
    # image through the main-lens centre, i.e. its micro-image position, is on the pixel grid).
    with np.errstate(invalid="ignore"):
        sensor_px = camera.sensor.image_plane_to_pixels(
            mla_points_img(hit, twin_dirs, f, f_prime) * camera.micro_image_scale
        )
    covered &= (
        (sensor_px[:, 0] >= -0.5)
        & (sensor_px[:, 0] <= camera.sensor.width_px - 0.5)
        & (sensor_px[:, 1] >= -0.5)
        & (sensor_px[:, 1] <= camera.sensor.height_px - 0.5)
    )

    # The analytic search predicts, per lens, the pixel whose chief ray passes P: undefined where
    # the air-side face is conjugate to the MLA (beta = 0: all pixels of a lens see one point).
    beta = sensor_to_plane_scale(points[:, 2], f, f_prime, camera.mla.focal_length_m)
    by_tree = usable & (np.abs(beta) < 1e-9 * f_prime / camera.mla.focal_length_m)
    # A ray without a thin-lens twin (a correction whose radial terms fold the field over) has
    # no prediction either: only the exact search finds its candidates.
    no_twin = valid & ~has_twin
    if uses_kdtree(camera, options):
        by_tree = usable | no_twin
    elif options.search == "auto":
        by_tree |= no_twin
    elif options.search == "analytic" and np.any(by_tree):
        raise ParameterError(
            "the port's air-side face is conjugate to the MLA through the main lens "
            f"(f={f!r}, lens_to_mla_m={f_prime!r}): the analytic candidate search is undefined there; "
            "use search='auto' or 'kdtree' (--search auto or kdtree on the command line)"
        )
    n = stop - first
    sel_index = np.empty((len(uv), options.k), dtype=np.int64)
    sel_dist = np.empty((len(uv), options.k), dtype=np.float64)
    rays = NecessaryRays(
        points=np.nan_to_num(points),
        aim_points=np.nan_to_num(aim_points),
        dirs=np.nan_to_num(dirs),
        usable=usable & ~by_tree,
        lens0=lens0,
    )
    select_candidates(
        rays, search.query, search.camera_scalars, search.lattice, search.face, search.model, sel_index, sel_dist
    )
    if np.any(by_tree):
        sel_index[by_tree], sel_dist[by_tree] = search.tree.get().nearest(points[by_tree], dirs[by_tree], options.k)
    capacity = n * s * s * options.k
    indices = np.empty(capacity, dtype=np.int32)
    weights = np.empty(capacity, dtype=np.float32)
    counts = np.zeros(n, dtype=np.int64)
    nnz = merge_rows(sel_index, sel_dist, s * s, indices, weights, counts)
    factor = (transmittance * port.radiance_scale).reshape(n, s * s)
    passing = (factor > 0).sum(axis=1)
    return _Block(
        counts=counts,
        indices=indices[:nnz].copy(),
        weights=weights[:nnz].copy(),
        factor=factor.sum(axis=1) / np.maximum(passing, 1),
        coverage=covered.reshape(n, s * s).mean(axis=1),
    )


def build_warp_map(
    camera: LightFieldCamera,
    port: FlatPort,
    *,
    output: PinholeCamera | None = None,
    options: SynthesisOptions | None = None,
    workers: int | None = None,
    progress: bool = False,
) -> WarpMap:
    """Build the warp map for a camera behind a port.

    Parameters
    ----------
    camera : LightFieldCamera
    port : FlatPort
        The port; equal indices model no refraction.
    output : PinholeCamera, optional
        Geometry of the refraction-free image; default :func:`virtual_camera_for` ``(camera)``
        (the simulator's ideal image uses the same).
    options : SynthesisOptions, optional
    workers : int, optional
        Threads that build blocks of output pixels in parallel; default: the CPUs this process
        may use. The map does not depend on it.
    progress : bool
        Show a progress bar over the blocks (tqdm, on stderr).

    Returns
    -------
    WarpMap

    Raises
    ------
    ParameterError
        For arguments of the wrong type, a port that cuts the aperture, and a map that would give no
        output pixel a captured ray (an image with no value anywhere), naming why: the lines of sight miss
        the port, or the port reflects their light totally.
    """
    if not isinstance(camera, LightFieldCamera):
        raise ParameterError(f"camera must be a LightFieldCamera, got {camera!r}")
    if not isinstance(port, FlatPort):
        raise ParameterError(f"port must be a FlatPort, got {port!r}")
    output = output if output is not None else virtual_camera_for(camera)
    if not isinstance(output, PinholeCamera):
        raise ParameterError(f"output must be a PinholeCamera, got {output!r}")
    options = options if options is not None else SynthesisOptions()
    workers = _available_cpus() if workers is None else positive_int("workers", workers)
    if port.clearance_m(camera.aperture_radius_m) <= 0.0:
        raise ParameterError(f"port.distance_m={port.distance_m!r} cuts the main-lens aperture")
    search = _Search(
        camera=camera,
        port=port,
        output=output,
        options=options,
        query=SearchQuery(
            lens_offsets=_lens_offsets(camera, options.lens_rings),
            k=options.k,
            window=options.window,
            lam_m_per_rad=float(options.lambda_m_per_rad),
            sites=options.sites,
        ),
        camera_scalars=_camera_scalars(camera, options.rim_margin_px),
        lattice=_lattice_scalars(camera),
        face=_air_face(port),
        model=_ray_model(options.ray_correction),
        tree=LazyRayTree(
            camera,
            port,
            usable_radius_m=camera.usable_aperture_radius_m(options.rim_margin_px),
            lambda_m_per_rad=options.lambda_m_per_rad,
            sites=None if options.cfa_pattern is None else options.sites,
            correction=options.ray_correction,
        ),
    )
    n_pixels = output.width_px * output.height_px
    starts = range(0, n_pixels, BLOCK_PIXELS)
    with ThreadPoolExecutor(max_workers=workers) as pool:
        jobs = pool.map(lambda first: _build_block(search, first, min(first + BLOCK_PIXELS, n_pixels)), starts)
        blocks = list(tqdm(jobs, total=len(starts), desc="warp map", unit="block", disable=not progress))

    indptr = np.zeros(n_pixels + 1, dtype=np.int64)
    np.cumsum(np.concatenate([b.counts for b in blocks]), out=indptr[1:])
    require_a_value(indptr[-1] > 0, what="the refraction-free image", because=lambda: _why_no_ray(camera, port, output))
    mean_factor = np.concatenate([b.factor for b in blocks])
    gain = np.ones(n_pixels, dtype=np.float32)
    if options.compensate_port:
        gain = np.where(mean_factor > 0, 1.0 / np.where(mean_factor > 0, mean_factor, 1.0), 0.0).astype(np.float32)
    coverage = np.concatenate([b.coverage for b in blocks]).reshape(output.height_px, output.width_px)
    meta = {
        "version": WARP_MAP_VERSION,
        "lfrefract": __version__,
        "camera": camera.to_dict(),
        "port": port.to_dict(),
        "output": output.to_dict(),
        "options": options.to_dict(),
    }
    return WarpMap(
        output=output,
        raw_shape=(camera.sensor.height_px, camera.sensor.width_px),
        indptr=indptr,
        indices=np.concatenate([b.indices for b in blocks]),
        weights=np.concatenate([b.weights for b in blocks]),
        gain=gain,
        coverage=coverage,
        key=warp_map_key(camera, port, output, options),
        meta=meta,
    )


def _why_no_ray(camera: LightFieldCamera, port: FlatPort, output: PinholeCamera) -> str:
    """Why no output pixel of a warp map got a captured ray: its lines of sight miss the port, or the
    port reflects their light totally, or (neither) no captured ray lies near any of them."""
    v, u = np.indices((output.height_px, output.width_px))
    directions = output.pixel_directions(np.column_stack([u.ravel(), v.ravel()]).astype(np.float64))
    geometry = output_geometry(output)
    tilt = f"tilt {math.degrees(port.total_tilt_rad):.3g} deg"
    if not np.any(directions @ port.normal > 0.0):
        return (
            f"no line of sight of {geometry} reaches the port ({tilt}): they all point away from it; give an "
            "output geometry that looks through the port (the capture's ideal camera)"
        )
    if not np.any(necessary_air_rays(port, directions)[3]):
        return (
            f"the light of every line of sight of {geometry} is totally internally reflected at the port ({tilt}, "
            f"n_water {port.n_water:.4g}): none reaches the camera; give a port of less tilt, or an output geometry "
            "that looks through the port (the capture's ideal camera)"
        )
    return f"no captured ray of {camera.name!r} lies near the necessary ray of any pixel of {geometry}"


def build_cfa_warp_maps(
    camera: LightFieldCamera,
    port: FlatPort,
    cfa_pattern: str,
    *,
    output: PinholeCamera | None = None,
    options: SynthesisOptions | None = None,
    workers: int | None = None,
    progress: bool = False,
) -> dict[str, WarpMap]:
    """One warp map per colour of a Bayer mosaic, each gathering from that colour's pixels only.

    Parameters
    ----------
    camera, port, output, workers, progress
        As for :func:`build_warp_map`.
    cfa_pattern : str
        The mosaic's pattern (:data:`lfrefract.formats.mosaic.CFA_PATTERNS`).
    options : SynthesisOptions, optional
        Everything but the CFA fields, which are set per map.

    Returns
    -------
    dict
        ``{"R": map, "G": map, "B": map}`` (:func:`apply_cfa` applies them). Each colour's k
        captured rays are the nearest of its own pixels (a quarter of the sensor for R and B, half
        for G), so each channel averages as many rays as a map of every pixel.
    """
    options = options if options is not None else SynthesisOptions()
    return {
        colour: build_warp_map(
            camera,
            port,
            output=output,
            options=dataclasses.replace(options, cfa_pattern=cfa_pattern, cfa_colour=colour),
            workers=workers,
            progress=progress,
        )
        for colour in "RGB"
    }


def apply_cfa(maps: dict[str, WarpMap], values: np.ndarray) -> np.ndarray:
    """The refraction-free RGB image of a mosaic's values: each colour's map on the same values.

    Parameters
    ----------
    maps : dict
        :func:`build_cfa_warp_maps` output.
    values : ndarray, shape (H, W)
        One linear value per raw pixel (a devignetted mosaic; pixels of other colours are ignored
        by each map).

    Returns
    -------
    ndarray of float32, shape (height, width, 3)
    """
    if set(maps) != {"R", "G", "B"}:
        raise ParameterError(f"maps must have the colours R, G and B, got {sorted(maps)}")
    values = np.asarray(values)
    if values.ndim != 2:
        raise ParameterError(f"values must be one value per raw pixel, shape (H, W), got {values.shape}")
    return np.stack([maps[c].apply(values) for c in "RGB"], axis=-1)


def _available_cpus() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1
