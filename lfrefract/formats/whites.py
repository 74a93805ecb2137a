"""White images: find the one that matches a Lytro capture, and develop the capture with it.

A Lytro camera ships white images (a diffuser in front of the lens, many exposures averaged) for a
grid of zoom and focus settings: the Illum as bare 10-bit ``.raw`` files with their metadata in a
``.txt`` of JSON beside each, the first-generation camera (F01) as 12-bit ``.raw`` with ``.json``;
``lfsim whites`` writes the same. :func:`find_white_images` lists such a folder (reading only the
metadata), :func:`select_white_image` picks the one whose lens steps are nearest a capture's (as
LFToolbox's white-image database does: zoom first, then focus), and :func:`develop` turns a
capture's mosaic into the linear image the core works on:

1. the black level is subtracted from capture and white;
2. each pixel is divided by the white's (devignetting: the main lens's fall-off, each micro-image's
   edge and the colour filters' response all cancel), so 1 is the white image's brightness; where
   the white holds less than :data:`MIN_WHITE_FRACTION` of its bright level (the gaps between
   micro-images, a vignetted rim) there is no light to measure: the value is 0 for the demosaicing,
   and the pixel is unrecorded;
3. pixels that cannot be trusted are flagged: saturated in the capture (at the white level, so their
   value is only a lower bound) and bad in the white (:func:`bad_pixels`: saturated there, or far
   darker than their bright neighbours);
4. the result is demosaiced (OpenCV, :func:`lfrefract.formats.mosaic.demosaic_values`) into camera
   RGB, and every flagged pixel with the 3 x 3 neighbourhood its value was spread to, and every
   pixel the white does not light, is NaN (unrecorded: the core's commands give it no weight);
5. the file's colour matrix takes the (balanced) camera RGB to linear RGB: the colour filters pass
   mixtures of the scene's colours, which devignetting by a white alone does not undo. Its negative
   entries can take a dark, noisy pixel's colour below 0, which is clipped to 0.

Frames and units: images ``(H, W)`` or ``(H, W, 3)``, row ``v`` then column ``u``; lens steps are
the metadata's ``devices.lens.zoomStep`` / ``focusStep`` (integers).
"""

from __future__ import annotations

import errno
import functools
import json
import math
import os
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from scipy import ndimage

from lfrefract.errors import FileFormatError, ParameterError
from lfrefract.formats.lytro import LytroCapture, colour_matrix, read_f01_raw, read_illum_raw, read_lfr
from lfrefract.formats.mosaic import RawMosaic, cfa_channels, demosaic_values
from lfrefract.optics.camera import LightFieldCamera
from lfrefract.validate import bounded_float, one_of

__all__ = [
    "BAD_PIXEL_RATIO",
    "LYTRO_SUFFIXES",
    "MAX_SATURATED_SHARE",
    "MAX_WHITE_SHIFT_PX",
    "MIN_WHITE_FRACTION",
    "WHITE_EVEN_SHARE",
    "WHITE_GAP_SHARE",
    "WHITE_RING_FRACTION",
    "DevelopedCapture",
    "FlatField",
    "WhiteImage",
    "WhiteMeasures",
    "bad_pixels",
    "develop",
    "existing_path",
    "find_white_images",
    "flat_field",
    "is_lytro_file",
    "lens_steps",
    "micro_image_shift_px",
    "read_lytro_file",
    "same_file",
    "select_white_image",
    "white_measures",
    "white_problem",
]

