"""What a Lytro sensor writes: a Bayer mosaic of integer digital numbers from the rendered radiance.

``raw.exr`` holds the noiseless per-pixel RGB radiance the camera receives (each pixel the mean
over its area). A real sensor turns it into one integer per pixel; this module models that chain,
in this order, with numpy and scipy only:

1. **Optics in front of the pixels.** Each input channel is convolved with the point-spread
   function (PSF) of diffraction at the microlens f-number ``N`` for that channel's wavelength
   ``lambda``: an Airy pattern whose first dark ring has radius ``1.22 lambda N``, or its Gaussian
   fit of standard deviation ``0.42 lambda N``; optionally widened by a Gaussian for what diffraction
   does not cover (microlens aberrations, defocus). The discrete kernel is the PSF integrated over
   each pixel: the share of the light of a point at a pixel's centre that each pixel receives.
2. **Colour filter array.** Each pixel keeps one channel of a 2 x 2 Bayer tile (``cfa_pattern``,
   top-left pixel first, row by row: ``"GRBG"`` is G R on row 0 and B G on row 1). Its filter
   passes a weighted sum of the input's linear RGB (``cfa_response``: rows R, G, B of the filter,
   columns the input's R, G, B).
3. **Photons to electrons.** Mean photoelectrons = ``quantum_efficiency *
   photons_per_unit_radiance * (filtered radiance)``; pixel crosstalk then moves the fraction
   ``crosstalk`` of each pixel's charge to its four neighbours (a quarter each).
4. **Noise and the converter.** Photoelectrons are Poisson-distributed about that mean (shot noise)
   and clipped at the full well; Gaussian read noise (electrons RMS) is added; the analogue gain
   (digital numbers per electron, ``gain_dn_per_e * iso / base_iso``) and the black level give the
   digital number, rounded to the nearest integer and clipped to ``[0, white_level_dn]``.

Frames and units: images are ``(H, W)`` or ``(H, W, 3)``, row ``v`` then column ``u``, pixel
centres at integers (as in OpenCV); radiance in the renderer's units; charge in electrons (e-);
digital numbers (DN) are integer counts.

:data:`DETECTOR_PRESETS` holds the Lytro Illum, the first-generation Lytro (F01) and the test camera
``tiny``; ``docs/simulator.md`` ("The sensor model") gives the source of every number.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import fft as sp_fft
from scipy import ndimage, signal, special

from lfrefract.errors import ParameterError
from lfrefract.formats.lytro import LytroSettings
from lfrefract.formats.mosaic import CFA_PATTERNS, DEMOSAIC_METHODS, RawMosaic, cfa_channels, demosaic
from lfrefract.optics.presets import camera_preset
from lfrefract.validate import (
    bounded_float,
    bounded_int,
    finite_vector,
    non_negative_float,
    one_of,
    positive_float,
    reject_unknown_keys,
    require_keys,
    shown,
)
from simulator.seeds import seed as checked_seed

__all__ = [
    "DEMOSAIC_METHODS",
    "DETECTOR_PRESETS",
    "PSF_MODELS",
    "DetectorConfig",
    "demosaic",
    "detector_preset",
    "edge_width_px",
    "expected_electrons",
    "lytro_settings",
    "pixel_psf_kernel",
    "radial_profile",
    "simulate_mosaic",
    "white_frames",
]

#: Point-spread functions of the optics in front of the pixels (``"none"``: no optical blur).
PSF_MODELS = ("airy", "gaussian", "none")
#: First zero of the Bessel function J1: the Airy pattern's first dark ring is at v = 3.8317,
#: r = 3.8317 / pi * lambda * N = 1.2197 lambda N.
_AIRY_FIRST_ZERO = 3.8317059702075125
#: Gaussian fit to the Airy disc: sigma = 0.42 lambda N (the paraxial best fit to the Airy core,
#: 0.21 lambda / NA with NA = 1 / (2 N)).
_GAUSSIAN_AIRY_SIGMA = 0.42
#: Airy kernels reach this many first-ring radii (beyond, J0^2 + J1^2 ~ 2 / (pi v) ~ 0.7 % of the
#: light is left out and the kernel renormalised); Gaussian kernels reach 6 sigma (2e-9 left out).
_AIRY_REACH_RINGS = 25.0
_GAUSSIAN_REACH_SIGMAS = 6.0
#: Sub-samples per pixel side when integrating an Airy PSF over the pixels: at least this many per
#: first-ring radius, and at least 8.
_AIRY_SAMPLES_PER_RING = 6.0
#: Largest kernel half-width, pixels (keeps a mistaken metre/pixel unit from allocating gigabytes).
_MAX_KERNEL_HALF_WIDTH_PX = 200


def _tuple3x3(name: str, value: Any) -> tuple[tuple[float, float, float], ...]:
    if isinstance(value, (str, bytes, Mapping)):
        raise ParameterError(f"{name} must be a 3 x 3 table of numbers (rows R, G, B), got {shown(value)}")
    try:
        rows = tuple(value)
    except TypeError:
        raise ParameterError(f"{name} must be a 3 x 3 table of numbers (rows R, G, B), got {shown(value)}") from None
    if len(rows) != 3:
        raise ParameterError(f"{name} must have 3 rows (R, G, B filters), got {shown(value)}")
    out = tuple(finite_vector(f"{name}[{i}]", row, 3) for i, row in enumerate(rows))
    return out  # type: ignore[return-value]


@dataclass(frozen=True, kw_only=True)
class DetectorConfig:
    """The sensor behind the microlens array: colour filters, photoelectrons, noise, converter, blur.

    Validated once, on construction; :meth:`from_dict` reads a table with the same keys.

    Attributes
    ----------
    cfa_pattern : {"RGGB", "BGGR", "GRBG", "GBRG"}
        Bayer tile: the 2 x 2 top-left block, row by row (Illum ``"GRBG"``, F01 ``"BGGR"``).
    cfa_response : 3 x 3 tuple of float
        Transmittance of each filter (rows R, G, B) for each linear RGB input channel (columns),
        dimensionless, each in [0, 1], each row summing to (0, 1]; invertible (so camera RGB can be
        turned back into radiance, :meth:`radiance_from_camera_rgb`).
    quantum_efficiency : float
        Photoelectrons per photon passing the filter, in (0, 1].
    photons_per_unit_radiance : float
        Photons reaching one pixel during the exposure per unit of raw radiance, > 0 (the exposure
        scale; :attr:`electrons_per_unit_radiance` includes the quantum efficiency).
    full_well_e : float
        Charge a pixel holds before it saturates, electrons, > 0.
    read_noise_e : float
        Read noise, electrons RMS, >= 0.
    gain_dn_per_e : float
        Analogue gain at the base ISO, digital numbers per electron, > 0.
    iso, base_iso : float
        ISO setting and base ISO, > 0; the gain is ``gain_dn_per_e * iso / base_iso``.
    black_level_dn : int
        Digital number of no light (the converter's offset), >= 0 and < ``white_level_dn``.
    white_level_dn : int
        Largest digital number (the converter clips there), at most ``2**bit_depth - 1``.
    bit_depth : int
        Bits per pixel of the converter, 8 to 16 (Illum 10, F01 12).
    pixel_pitch_m : float
        Pixel pitch, metres, in (0, 1e-3].
    microlens_f_number : float
        f-number of the microlenses (MLA-sensor gap over lens pitch), in (0, 100]: sets the
        diffraction blur.
    psf : {"airy", "gaussian", "none"}
        Diffraction PSF at the microlens f-number: the Airy pattern, its Gaussian fit
        (sigma = 0.42 lambda N), or none.
    wavelengths_m : tuple of 3 float
        Wavelength at which each input channel R, G, B is diffracted, metres, each in [350e-9, 1e-6].
    extra_blur_sigma_m : float
        Standard deviation of a further Gaussian blur (microlens aberrations, defocus), metres,
        in [0, 1e-3]; 0 for none.
    crosstalk : float
        Fraction of each pixel's charge that ends in its four nearest neighbours (a quarter each),
        in [0, 0.5].
    """

    cfa_pattern: str
    cfa_response: tuple[tuple[float, float, float], ...]
    quantum_efficiency: float
    photons_per_unit_radiance: float
    full_well_e: float
    read_noise_e: float
    gain_dn_per_e: float
    iso: float
    base_iso: float
    black_level_dn: int
    white_level_dn: int
    bit_depth: int
    pixel_pitch_m: float
    microlens_f_number: float
    psf: str = "airy"
    wavelengths_m: tuple[float, float, float] = (600e-9, 530e-9, 460e-9)
    extra_blur_sigma_m: float = 0.0
    crosstalk: float = 0.0

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "cfa_pattern", one_of("cfa_pattern", self.cfa_pattern, CFA_PATTERNS))
        response = _tuple3x3("cfa_response", self.cfa_response)
        for i, row in enumerate(response):
            for j, value in enumerate(row):
                bounded_float(f"cfa_response[{i}][{j}]", value, 0.0, 1.0)
            if not 0.0 < sum(row) <= 1.0 + 1e-6:  # 1e-6: colour matrices stored in float32
                raise ParameterError(f"cfa_response[{i}] (filter {'RGB'[i]}) must sum to (0, 1], got {sum(row)!r}")
        if np.linalg.cond(np.array(response)) > 1e6:
            raise ParameterError(f"cfa_response must be invertible, got {shown(self.cfa_response)}")
        set_(self, "cfa_response", response)
        set_(
            self,
            "quantum_efficiency",
            bounded_float("quantum_efficiency", self.quantum_efficiency, 0.0, 1.0, low_open=True),
        )
        set_(
            self,
            "photons_per_unit_radiance",
            positive_float("photons_per_unit_radiance", self.photons_per_unit_radiance),
        )
        set_(self, "full_well_e", positive_float("full_well_e", self.full_well_e))
        set_(self, "read_noise_e", non_negative_float("read_noise_e", self.read_noise_e))
        set_(self, "gain_dn_per_e", positive_float("gain_dn_per_e", self.gain_dn_per_e))
        set_(self, "iso", positive_float("iso", self.iso))
        set_(self, "base_iso", positive_float("base_iso", self.base_iso))
        bits = bounded_int("bit_depth", self.bit_depth, 8, 16)
        set_(self, "bit_depth", bits)
        white = bounded_int("white_level_dn", self.white_level_dn, 1, 2**bits - 1)
        set_(self, "white_level_dn", white)
        black = bounded_int("black_level_dn", self.black_level_dn, 0, 2**bits - 1)
        if black >= white:
            raise ParameterError(
                f"black_level_dn must be below white_level_dn = {white}, got {shown(self.black_level_dn)}"
            )
        set_(self, "black_level_dn", black)
        set_(
            self,
            "pixel_pitch_m",
            bounded_float("pixel_pitch_m", self.pixel_pitch_m, 0.0, 1e-3, low_open=True, unit="m"),
        )
        set_(
            self,
            "microlens_f_number",
            bounded_float("microlens_f_number", self.microlens_f_number, 0.0, 100.0, low_open=True),
        )
        set_(self, "psf", one_of("psf", self.psf, PSF_MODELS))
        waves = finite_vector("wavelengths_m", self.wavelengths_m, 3)
        for i, w in enumerate(waves):
            bounded_float(f"wavelengths_m[{i}]", w, 350e-9, 1e-6, unit="m")
        set_(self, "wavelengths_m", waves)
        set_(
            self,
            "extra_blur_sigma_m",
            bounded_float("extra_blur_sigma_m", self.extra_blur_sigma_m, 0.0, 1e-3, unit="m"),
        )
        set_(self, "crosstalk", bounded_float("crosstalk", self.crosstalk, 0.0, 0.5))

    # ------------------------------------------------------------------ derived figures
    @property
    def gain_effective_dn_per_e(self) -> float:
        """Analogue gain at :attr:`iso`, digital numbers per electron."""
        return self.gain_dn_per_e * self.iso / self.base_iso

    @property
    def electrons_per_unit_radiance(self) -> float:
        """Photoelectrons per unit of filtered radiance, ``quantum_efficiency * photons_per_unit_radiance``."""
        return self.quantum_efficiency * self.photons_per_unit_radiance

    def airy_radius_m(self, channel: int) -> float:
        """Radius of the first dark ring of the Airy pattern of input channel 0, 1, 2 (R, G, B), metres:
        ``1.22 lambda N``."""
        return _AIRY_FIRST_ZERO / math.pi * self.wavelengths_m[channel] * self.microlens_f_number

    def psf_sigma_m(self, channel: int) -> float:
        """Standard deviation of the Gaussian PSF of input channel 0, 1, 2, metres:
        ``sqrt((0.42 lambda N)^2 + extra_blur_sigma_m^2)`` (``"gaussian"`` PSF), ``extra_blur_sigma_m``
        otherwise (the Gaussian part of the ``"airy"`` PSF, or the whole blur of ``"none"``)."""
        diffraction = _GAUSSIAN_AIRY_SIGMA * self.wavelengths_m[channel] * self.microlens_f_number
        return math.hypot(diffraction, self.extra_blur_sigma_m) if self.psf == "gaussian" else self.extra_blur_sigma_m

    def radiance_from_camera_rgb(self, camera_rgb: np.ndarray) -> np.ndarray:
        """Radiance (linear RGB, renderer units) whose mean signal is ``camera_rgb``.

        Parameters
        ----------
        camera_rgb : array_like, shape (..., 3)
            Demosaiced camera RGB as :func:`demosaic` returns it (black subtracted, 1 = white level).

        Returns
        -------
        ndarray of float64, shape (..., 3)
            The inverse of the converter gain, the electrons per unit radiance and the filters'
            response; crosstalk, blur, noise and clipping are not undone.
        """
        rgb = np.asarray(camera_rgb, dtype=np.float64)
        if rgb.ndim < 1 or rgb.shape[-1] != 3:
            raise ParameterError(f"camera_rgb must have shape (..., 3), got {rgb.shape}")
        scale = (self.white_level_dn - self.black_level_dn) / (
            self.gain_effective_dn_per_e * self.electrons_per_unit_radiance
        )
        return (rgb * scale) @ np.linalg.inv(np.array(self.cfa_response)).T

    # ------------------------------------------------------------------ tables
    def to_dict(self) -> dict:
        """Plain data (the keys of :meth:`from_dict`)."""
        out = dataclasses.asdict(self)
        out["cfa_response"] = [list(row) for row in self.cfa_response]
        out["wavelengths_m"] = list(self.wavelengths_m)
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, where: str = "sensor") -> DetectorConfig:
        """A config from a table (a scene's ``[sensor]`` table, a sidecar's record).

        Parameters
        ----------
        data : mapping
            Every field of the class by name; ``psf``, ``wavelengths_m``, ``extra_blur_sigma_m``
            and ``crosstalk`` may be left out (defaults ``"airy"``, (600, 530, 460) nm, 0, 0).
            A ``preset`` key names a :data:`DETECTOR_PRESETS` entry whose fields the other keys
            replace.
        where : str
            The table's name in messages.

        Raises
        ------
        ParameterError
            For unknown or missing keys (named with ``where``) or any invalid value (named).
        """
        fields = {f.name for f in dataclasses.fields(cls)}
        reject_unknown_keys(where, dict(data) if isinstance(data, Mapping) else data, fields | {"preset"})
        values = dict(data)
        preset = values.pop("preset", None)
        if preset is not None:
            base = detector_preset(one_of(f"{where}.preset", preset, tuple(DETECTOR_PRESETS))).to_dict()
            base.update(values)
            values = base
        defaults = {f.name for f in dataclasses.fields(cls) if f.default is not dataclasses.MISSING}
        require_keys(where, values, frozenset(fields - defaults))
        return cls(**values)


def _preset(camera: str, **values: Any) -> DetectorConfig:
    """A preset with the pixel pitch and microlens f-number of the named camera preset."""
    cam = camera_preset(camera)
    return DetectorConfig(
        pixel_pitch_m=cam.sensor.pixel_pitch_m, microlens_f_number=cam.mla.focal_length_m / cam.mla.pitch_m, **values
    )


# Inverses of the colour matrices of two real captures (camera RGB to linear sRGB, rows summing to 1):
# every entry is in [0, 1], as a filter's transmittance must be.
_ILLUM_CCM = np.array(
    [
        [2.2271547317504883, -1.055293321609497, -0.1718614399433136],
        [-0.4269128441810608, 1.7458617687225342, -0.3189488351345062],
        [-0.20497213304042816, -0.7469924688339233, 1.9519646167755127],
    ]
)
_F01_CCM = np.array(
    [
        [3.1115827560424805, -1.9393929243087769, -0.172189861536026],
        [-0.3629055917263031, 1.6408803462982178, -0.27797481417655945],
        [0.07896701246500015, -1.1558042764663696, 2.0768373012542725],
    ]
)
#: Illum: the sensor's normalised responses to white at 5100 K (r, g, b).
_ILLUM_RESPONSES = np.array([0.7761663198471069, 1.0, 0.7344976663589478])
#: F01: the inverse white-balance gains of the capture (r 1, g 1, b 1 / 1.2578125).
_F01_RESPONSES = np.array([1.0, 1.0, 1.0 / 1.2578125])


def _response(ccm: np.ndarray, responses: np.ndarray) -> tuple[tuple[float, float, float], ...]:
    m = responses[:, None] * np.linalg.inv(ccm)
    return tuple(tuple(float(v) for v in row) for row in m)  # type: ignore[return-value]


#: Illum-like electrons (assumptions, see docs/simulator.md): 4500 e- full well of a 1.4 um pixel,
#: quantum efficiency 0.5, read noise 2.5 e-, white (radiance 1) at 70 % of the full well in green.
_FULL_WELL_E = 4500.0
_QE = 0.5
_READ_NOISE_E = 2.5
_WHITE_FILL = 0.7
_CROSSTALK = 0.03


def _lytro(cfa_pattern: str, cfa_response, *, black_level_dn: int, white_level_dn: int, bit_depth: int, iso: float):
    """A Lytro camera's detector table: its metadata's pattern, levels, bit depth and base ISO, and the
    assumptions shared by both cameras (quantum efficiency, full well, read noise, exposure, crosstalk);
    the gain spans the full well from black to white."""
    return dict(
        cfa_pattern=cfa_pattern,
        cfa_response=cfa_response,
        quantum_efficiency=_QE,
        photons_per_unit_radiance=_WHITE_FILL * _FULL_WELL_E / _QE,
        full_well_e=_FULL_WELL_E,
        read_noise_e=_READ_NOISE_E,
        gain_dn_per_e=(white_level_dn - black_level_dn) / _FULL_WELL_E,
        iso=iso,
        base_iso=iso,
        black_level_dn=black_level_dn,
        white_level_dn=white_level_dn,
        bit_depth=bit_depth,
        psf="airy",
        crosstalk=_CROSSTALK,
    )


_ILLUM = _lytro(
    "GRBG", _response(_ILLUM_CCM, _ILLUM_RESPONSES), black_level_dn=64, white_level_dn=1023, bit_depth=10, iso=80.0
)

#: Named detector presets: ``"illum"`` (Lytro Illum), ``"f01"`` (first-generation Lytro) and
#: ``"tiny"`` (the test camera, with the Illum's sensor and its micro-image edges as soft in pixels).
DETECTOR_PRESETS: dict[str, DetectorConfig] = {
    "illum": _preset("illum", **_ILLUM),
    "f01": _preset(
        "f01",
        **_lytro(
            "BGGR", _response(_F01_CCM, _F01_RESPONSES), black_level_dn=168, white_level_dn=4095, bit_depth=12, iso=50.0
        ),
    ),
    # The tiny camera's 10 um pixels are 7.1 times the Illum's 1.4 um, so diffraction at its f/2
    # microlenses spans 0.13 px; the extra Gaussian (2.9 um = 0.29 px) is the Illum's diffraction
    # in Illum pixels (sigma = 0.42 * 530 nm * 1.8 = 0.40 um = 0.29 px).
    "tiny": _preset("tiny", **_ILLUM, extra_blur_sigma_m=2.9e-6),
}


def lytro_settings(config: DetectorConfig, **fields: Any) -> LytroSettings:
    """What a Lytro file records of this sensor: its colour matrix, white balance and ISO.

    The white balance makes white radiance grey: each filter's gain is the green filter's signal for
    white (the row sums of ``cfa_response``) over its own. The colour matrix maps white-balanced
    camera RGB back to the renderer's linear RGB, scaled so that each row sums to 1 (as a camera's
    matrix to sRGB does). For the ``illum`` and ``f01`` presets these are the captures' own matrices.

    Parameters
    ----------
    config : DetectorConfig
    **fields
        Any other :class:`lfrefract.formats.lytro.LytroSettings` field (``exit_pupil_offset_m``,
        ``zoom_step``, ``focus_step``, ``serial_number``).

    Returns
    -------
    LytroSettings
        ``iso`` and ``base_iso`` rounded to integers (the files hold integers).
    """
    response = np.array(config.cfa_response)
    white = response.sum(axis=1)
    gains = white[1] / white
    matrix = white[1] * np.linalg.inv(gains[:, None] * response)
    return LytroSettings(
        color_matrix=tuple(float(v) for v in matrix.ravel()),
        white_balance_gain=(float(gains[0]), float(gains[1]), float(gains[1]), float(gains[2])),
        iso=round(config.iso),
        base_iso=round(config.base_iso),
        **fields,
    )


def detector_preset(name: str) -> DetectorConfig:
    """The named detector preset: ``"illum"``, ``"f01"`` or ``"tiny"``."""
    return DETECTOR_PRESETS[one_of("detector preset", name, tuple(DETECTOR_PRESETS))]


# ---------------------------------------------------------------------------------------- blur
def _gaussian_pixel_weights(sigma_px: float, half: int) -> np.ndarray:
    """Share of a 1-D Gaussian centred on pixel 0 that falls in pixels -half..half (unnormalised)."""
    edges = (np.arange(-half, half + 2) - 0.5) / (sigma_px * math.sqrt(2.0))
    return np.diff(special.erf(edges)) / 2.0


def pixel_psf_kernel(config: DetectorConfig, channel: int) -> np.ndarray:
    """The optical blur of one input channel as a discrete kernel: the PSF integrated over each pixel.

    Parameters
    ----------
    config : DetectorConfig
    channel : {0, 1, 2}
        Input channel R, G or B (its wavelength sets the diffraction).

    Returns
    -------
    ndarray of float64, shape (2 k + 1, 2 k + 1)
        Entry ``[k + dv, k + du]`` is the share of the light of a point at the centre of a pixel
        that falls into the pixel ``(du, dv)`` away; the entries sum to 1. ``[[1.0]]`` without blur.
        Gaussian kernels reach 6 sigma, Airy kernels 25 first-ring radii (and 6 sigma of the extra
        Gaussian), renormalised.
    """
    bounded_int("channel", channel, 0, 2)
    pitch = config.pixel_pitch_m
    sigma_px = config.psf_sigma_m(channel) / pitch
    if config.psf != "airy":
        if sigma_px == 0.0:
            return np.ones((1, 1))
        half = min(_MAX_KERNEL_HALF_WIDTH_PX, max(1, math.ceil(_GAUSSIAN_REACH_SIGMAS * sigma_px)))
        g = _gaussian_pixel_weights(sigma_px, half)
        kernel = np.outer(g, g)
        return kernel / kernel.sum()
    ring_px = config.airy_radius_m(channel) / pitch
    reach = max(_AIRY_REACH_RINGS * ring_px, _GAUSSIAN_REACH_SIGMAS * sigma_px, 1.0)
    half = min(_MAX_KERNEL_HALF_WIDTH_PX, math.ceil(reach))
    sub = max(8, math.ceil(_AIRY_SAMPLES_PER_RING / ring_px))
    if sigma_px > 0.0:  # the fine grid must also resolve the Gaussian
        sub = max(sub, math.ceil(4.0 / sigma_px))
    sub = min(sub, max(8, 4096 // (2 * half + 1)))  # at most 4096 fine samples per side
    n = (2 * half + 1) * sub
    fine = (np.arange(n) + 0.5) / sub - (half + 0.5)  # sub-sample centres, pixels from the centre
    r = np.hypot(fine[:, None], fine[None, :])
    v = math.pi * r / (ring_px * math.pi / _AIRY_FIRST_ZERO)  # v = pi r / (lambda N)
    safe = np.where(v > 0.0, v, 1.0)
    airy = np.where(v > 0.0, (2.0 * special.j1(safe) / safe) ** 2, 1.0)
    if sigma_px > 0.0:
        g = _gaussian_pixel_weights(sigma_px * sub, min(n, math.ceil(_GAUSSIAN_REACH_SIGMAS * sigma_px * sub)))
        airy = signal.fftconvolve(airy, np.outer(g, g), mode="same")
    kernel = airy.reshape(2 * half + 1, sub, 2 * half + 1, sub).sum(axis=(1, 3))
    return kernel / kernel.sum()


def _blurred(channel_image: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """``channel_image`` convolved with ``kernel``, the image mirrored at its border."""
    if kernel.shape == (1, 1):
        return channel_image.copy()
    k = kernel.shape[0] // 2
    if np.allclose(kernel, np.outer(kernel[:, k], kernel[k, :]) / kernel[k, k], rtol=1e-9, atol=1e-15):
        col = kernel.sum(axis=1)
        row = kernel.sum(axis=0)
        out = ndimage.convolve1d(channel_image, col, axis=0, mode="reflect")
        return ndimage.convolve1d(out, row, axis=1, mode="reflect")
    # Not separable (the Airy pattern): one FFT product over the mirrored image. A circular convolution
    # of at least the padded size leaves the valid part (offsets 2k onwards) free of wrap-around.
    padded = np.pad(channel_image, k, mode="symmetric")
    size = tuple(sp_fft.next_fast_len(n, real=True) for n in padded.shape)
    product = sp_fft.rfft2(padded, size, workers=-1)
    product *= sp_fft.rfft2(kernel, size, workers=-1)
    del padded
    full = sp_fft.irfft2(product, size, workers=-1)
    h, w = channel_image.shape
    return full[2 * k : 2 * k + h, 2 * k : 2 * k + w]


# ---------------------------------------------------------------------------------------- the chain
def _radiance(name: str, radiance_rgb: Any) -> np.ndarray:
    image = np.asarray(radiance_rgb)
    if not np.issubdtype(image.dtype, np.floating):  # float32 (as raw.exr holds) stays float32
        image = image.astype(np.float64)
    if image.ndim != 3 or image.shape[2] != 3 or image.shape[0] < 2 or image.shape[1] < 2:
        raise ParameterError(f"{name} must have shape (H, W, 3) with H, W >= 2, got {image.shape}")
    if not np.all(np.isfinite(image)):
        raise ParameterError(f"{name} must be finite, got {int(np.sum(~np.isfinite(image)))} non-finite values")
    if image.min() < 0.0:
        raise ParameterError(f"{name} must be non-negative, got a minimum of {float(image.min())!r}")
    return image


def expected_electrons(radiance_rgb: np.ndarray, config: DetectorConfig) -> np.ndarray:
    """Mean photoelectrons of every pixel: blur, colour filters, quantum efficiency, crosstalk.

    Parameters
    ----------
    radiance_rgb : array_like, shape (H, W, 3)
        Per-pixel linear RGB radiance (``raw.exr``), finite and >= 0.
    config : DetectorConfig

    Returns
    -------
    ndarray of float64, shape (H, W)
        The Poisson mean of each pixel's charge, electrons, before the full well clips it.
    """
    image = _radiance("radiance_rgb", radiance_rgb)
    if not isinstance(config, DetectorConfig):
        raise ParameterError(f"config must be a DetectorConfig, got {shown(config)}")
    h, w, _ = image.shape
    channels = cfa_channels(config.cfa_pattern, (h, w))
    response = np.array(config.cfa_response)
    filtered = np.zeros((h, w))
    for c in range(3):  # input channels: each its own wavelength's blur
        blurred = _blurred(image[:, :, c].astype(np.float64), pixel_psf_kernel(config, c))
        filtered += response[channels, c] * blurred
    electrons = config.electrons_per_unit_radiance * filtered
    if config.crosstalk > 0.0:
        q = config.crosstalk / 4.0
        cross = np.array([[0.0, q, 0.0], [q, 1.0 - config.crosstalk, q], [0.0, q, 0.0]])
        electrons = ndimage.convolve(electrons, cross, mode="reflect")
    return np.maximum(electrons, 0.0)


def _digitised(mean_e: np.ndarray, config: DetectorConfig, rng: np.random.Generator) -> np.ndarray:
    """One exposure of mean charge ``mean_e``: Poisson, full well, read noise, gain, black, round, clip (float64 DN)."""
    # Charge far beyond the full well saturates whatever the draw: cap the mean 10 sigma above it
    # (a draw below the well is then as unlikely as 1e-23), so that numpy's Poisson, which refuses
    # means above about 1e19, takes any finite radiance.
    cap = config.full_well_e + 10.0 * np.sqrt(config.full_well_e) + 10.0
    electrons = np.minimum(rng.poisson(np.minimum(mean_e, cap)).astype(np.float64), config.full_well_e)
    if config.read_noise_e > 0.0:
        electrons += rng.normal(0.0, config.read_noise_e, size=electrons.shape)
    dn = np.rint(electrons * config.gain_effective_dn_per_e + config.black_level_dn)
    return np.clip(dn, 0.0, float(config.white_level_dn))


def _mosaic(counts: np.ndarray, config: DetectorConfig) -> RawMosaic:
    return RawMosaic(
        counts=counts.astype(np.uint16),
        cfa_pattern=config.cfa_pattern,
        black_level_dn=config.black_level_dn,
        white_level_dn=config.white_level_dn,
        bit_depth=config.bit_depth,
    )


def simulate_mosaic(radiance_rgb: np.ndarray, config: DetectorConfig, *, seed: int) -> RawMosaic:
    """One exposure of the sensor: the Bayer mosaic of digital numbers for a rendered raw image.

    Parameters
    ----------
    radiance_rgb : array_like, shape (H, W, 3)
        Per-pixel linear RGB radiance (``raw.exr``), finite and >= 0.
    config : DetectorConfig
    seed : int
        Seed of the noise, in [0, 2**31) (:func:`simulator.seeds.seed`); the same seed gives the
        same mosaic, bit for bit.

    Returns
    -------
    RawMosaic
        ``counts`` of shape (H, W), uint16.
    """
    rng = np.random.default_rng(np.random.SeedSequence(checked_seed("seed", seed)))
    return _mosaic(_digitised(expected_electrons(radiance_rgb, config), config, rng), config)


def white_frames(radiance_rgb: np.ndarray, config: DetectorConfig, *, frames: int, seed: int) -> RawMosaic:
    """A white image as a camera ships it: the mean of ``frames`` exposures, rounded to digital numbers.

    Parameters
    ----------
    radiance_rgb : array_like, shape (H, W, 3)
        The rendered white image (radiance).
    config : DetectorConfig
    frames : int
        Number of exposures averaged, 1 to 4096.
    seed : int
        Seed in [0, 2**31); frame ``k`` draws its noise from ``SeedSequence([seed, k])``.

    Returns
    -------
    RawMosaic
        The per-pixel mean of the frames' digital numbers, rounded to the nearest integer (the
        shot and read noise shrink by ``sqrt(frames)``; each frame is clipped and quantised).
    """
    base = checked_seed("seed", seed)
    count = bounded_int("frames", frames, 1, 4096)
    mean_e = expected_electrons(radiance_rgb, config)
    total = np.zeros_like(mean_e)
    for k in range(count):  # frames, each one vectorised
        total += _digitised(mean_e, config, np.random.default_rng(np.random.SeedSequence([base, k])))
    return _mosaic(np.rint(total / count), config)


# ---------------------------------------------------------------------------------------- measuring
def radial_profile(
    image: np.ndarray, centres_px: np.ndarray, *, max_radius_px: float, bin_px: float = 0.1
) -> tuple[np.ndarray, np.ndarray]:
    """Mean value against distance from the nearest micro-image centre (the micro-image profile).

    Parameters
    ----------
    image : array_like, shape (H, W)
        A white image (any linear scale); NaN pixels are left out (e.g. the pixels of the other
        colours of a mosaic).
    centres_px : array_like, shape (N, 2)
        Micro-image centres ``(u, v)``, pixels. Only centres at least ``max_radius_px + 1`` from the
        border count, and each pixel counts for its nearest centre.
    max_radius_px : float
        Largest distance binned, pixels (> 0).
    bin_px : float
        Bin width, pixels (> 0).

    Returns
    -------
    radii_px : ndarray, shape (B,)
        Bin centres, pixels.
    profile : ndarray, shape (B,)
        Mean image value of the pixels in each bin (NaN for an empty bin).
    """
    from scipy.spatial import cKDTree

    img = np.asarray(image, dtype=np.float64)
    if img.ndim != 2:
        raise ParameterError(f"image must have shape (H, W), got {img.shape}")
    centres = np.asarray(centres_px, dtype=np.float64).reshape(-1, 2)
    reach = positive_float("max_radius_px", max_radius_px)
    width = positive_float("bin_px", bin_px)
    h, w = img.shape
    inside = (
        (centres[:, 0] >= reach + 1)
        & (centres[:, 0] <= w - 2 - reach)
        & (centres[:, 1] >= reach + 1)
        & (centres[:, 1] <= h - 2 - reach)
    )
    if not np.any(inside):
        raise ParameterError(f"no micro-image centre lies {reach + 1:g} px inside the {w} x {h} px image")
    v, u = np.mgrid[0:h, 0:w]
    pixels = np.column_stack([u.ravel(), v.ravel()]).astype(np.float64)
    distance, nearest = cKDTree(centres).query(pixels)
    keep = inside[nearest] & (distance < reach) & np.isfinite(img.ravel())
    bins = np.floor(distance[keep] / width).astype(np.int64)
    n_bins = math.ceil(reach / width)
    sums = np.bincount(bins, weights=img.ravel()[keep], minlength=n_bins)[:n_bins]
    counts = np.bincount(bins, minlength=n_bins)[:n_bins]
    with np.errstate(invalid="ignore", divide="ignore"):
        profile = np.where(counts > 0, sums / np.maximum(counts, 1), np.nan)
    return (np.arange(n_bins) + 0.5) * width, profile


def edge_width_px(
    radii_px: np.ndarray, profile: np.ndarray, *, plateau_px: float, low: float = 0.1, high: float = 0.9
) -> tuple[float, float, float]:
    """Width of a micro-image's edge: where its profile falls from ``high`` to ``low`` of its plateau.

    Parameters
    ----------
    radii_px, profile : array_like, shape (B,)
        A radial profile (:func:`radial_profile`), radii increasing.
    plateau_px : float
        The plateau is the mean profile within this radius, pixels.
    low, high : float
        Fractions of the plateau, ``0 < low < high < 1``.

    Returns
    -------
    width_px : float
        ``r_low - r_high``, pixels.
    r_high_px, r_low_px : float
        First radii (linearly interpolated) where the profile falls below ``high`` and ``low`` of
        the plateau.
    """
    r = np.asarray(radii_px, dtype=np.float64)
    p = np.asarray(profile, dtype=np.float64)
    ok = np.isfinite(p)
    r, p = r[ok], p[ok]
    positive_float("plateau_px", plateau_px)
    if not 0.0 < low < high < 1.0:
        raise ParameterError(f"low and high must satisfy 0 < low < high < 1, got {low!r}, {high!r}")
    plateau = float(np.mean(p[r < plateau_px])) if np.any(r < plateau_px) else math.nan
    if not plateau > 0.0:
        raise ParameterError(f"the profile has no positive plateau within {plateau_px:g} px")

    def crossing(fraction: float) -> float:
        below = np.flatnonzero(p < fraction * plateau)
        if len(below) == 0 or below[0] == 0:
            raise ParameterError(f"the profile never falls from above to below {fraction:g} of its plateau")
        i = below[0]
        t = (p[i - 1] - fraction * plateau) / (p[i - 1] - p[i])
        return float(r[i - 1] + t * (r[i] - r[i - 1]))

    r_high, r_low = crossing(high), crossing(low)
    return r_low - r_high, r_high, r_low