#: File suffixes of Lytro captures and white images (case-insensitive).
LYTRO_SUFFIXES = (".lfr", ".raw")
#: Below this fraction of the white image's bright level (its 99th percentile, per colour) a pixel
#: receives too little light to devignet: its value is set to 0. The gaps between micro-images hold
#: a few percent; a tenth keeps the edge of every micro-image whose light is measurable.
MIN_WHITE_FRACTION = 0.1
#: A lit pixel whose white is below this fraction of the brightest white within
#: :data:`PEAK_REACH_PX` of it is partly vignetted: a stop cuts the part of the main lens's aperture
#: it sees (the lens's barrel at the field's edge, which the thin-lens model does not know, or the
#: micro-image's rim), so its light passes the aperture off the point the camera model gives it. Its
#: devignetted value is right, its ray is not: a fit on every raw pixel (chessboard corners in the
#: light field) leaves it out (:attr:`DevelopedCapture.fully_lit`). Across a vignetting edge the white
#: falls from its full value to the gap's within 1-2 px, inside a micro-image it changes by a few
#: percent over 2 px; measured on an Illum white through the double Gauss lens, 15 % of the pixels
#: the corner fit used lie below 0.8 (docs/calibration.md).
FULLY_LIT_FRACTION = 0.8
#: How far (pixels, along rows and columns) :data:`FULLY_LIT_FRACTION`'s brightest neighbour is sought:
#: the width of a vignetting edge.
PEAK_REACH_PX = 2
#: A white pixel this many times darker than the darkest of its eight nearest neighbours, all
#: bright, is dead (:func:`bad_pixels`; each colour relative to its bright level). Inside a
#: micro-image a white changes by less than a factor of 2 from pixel to pixel; a dead pixel reads
#: about 0.
BAD_PIXEL_RATIO = 4.0
#: Where the neighbours are bright enough to judge a pixel: this fraction of their colour's bright level.
_JUDGED_FRACTION = 0.5
#: Percentile of a colour's white values taken as its bright level.
_BRIGHT_PERCENTILE = 99.0
#: Percentile of the micro-image peaks at one distance from the light's centre taken as the white's
#: level there (:func:`white_problem`): a tenth of a ring may be brighter (noise, a hot micro-image).
_RING_PERCENTILE = 90.0
#: Most pixels of a white image that may be saturated: a white is exposed below saturation (hot pixels
#: are a few in a million).
MAX_SATURATED_SHARE = 0.01
#: Least share of a white's lit field with a darker gap within one micro-image pitch (:func:`white_problem`).
#: Measured: 100 % on the simulator's tiny whites and the test's drawn whites, 0 % on a uniform image.
WHITE_GAP_SHARE = 0.5
#: Least share of a white's lit field whose micro-images are at least half as bright as those at the same
#: distance from the light's centre (:func:`white_problem`). Measured: see the test of the rule.
WHITE_EVEN_SHARE = 0.9
#: A white's micro-image is as bright as those at its distance from the light's centre when its peak is
#: at least this fraction of theirs (:func:`white_problem`). A lens's fall-off is rotationally symmetric;
#: a scene's texture is not.
WHITE_RING_FRACTION = 0.8
#: Farthest (pixels) a white's micro-image centres may lie from the capture's, by the two files'
#: metadata (:func:`micro_image_shift_px`): beyond it a white of another zoom or focus setting would
#: devignette a micro-image's rim by its neighbour's gap (the synthesis leaves 0.71 px of the rim out).
MAX_WHITE_SHIFT_PX = 1.0


def is_lytro_file(path: str | os.PathLike) -> bool:
    """Whether ``path`` names a Lytro file by its suffix (``.lfr`` or ``.raw``)."""
    return Path(path).suffix.lower() in LYTRO_SUFFIXES


def existing_path(path: str | os.PathLike, what: str, *, kind: str = "file") -> Path:
    """``path``, after checking that it names something that can be looked at.

    ``Path.is_file()`` reads a symbolic link loop as a missing file and ``Path.resolve()`` raises
    RuntimeError on one: a loop is named here instead.

    Raises
    ------
    FileFormatError
        If ``path`` is a symbolic link loop, missing (or a link to nothing: "no such ``kind``") or
        cannot be looked at; the message names it as ``what``.
    """
    path = Path(path)
    try:
        path.stat()
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise FileFormatError(
                f"{what} {str(path)!r} is a symbolic link loop (it never reaches a file): point it at a file"
            ) from None
        if isinstance(exc, FileNotFoundError):
            dangling = " (a symbolic link to nothing)" if path.is_symlink() else ""
            raise FileFormatError(f"no such {kind}: {what} {str(path)!r}{dangling}") from None
        raise FileFormatError(f"{what} {str(path)!r} cannot be read: {exc.strerror or exc}") from None
    return path


def same_file(a: Path, b: Path) -> bool:
    """Whether ``a`` and ``b`` (both existing) are the same file."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def _raw_metadata(path: Path) -> tuple[Path, dict] | None:
    for suffix in (".json", ".txt", ".JSON", ".TXT"):
        meta = path.with_suffix(suffix)
        if meta.is_file():
            try:
                return meta, json.loads(meta.read_text(encoding="utf-8"))
            except (UnicodeDecodeError, json.JSONDecodeError) as exc:
                raise FileFormatError(f"{str(meta)!r} (the metadata of {str(path)!r}) is not JSON: {exc}") from None
    return None


def read_lytro_file(path: str | os.PathLike) -> LytroCapture:
    """Read a Lytro capture or white image: an Illum ``.lfr``, or a ``.raw`` with its metadata beside it
    (10-bit little-endian packing: the Illum's; 12-bit big-endian: the F01's).

    Raises
    ------
    FileFormatError
        If the file is missing, is no Lytro file, or its metadata is missing or malformed.
    """
    path = existing_path(path, "Lytro file")
    if not path.is_file():
        raise FileFormatError(f"{str(path)!r} is not a file (a Lytro file is a .lfr, or a .raw with its metadata)")
    suffix = path.suffix.lower()
    if suffix == ".lfr":
        return read_lfr(path)
    if suffix != ".raw":
        raise FileFormatError(f"{str(path)!r} is no Lytro file (its suffix is none of {list(LYTRO_SUFFIXES)})")
    found = _raw_metadata(path)
    if found is None:
        raise FileFormatError(f"{str(path)!r} has no metadata beside it (.json or .txt)")
    _, metadata = found
    image = metadata.get("image") if isinstance(metadata, dict) else None
    if isinstance(image, dict) and isinstance(image.get("rawDetails"), dict):
        return read_f01_raw(path)
    return read_illum_raw(path)


def lens_steps(metadata: dict, where: str) -> dict[str, int | None]:
    """``devices.lens.zoomStep`` and ``focusStep`` of a Lytro file's metadata, None where absent.

    Raises
    ------
    FileFormatError
        If one is present but not an integer (the message names the key and ``where``).
    """
    devices = metadata.get("devices") if isinstance(metadata, dict) else None
    lens = devices.get("lens") if isinstance(devices, dict) else None
    steps: dict[str, int | None] = {}
    for key in ("zoomStep", "focusStep"):
        value = lens.get(key) if isinstance(lens, dict) else None
        if value is not None and (isinstance(value, bool) or not isinstance(value, int)):
            raise FileFormatError(f"{where}: metadata 'devices.lens.{key}' must be an integer, got {value!r}")
        steps[key] = value
    return steps


def _lens_step(metadata: dict, key: str, where: str) -> int:
    value = lens_steps(metadata, where)[key]
    if value is None:
        raise FileFormatError(f"{where}: the metadata has no integer devices.lens.{key}")
    return value


@dataclass(frozen=True, kw_only=True)
class WhiteImage:
    """A white image on disk and the lens setting it was taken at (its mosaic is read on demand).

    Attributes
    ----------
    path : pathlib.Path
        The ``.raw`` (metadata beside it) or ``.lfr`` file.
    zoom_step, focus_step : int
        The lens motors' positions of its metadata (``devices.lens``).
    """

    path: Path
    zoom_step: int
    focus_step: int

    @classmethod
    def from_file(cls, path: str | os.PathLike) -> WhiteImage:
        """The white image of ``path``, its lens steps read from its metadata (not its mosaic)."""
        path = existing_path(path, "white image")
        where = repr(str(path))
        if not is_lytro_file(path):
            raise FileFormatError(
                f"white image {where} is no Lytro file: a white image is a .raw with its .json or .txt metadata beside "
                "it, or an .lfr, a folder of them (lfsim whites writes one); it develops a Lytro capture's mosaic, "
                "which a render's raw.exr is not"
            )
        if path.suffix.lower() == ".lfr":
            metadata = read_lfr(path).metadata
        else:
            found = _raw_metadata(path)
            if found is None:
                raise FileFormatError(f"{where} has no metadata beside it (.json or .txt)")
            metadata = found[1]
        if not isinstance(metadata, dict):
            raise FileFormatError(f"{where}: the metadata is not a JSON object")
        zoom, focus = _lens_step(metadata, "zoomStep", where), _lens_step(metadata, "focusStep", where)
        return cls(path=path, zoom_step=zoom, focus_step=focus)

    def read(self) -> LytroCapture:
        """The white image's mosaic and metadata (:func:`read_lytro_file`)."""
        return read_lytro_file(self.path)

    def flat_field(self) -> FlatField:
        """The white's :func:`flat_field`, prepared once for all the captures it develops (read again
        only when the file changes: its inode, size, modification or status change time).

        Raises
        ------
        FileFormatError
            If the file is no white image (:func:`white_problem`), naming it and why.
        """
        field, _, problem = self.prepared()
        if problem is not None:
            raise FileFormatError(f"{str(self.path)!r} is no white image: {problem}")
        return field

    def prepared(self) -> tuple[FlatField, LightFieldCamera, str | None]:
        """Its :func:`flat_field`, the camera of its metadata and :func:`white_problem` (why it is no
        white image; None if it is one), read once (again only when the file changes).

        Raises
        ------
        FileFormatError
            If the file cannot be read.
        """
        stat = existing_path(self.path, "white image").stat()
        # The status change time and inode too: whites of one camera are all of one size, and one copied
        # over the file with ``cp -p`` keeps the modification time; the kernel sets ctime on every write.
        key = (stat.st_dev, stat.st_ino, stat.st_size, stat.st_mtime_ns, stat.st_ctime_ns)
        return _white_of_file(str(self.path.resolve()), key)


@functools.lru_cache(maxsize=2)  # a stereo rig's two whites; an Illum's flat field is about 0.25 GB
def _white_of_file(path: str, stat_key: tuple[int, ...]) -> tuple[FlatField, LightFieldCamera, str | None]:
    """:meth:`WhiteImage.prepared` of the white image file ``path``; ``stat_key`` (its device, inode, size,
    modification and status change times) keys the cache."""
    white = read_lytro_file(path)
    field = flat_field(white.mosaic)
    problem = white_problem(white.mosaic, field, micro_image_pitch_px=white.camera.micro_image_pitch_px)
    return field, white.camera, problem


@dataclass(frozen=True)
class WhiteMeasures:
    """What :func:`white_problem` judges a white image by (:func:`white_measures`).

    Attributes
    ----------
    saturated_share : float
        Share of its pixels at the white level.
    lit : bool
        Whether any usable pixel holds light above the black level.
    gap_share : float
        Share of its lit field (where a micro-image within 1.5 pitches peaks above
        2 * :data:`MIN_WHITE_FRACTION` of its colour's bright level) whose window of one micro-image
        pitch holds a pixel under half its brightest: the gaps between micro-images. NaN if not lit.
    even_share : float
        Share of the lit field whose micro-image peaks at least :data:`WHITE_RING_FRACTION` of the
        level of the peaks at its distance from the light's centre (:func:`_ring_levels`). NaN if not lit.
    """

    saturated_share: float
    lit: bool
    gap_share: float
    even_share: float


def white_measures(mosaic: RawMosaic, field: FlatField, *, micro_image_pitch_px: float) -> WhiteMeasures:
    """The measures of ``mosaic`` (with its :func:`flat_field`) that tell a white image from a capture.

    Each colour is taken relative to its bright level, bad pixels left out; a micro-image's peak is
    the brightest pixel within half a pitch. ``micro_image_pitch_px`` is the micro-image pitch, pixels.
    """
    saturated = float(mosaic.saturated.mean())
    levels = field.lit_dn[field.usable & ~field.bad]
    if levels.size == 0 or float(levels.max()) <= 0.0:
        return WhiteMeasures(saturated_share=saturated, lit=False, gap_share=math.nan, even_share=math.nan)
    bright = _bright_levels(field.lit_dn.astype(np.float64), mosaic.channel_index())
    relative = np.divide(field.lit_dn, bright, out=np.zeros(field.shape), where=(bright > 0.0) & ~field.bad)
    relative = relative.astype(np.float32)
    near = np.ones((2 * math.ceil(micro_image_pitch_px / 2) + 1,) * 2, dtype=np.uint8)
    around = np.ones((2 * math.ceil(1.5 * micro_image_pitch_px) + 1,) * 2, dtype=np.uint8)
    border = cv2.BORDER_REPLICATE
    peak = cv2.dilate(relative, near, borderType=border)
    valley = cv2.erode(relative, near, borderType=border)
    brightest = cv2.dilate(peak, around, borderType=border)
    lit = brightest >= 2.0 * MIN_WHITE_FRACTION
    gaps = float((valley < 0.5 * peak)[lit].mean())
    step = max(1, int(micro_image_pitch_px // 2))  # the peak map is flat within a micro-image
    peaks, judged = peak[::step, ::step], lit[::step, ::step]
    level = _ring_levels(peaks, judged, ring_px=1.0, reach_px=micro_image_pitch_px / step)
    even = float((peaks >= WHITE_RING_FRACTION * level)[judged].mean())
    return WhiteMeasures(saturated_share=saturated, lit=True, gap_share=gaps, even_share=even)


def white_problem(mosaic: RawMosaic, field: FlatField, *, micro_image_pitch_px: float) -> str | None:
    """Why ``mosaic`` (with its :func:`flat_field`) is no white image; None if it is one.

    A white image is a diffuser's uniform light through the camera (:func:`white_measures`): under
    :data:`MAX_SATURATED_SHARE` of its pixels saturated, some light, micro-images separated by darker
    gaps (in at least :data:`WHITE_GAP_SHARE` of its lit field), and every lit micro-image near the
    level of those at its distance from the light's centre (in at least :data:`WHITE_EVEN_SHARE` of the
    lit field). A capture of a scene or a board fails the last test, an image with no micro-images the
    gaps'. A lens's fall-off is rotationally symmetric about its axis, however steep: the edge of an
    image circle smaller than the sensor (a Petzval or a near-telecentric design) passes.
    """
    measures = white_measures(mosaic, field, micro_image_pitch_px=micro_image_pitch_px)
    if measures.saturated_share > MAX_SATURATED_SHARE:
        return (
            f"{100 * measures.saturated_share:.1f} % of its pixels are saturated (at the white level "
            f"{mosaic.white_level_dn}); a white image is exposed below saturation (at most "
            f"{100 * MAX_SATURATED_SHARE:g} %)"
        )
    if not measures.lit:
        return f"it holds no light (every pixel at or below the black level {mosaic.black_level_dn})"
    if measures.gap_share < WHITE_GAP_SHARE:
        return (
            f"it shows no micro-images: only {100 * measures.gap_share:.0f} % of its lit field has darker gaps "
            f"within one micro-image pitch ({micro_image_pitch_px:.1f} px), a white image's has them nearly everywhere"
        )
    if measures.even_share < WHITE_EVEN_SHARE:
        return (
            f"its light is not uniform: in {100 * (1 - measures.even_share):.0f} % of its lit field a micro-image "
            f"is under {100 * WHITE_RING_FRACTION:.0f} % as bright as those at its distance from the light's "
            "centre (a scene or board capture?); a white image's micro-images follow the lens's rotationally "
            f"symmetric fall-off (allowed: {100 * (1 - WHITE_EVEN_SHARE):.0f} %)"
        )
    return None


def _ring_levels(peaks: np.ndarray, lit: np.ndarray, *, ring_px: float, reach_px: float) -> np.ndarray:
    """The level of a white's light about each pixel's distance from the light's centre, shape of ``peaks``.

    ``peaks`` (H, W) holds the relative micro-image peaks, ``lit`` (H, W) where they are judged. The
    light's centre is the peaks' centroid over ``lit``; the lit pixels are binned into rings ``ring_px``
    wide about it, a ring's level is its :data:`_RING_PERCENTILE` th percentile (0 for a ring with no lit
    pixel), and each pixel gets the lowest level of the rings within ``reach_px`` of its own: where the
    light falls off steeply (an image circle's edge, drawn in micro-images) a micro-image is judged
    against the fall-off one pitch farther out.
    """
    rows, cols = np.nonzero(lit)
    if rows.size == 0:
        return np.zeros(peaks.shape)
    values = peaks[rows, cols].astype(np.float64)
    weights = np.maximum(values, 0.0)
    total = float(weights.sum()) or 1.0
    centre = (float(rows @ weights) / total, float(cols @ weights) / total)
    grid_rows, grid_cols = np.indices(peaks.shape)
    ring = (np.hypot(grid_rows - centre[0], grid_cols - centre[1]) / ring_px).astype(np.int64)
    lit_ring = ring[rows, cols]
    order = np.lexsort((values, lit_ring))  # by ring, then by value within it
    sorted_rings, sorted_values = lit_ring[order], values[order]
    starts = np.flatnonzero(np.r_[True, sorted_rings[1:] != sorted_rings[:-1]])
    counts = np.diff(np.r_[starts, sorted_rings.size])
    level = np.zeros(int(ring.max()) + 1)
    level[sorted_rings[starts]] = sorted_values[
        starts + np.floor(_RING_PERCENTILE / 100 * (counts - 1)).astype(np.int64)
    ]
    reach = math.ceil(reach_px / ring_px)
    return ndimage.minimum_filter1d(level, 2 * reach + 1, mode="constant", cval=0.0)[ring]


def micro_image_shift_px(a: LightFieldCamera, b: LightFieldCamera) -> float:
    """Largest distance between the micro-image centres of the same microlenses in cameras ``a`` and
    ``b`` (over ``a``'s lenses on its sensor), pixels: how far a white of ``b`` misplaces ``a``'s micro-images."""
    indices = a.lens_indices_on_sensor()
    if len(indices) == 0:
        return 0.0
    return float(np.max(np.linalg.norm(a.micro_image_centres_px(indices) - b.micro_image_centres_px(indices), axis=1)))


def find_white_images(folder: str | os.PathLike) -> list[WhiteImage]:
    """Every white image in ``folder`` (not its sub-folders): ``.raw`` files with metadata beside them
    and ``.lfr`` files, sorted by name; only their metadata is read.

    Raises
    ------
    FileFormatError
        If ``folder`` is no folder, holds no white image, or a file's metadata lacks the lens steps.
    """
    folder = Path(folder)
    if not existing_path(folder, "white-image folder", kind="folder").is_dir():
        raise FileFormatError(f"white-image folder {str(folder)!r} is not a folder")
    # A link among them that reaches nothing is named, not skipped.
    files = sorted(p for p in folder.iterdir() if is_lytro_file(p) and existing_path(p, "white image").is_file())
    whites = [WhiteImage.from_file(p) for p in files if p.suffix.lower() == ".lfr" or _raw_metadata(p) is not None]
    if not whites:
        raise FileFormatError(f"white-image folder {str(folder)!r} holds no .raw (with metadata) or .lfr file")
    return whites


def select_white_image(whites: list[WhiteImage], *, zoom_step: int, focus_step: int) -> WhiteImage:
    """The white image whose lens setting is nearest: smallest zoom difference, then focus difference.

    The micro-image centres move with zoom far more than with focus, so zoom decides first, as in
    LFToolbox's white-image database; ties go to the first by name.
    """
    if not whites:
        raise ParameterError("whites must hold at least one WhiteImage")
    return min(whites, key=lambda w: (abs(w.zoom_step - zoom_step), abs(w.focus_step - focus_step)))


def _bright_levels(values: np.ndarray, channels: np.ndarray) -> np.ndarray:
    """Per-pixel bright level of its colour: the colour's 99th percentile, shape (H, W)."""
    levels = np.zeros(3)
    for c in range(3):
        sites = values[channels == c]
        levels[c] = float(np.percentile(sites, _BRIGHT_PERCENTILE)) if sites.size else 0.0
    return levels[channels]


@dataclass(frozen=True, eq=False, kw_only=True)
class FlatField:
    """A white image prepared to devignette captures (:func:`flat_field`); :func:`develop` takes it
    in place of the white's mosaic, which spares a command the white's work for every capture.

    Attributes
    ----------
    lit_dn : ndarray of float32, shape (H, W)
        The white's black-subtracted counts (digital numbers): what a capture is divided by.
    usable : ndarray of bool, shape (H, W)
        Pixels the white lights enough to devignette: at least :data:`MIN_WHITE_FRACTION` of their
        colour's bright level.
    fully_lit : ndarray of bool, shape (H, W)
        Usable pixels no stop vignettes in part: at least :data:`FULLY_LIT_FRACTION` of the
        brightest white within :data:`PEAK_REACH_PX` (each colour relative to its bright level).
    bad : ndarray of bool, shape (H, W)
        The white's :func:`bad_pixels`.
    cfa_pattern : str
        The white's mosaic pattern.
    """

    lit_dn: np.ndarray
    usable: np.ndarray
    fully_lit: np.ndarray
    bad: np.ndarray
    cfa_pattern: str

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)``, pixels."""
        return self.lit_dn.shape


def flat_field(white: RawMosaic) -> FlatField:
    """What a white image gives every capture it develops (steps 1-3 of the module docstring on the
    white's side): its black-subtracted counts, the pixels it lights and its bad pixels."""
    if not isinstance(white, RawMosaic):
        raise ParameterError(f"white must be a RawMosaic, got {type(white).__name__}")
    lit = np.maximum(white.counts.astype(np.float64) - white.black_level_dn, 0.0)
    bright = _bright_levels(lit, white.channel_index())
    usable = lit >= MIN_WHITE_FRACTION * bright
    bad = bad_pixels(white)
    # Each colour relative to its bright level, so that neighbours of other colours compare; a bad
    # pixel (a hot one) must not make its neighbours look vignetted.
    relative = np.divide(lit, bright, out=np.zeros_like(lit), where=(bright > 0.0) & ~bad).astype(np.float32)
    reach = 2 * PEAK_REACH_PX + 1
    peak = cv2.dilate(relative, np.ones((reach, reach), dtype=np.uint8), borderType=cv2.BORDER_REPLICATE)
    fully_lit = usable & (relative >= FULLY_LIT_FRACTION * peak)
    field = FlatField(
        lit_dn=lit.astype(np.float32), usable=usable, fully_lit=fully_lit, bad=bad, cfa_pattern=white.cfa_pattern
    )
    for array in (field.lit_dn, field.usable, field.fully_lit, field.bad):
        array.flags.writeable = False  # shared between the captures a white develops
    return field


def bad_pixels(white: RawMosaic, *, ratio: float = BAD_PIXEL_RATIO) -> np.ndarray:
    """Dead and hot pixels of a white image: bool (H, W).

    *Hot*: at the white level (a white image is exposed below saturation: a pixel there does not
    follow the light). *Dead*: ``ratio`` times darker than the darkest of its eight nearest
    neighbours while they are all bright, each value black-subtracted and divided by its colour's
    bright level (so the colours compare): at least half of it, inside a micro-image, where a white
    image is smooth. A pixel in a gap between micro-images has a dim neighbour in the gap, however
    narrow, and is not judged; a dead pixel is found anywhere but on a micro-image's outermost ring.
    """
    if not isinstance(white, RawMosaic):
        raise ParameterError(f"white must be a RawMosaic, got {type(white).__name__}")
    ratio = bounded_float("ratio", ratio, 1.0, 1e6, low_open=True)
    values = np.maximum(white.counts.astype(np.float64) - white.black_level_dn, 0.0)
    bright = _bright_levels(values, white.channel_index())
    relative = np.divide(values, bright, out=np.zeros_like(values), where=bright > 0)
    ring = np.ones((3, 3), dtype=bool)
    ring[1, 1] = False
    darkest = ndimage.minimum_filter(relative, footprint=ring, mode="mirror")
    dead = (darkest >= _JUDGED_FRACTION) & (relative * ratio < darkest)
    return dead | white.saturated


@dataclass(frozen=True, eq=False, kw_only=True)
class DevelopedCapture:
    """A Lytro capture developed for the core (:func:`develop`).

    Attributes
    ----------
    image : ndarray of float32, shape (H, W, 3)
        Camera RGB relative to the white image (1: as bright as the white), or without a white
        black-subtracted counts over ``white - black``; NaN at unrecorded pixels.
    values : ndarray of float32, shape (H, W)
        The devignetted mosaic before demosaicing: one value per pixel, of its colour
        (``cfa_pattern``); 0 at flagged pixels.
    cfa_pattern : str
        The mosaic's pattern.
    saturated, bad : ndarray of bool, shape (H, W)
        Pixels at the capture's white level, and bad pixels of the white image.
    flagged : ndarray of bool, shape (H, W)
        ``saturated | bad``: the pixels of ``values`` not to be used.
    lit : ndarray of bool, shape (H, W)
        Pixels the white image lights enough to devignet (every pixel without a white); elsewhere
        ``values`` is 0.
    fully_lit : ndarray of bool, shape (H, W)
        Lit pixels that no stop vignettes in part (:attr:`FlatField.fully_lit`; every pixel without a
        white): those whose ray is the camera model's.
    unrecorded : ndarray of bool, shape (H, W)
        The NaN pixels of ``image``: ``flagged`` grown by one pixel (the demosaicing's reach), and
        the pixels not ``lit``. A real main lens's micro-images are smaller than the disc a camera
        model's aperture gives them (its stops vignette them), so unlit pixels lie inside it too: read
        as 0 they were black samples in the synthesis (through the Heliar design at tiny-2x a test
        board's corners 0.36 px RMS off where they were found, and in one view of four not found;
        with them unrecorded 0.32 px and found).
    white : WhiteImage or None
        The white image used.
    color_matrix : ndarray, shape (3, 3)
        The colour matrix ``image`` went through (camera RGB, balanced, to linear RGB); a
        colour-by-colour synthesis of ``values`` applies it to its result.
    """

    image: np.ndarray
    values: np.ndarray
    cfa_pattern: str
    saturated: np.ndarray
    bad: np.ndarray
    flagged: np.ndarray
    lit: np.ndarray
    fully_lit: np.ndarray
    unrecorded: np.ndarray
    white: WhiteImage | None
    color_matrix: np.ndarray

    def measured(self) -> np.ndarray:
        """:attr:`image` with the pixels the white does not light fully unrecorded (NaN) too.

        In :attr:`image` unlit pixels are unrecorded; a fit on every raw pixel (the light field's
        chessboard corners) leaves out those lit in part as well (not :attr:`fully_lit`): their light
        passes the aperture away from where the camera model puts their ray (at the field's edge,
        where the main lens vignettes parts of micro-images, an Illum in-air board 17.5 deg off the
        axis had 9 of its 24 corners located in the light field with its unlit pixels read as 0, 24
        with them unrecorded).

        Returns
        -------
        ndarray of float32, shape (H, W, 3)
        """
        return np.where(self.fully_lit[..., None], self.image, np.float32(np.nan))

    def grey(self) -> np.ndarray:
        """The devignetted mosaic as one grey light field at full resolution, nothing interpolated.

        Each colour's sites of :attr:`values` are divided by that colour's bright level (the 99th
        percentile of its recorded sites), so that on a neutral target (a black and white
        chessboard) the three colours agree whatever the light's colour; NaN at :attr:`flagged`
        pixels and where the white image gives no light or not its full light (:attr:`fully_lit`,
        as :meth:`measured`). Corners located on it are not moved by demosaicing, which mixes each
        micro-image's border pixels with its dark neighbours (docs/calibration.md measures the
        difference).

        Returns
        -------
        ndarray of float32, shape (H, W)
        """
        channels = cfa_channels(self.cfa_pattern, self.values.shape)
        recorded = self.fully_lit & ~self.flagged
        levels = np.zeros(3)
        for c in range(3):
            sites = self.values[recorded & (channels == c)]
            levels[c] = float(np.percentile(sites, _BRIGHT_PERCENTILE)) if sites.size else 0.0
        if not np.all(levels > 0.0):
            raise ParameterError(
                f"the capture has no recorded light in some colour (bright levels R, G, B {levels.tolist()}): "
                "it cannot be turned into a grey light field"
            )
        grey = (self.values / levels[channels]).astype(np.float32)
        grey[~recorded] = np.nan
        return grey


def develop(
    mosaic: RawMosaic,
    white: RawMosaic | FlatField | None = None,
    *,
    white_image: WhiteImage | None = None,
    color_matrix: np.ndarray | None = None,
    white_balance_gain: tuple[float, float, float] = (1.0, 1.0, 1.0),
    method: str = "bilinear",
) -> DevelopedCapture:
    """Black level, devignetting by ``white``, flags, demosaicing and colour: the module's steps 1-5.

    Parameters
    ----------
    mosaic : RawMosaic
        The capture.
    white : RawMosaic or FlatField, optional
        The white image of the same lens setting and sensor (same shape and pattern), or its
        :func:`flat_field` (prepared once for many captures: :meth:`WhiteImage.flat_field`). Without one
        the capture is only black-subtracted, scaled to its white level and white-balanced by
        ``white_balance_gain`` (not devignetted).
    white_image : WhiteImage, optional
        Where ``white`` came from (recorded in the result).
    color_matrix : array_like, shape (3, 3), optional
        The file's colour matrix from white-balanced camera RGB to linear RGB (Lytro's ``ccm``),
        applied to the demosaiced image (default identity). Devignetting by a white image balances
        the colours to the white's.
    white_balance_gain : tuple of 3 float
        Gains of R, G, B without a white (Lytro's ``whiteBalanceGain``; the two greens' mean).
    method : {"bilinear", "edge_aware"}
        OpenCV's demosaicing.

    Raises
    ------
    ParameterError
        If the white does not match the capture (shape or pattern).
    """
    if not isinstance(mosaic, RawMosaic):
        raise ParameterError(f"mosaic must be a RawMosaic, got {type(mosaic).__name__}")
    one_of("method", method, ("bilinear", "edge_aware"))
    saturated = mosaic.saturated
    counts = np.maximum(mosaic.counts.astype(np.float64) - mosaic.black_level_dn, 0.0)
    matrix = np.eye(3) if color_matrix is None else colour_matrix("color_matrix", np.asarray(color_matrix).reshape(-1))
    gains = np.array(
        [
            bounded_float(f"white_balance_gain[{i}]", g, 0.0, 1e3, low_open=True)
            for i, g in enumerate(white_balance_gain)
        ],
    )
    if white is None:
        values = counts / (mosaic.white_level_dn - mosaic.black_level_dn) * gains[mosaic.channel_index()]
        bad = np.zeros(mosaic.shape, dtype=bool)
        usable = fully_lit = np.ones(mosaic.shape, dtype=bool)
    else:
        if not isinstance(white, (RawMosaic, FlatField)):
            raise ParameterError(f"white must be a RawMosaic or a FlatField, got {type(white).__name__}")
        if white.shape != mosaic.shape or white.cfa_pattern != mosaic.cfa_pattern:
            raise ParameterError(
                f"the white image ({white.shape[1]} x {white.shape[0]} px, {white.cfa_pattern}) does not match the "
                f"capture ({mosaic.shape[1]} x {mosaic.shape[0]} px, {mosaic.cfa_pattern})"
            )
        field = white if isinstance(white, FlatField) else flat_field(white)
        usable, fully_lit, bad = field.usable, field.fully_lit, field.bad
        values = np.divide(counts, field.lit_dn, out=np.zeros_like(counts), where=usable)
    flagged = saturated | bad
    kept = np.where(flagged, 0.0, values)
    # The colour matrix has negative entries: in dark pixels noise can take a colour below 0, which is
    # no radiance; it is clipped to 0 (a bias of a fraction of the noise there).
    image = np.maximum(demosaic_values(kept, mosaic.cfa_pattern, method=method) @ matrix.T, 0.0).astype(np.float32)
    unrecorded = ndimage.binary_dilation(flagged, structure=np.ones((3, 3), dtype=bool)) | ~usable
    image[unrecorded] = np.nan
    return DevelopedCapture(
        image=image,
        values=kept.astype(np.float32),
        cfa_pattern=mosaic.cfa_pattern,
        saturated=saturated,
        bad=bad,
        flagged=flagged,
        lit=usable,
        fully_lit=fully_lit,
        unrecorded=unrecorded,
        white=white_image,
        color_matrix=matrix,
    )
