"""The camera as the core sees it: a light-field camera, the model of its rays and that model's uncertainty.

A :class:`CameraModel` is what every command and function of the core takes where it needs a
camera's rays: the thin-lens geometry (:class:`~lfrefract.optics.camera.LightFieldCamera`), the
calibrated correction of its rays (:mod:`lfrefract.optics.ray_correction`: the radial
:class:`~lfrefract.optics.ray_correction.RayCorrection`, the generic
:class:`~lfrefract.optics.ray_correction.PolynomialCorrection`, a known main lens traced,
:class:`~lfrefract.optics.real_lens.TracedLens`, or None for the thin lens itself) and
what a camera calibration (``lfrefract calibrate camera``) says of that correction's uncertainty.
:func:`lfrefract.formats.capture.camera_model_from_option` reads one from a ``--camera`` value (a
preset, a camera file, a render's ``meta.json`` or a camera calibration), reading the file once.

Frames and units: camera frame (OpenCV axes), metres; the correction's parameters as its ``vector()``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from lfrefract.errors import ParameterError
from lfrefract.optics.camera import CapturedRays, LightFieldCamera
from lfrefract.optics.ray_correction import (
    Correction,
    CorrectionEstimate,
    PolynomialCorrection,
    RayCorrection,
    moved,
)
from lfrefract.optics.real_lens import TracedLens
from lfrefract.validate import shown

__all__ = ["BOARD_COLOURS", "RAY_MODELS", "CameraModel", "as_camera_model"]

#: The names of the ray models (:attr:`CameraModel.ray_model`): the thin lens, the radial correction,
#: the polynomial one and a known prescription traced (a render's truth, not calibrated).
RAY_MODELS = ("thin-lens", "radial", "polynomial", "traced")
#: How a Lytro board capture is read for the light-field corners: its devignetted Bayer mosaic as one
#: grey light field, or its demosaiced image (:attr:`CameraModel.board_colour`).
BOARD_COLOURS = ("cfa", "demosaic")


@dataclass(frozen=True, eq=False, kw_only=True)
class CameraModel:
    """A light-field camera with the model of its rays and that model's uncertainty.

    Attributes
    ----------
    camera : LightFieldCamera
        The thin-lens geometry (main lens, MLA, sensor) the rays are indexed by.
    correction : RayCorrection, PolynomialCorrection, TracedLens or None
        How the camera's rays depart from the thin lens's; None (the default): the thin lens. A
        :class:`~lfrefract.optics.real_lens.TracedLens` must be of :attr:`camera`.
    covariance : ndarray, shape (5, 5), or None
        Covariance of the radial correction's parameters
        (:data:`~lfrefract.optics.ray_correction.PARAMETERS`; the drift's entries in metres): what a
        joint refinement with the port takes as the in-air calibration's say (:meth:`estimate`).
        None where it is not known (the thin lens, the polynomial model, a calibration written
        before it was recorded). Only a :class:`RayCorrection` has one.
    spread : ndarray, shape (k, n)
        The correction's uncertainty as ``k`` directions of its parameter vector (``n`` numbers,
        ``correction.vector()``): its covariance is about ``spread.T @ spread``. A port calibrated on
        this model propagates it. Default: none, shape (0, n) (n = 0 for the thin lens).
    source : str or None
        Where the model was read from (a preset name or a file), for messages; None if made in code.
    main_lens : str or None
        The real (multi-element) main lens the source file says the camera was taken through (a
        render's ``meta.json`` records it), by name; None for the thin lens or where none is
        recorded. The core does not trace it: a capture through a real lens needs a calibrated
        correction (:func:`lfrefract.formats.capture.check_lens_modelled`).
    board_colour : {"cfa", "demosaic"} or None
        How the calibration's in-air board captures (Lytro files) were read: their grey mosaic or their
        demosaiced image (``lfrefract calibrate camera --colour``). The light-field corners differ
        between the two readings by about 1 % of their parallax on a real lens, which a port fitted
        on this model absorbs: underwater boards must be read alike. None where not recorded (the
        thin lens, linear raw boards, a calibration written before it was recorded).

    Raises
    ------
    ParameterError
        If a field has the wrong type, ``covariance`` is given without a radial correction or is not
        a finite, symmetric, positive definite 5 x 5 matrix, or ``spread`` is not rows of the
        correction's parameter count of finite numbers (each message names the field and the value).

    Examples
    --------
    >>> from lfrefract.optics.presets import camera_preset
    >>> from lfrefract.optics.ray_correction import RayCorrection
    >>> thin = CameraModel(camera=camera_preset("tiny"))
    >>> thin.ray_model, thin.spread.shape
    ('thin-lens', (0, 0))
    >>> calibrated = thin.with_correction(RayCorrection(k1=0.02))
    >>> calibrated.ray_model, calibrated.spread.shape
    ('radial', (0, 5))
    """

    camera: LightFieldCamera
    correction: Correction | None = None
    covariance: np.ndarray | None = None
    spread: np.ndarray | None = None
    source: str | None = None
    main_lens: str | None = None
    board_colour: str | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.camera, LightFieldCamera):
            raise ParameterError(f"camera must be a LightFieldCamera, got {type(self.camera).__name__}")
        correction = self.correction
        if correction is not None and not isinstance(correction, (RayCorrection, PolynomialCorrection, TracedLens)):
            raise ParameterError(
                "correction must be a RayCorrection, a PolynomialCorrection, a TracedLens or None, "
                f"got {shown(correction)}"
            )
        if isinstance(correction, TracedLens) and correction.camera != self.camera:
            raise ParameterError(
                f"correction maps the thin-lens rays of camera {correction.camera.name!r} to lens "
                f"{correction.real.lens.name!r}'s, not those of this model's camera {self.camera.name!r} "
                "(TracedLens.on_camera)"
            )
        for name in ("source", "main_lens"):
            value = getattr(self, name)
            if value is not None and not isinstance(value, str):
                raise ParameterError(f"{name} must be a string or None, got {shown(value)}")
        if self.board_colour not in (None, *BOARD_COLOURS):
            raise ParameterError(f"board_colour must be one of {BOARD_COLOURS} or None, got {shown(self.board_colour)}")
        if self.covariance is not None:
            if not isinstance(correction, RayCorrection):
                raise ParameterError(
                    f"covariance is that of the radial model's parameters, but the ray model is {self.ray_model}"
                )
            # CorrectionEstimate checks it: finite, 5 x 5, symmetric, positive definite (a read-only copy).
            estimate = CorrectionEstimate(correction=correction, covariance=self.covariance)
            object.__setattr__(self, "covariance", estimate.covariance)
        n = 0 if correction is None else correction.vector().size
        given = np.zeros((0, n)) if self.spread is None else self.spread
        try:
            spread = np.array(given, dtype=np.float64)
        except (TypeError, ValueError):
            raise ParameterError(f"spread must be rows of {n} numbers, got {shown(given)}") from None
        if spread.ndim != 2 or spread.shape[1] != n or not np.all(np.isfinite(spread)):
            raise ParameterError(
                f"spread must be rows of {n} finite numbers (the {self.ray_model} model's parameters), "
                f"got shape {spread.shape}"
            )
        spread.setflags(write=False)
        object.__setattr__(self, "spread", spread)

    @property
    def ray_model(self) -> str:
        """Which model the rays follow: ``"thin-lens"``, ``"radial"``, ``"polynomial"`` or ``"traced"``
        (:data:`RAY_MODELS`)."""
        if self.correction is None:
            return "thin-lens"
        if isinstance(self.correction, TracedLens):
            return "traced"
        return "radial" if isinstance(self.correction, RayCorrection) else "polynomial"

    @property
    def described_camera(self) -> LightFieldCamera:
        """The camera geometry the model's source describes: :attr:`camera`, but for a traced lens the
        camera the lens was rendered on (:attr:`camera` is then its micro-image lattice,
        :attr:`lfrefract.optics.real_lens.RealLensCamera.lattice_camera`): what a render or a camera
        option takes.

        Examples
        --------
        >>> from lfrefract.optics.presets import camera_preset
        >>> CameraModel(camera=camera_preset("tiny")).described_camera.name
        'tiny'
        """
        return self.correction.real.camera if isinstance(self.correction, TracedLens) else self.camera

    @property
    def named(self) -> str:
        """How messages name the model: ``"the camera model of 'SOURCE'"`` (:attr:`source`), else
        ``"the camera model"``."""
        return "the camera model" if self.source is None else f"the camera model of {self.source!r}"

    def estimate(self) -> CorrectionEstimate:
        """The radial correction with its covariance: what a joint refinement with the port refines.

        Raises
        ------
        ParameterError
            If the model is not a calibrated radial one with its covariance (the thin lens, the
            polynomial model, or a calibration written before the covariance was recorded); the
            message names the model's source and says what to do.

        Examples
        --------
        >>> import numpy as np
        >>> from lfrefract.optics.presets import camera_preset
        >>> from lfrefract.optics.ray_correction import RayCorrection
        >>> model = CameraModel(camera=camera_preset("tiny"), correction=RayCorrection(), covariance=np.eye(5) * 1e-6)
        >>> model.estimate().std.round(6).tolist()
        [0.001, 0.001, 0.001, 0.001, 0.001]
        """
        if self.correction is None:
            raise ParameterError(
                f"{self.named} is not a camera calibration (lfrefract calibrate camera output): "
                "a refinement needs the calibrated ray model and its covariance"
            )
        if not isinstance(self.correction, RayCorrection):
            raise ParameterError(
                f"{self.named} holds the {self.correction.name} ray model: a joint refinement with the port "
                "takes the radial model only (lfrefract calibrate camera --ray-model radial); the polynomial model "
                "is used as calibrated"
            )
        if self.covariance is None:
            raise ParameterError(
                f"{self.named} has no correction_covariance (written by an earlier lfrefract): run "
                "lfrefract calibrate camera again to refine it"
            )
        return CorrectionEstimate(correction=self.correction, covariance=self.covariance)

    def with_correction(
        self, correction: Correction | None, *, covariance: np.ndarray | None = None, spread: np.ndarray | None = None
    ) -> CameraModel:
        """This camera with another ray model (and its uncertainty: none unless given); the source kept.

        Examples
        --------
        >>> from lfrefract.optics.presets import camera_preset
        >>> from lfrefract.optics.ray_correction import RayCorrection
        >>> CameraModel(camera=camera_preset("tiny")).with_correction(RayCorrection(k1=0.01)).correction.k1
        0.01
        """
        return dataclasses.replace(self, correction=correction, covariance=covariance, spread=spread)

    def with_camera(self, camera: LightFieldCamera) -> CameraModel:
        """The same ray model on another camera geometry (an MLA calibration's, a capture's own); a
        traced lens is traced for that camera (:meth:`TracedLens.on_camera`).

        Examples
        --------
        >>> import dataclasses
        >>> from lfrefract.optics.presets import camera_preset
        >>> tiny = camera_preset("tiny")
        >>> CameraModel(camera=tiny).with_camera(dataclasses.replace(tiny, name="mine")).camera.name
        'mine'
        """
        correction = self.correction
        if isinstance(correction, TracedLens):
            correction = correction.on_camera(camera)
        return dataclasses.replace(self, camera=camera, correction=correction)

    def spread_corrections(self) -> tuple[Correction, ...]:
        """The correction moved along each direction of :attr:`spread` (``k`` models; none for the thin
        lens or a model without a spread): how a port calibration propagates the model's uncertainty.

        Examples
        --------
        >>> import numpy as np
        >>> from lfrefract.optics.presets import camera_preset
        >>> from lfrefract.optics.ray_correction import RayCorrection
        >>> model = CameraModel(camera=camera_preset("tiny"), correction=RayCorrection(), spread=[[0, 0, 0.01, 0, 0]])
        >>> [c.k1 for c in model.spread_corrections()]
        [0.01]
        """
        if self.correction is None:
            return ()
        return tuple(moved(self.correction, row) for row in self.spread)  # type: ignore[union-attr]

    def captured_rays(self, uv: np.ndarray | None = None) -> CapturedRays:
        """The ray of each raw pixel under this model (``uv`` (N, 2) or every pixel, as
        :meth:`LightFieldCamera.captured_rays`; corrected unless the model is the thin lens).

        Examples
        --------
        >>> from lfrefract.optics.presets import camera_preset
        >>> CameraModel(camera=camera_preset("tiny")).captured_rays([[10.0, 12.0]]).origins_cam.shape
        (1, 3)
        """
        rays = self.camera.captured_rays(uv)
        return rays if self.correction is None else self.correction.corrected(rays)


def as_camera_model(camera: LightFieldCamera | CameraModel) -> CameraModel:
    """``camera`` as a :class:`CameraModel`: a bare :class:`LightFieldCamera` is its thin-lens model.

    Raises
    ------
    ParameterError
        If ``camera`` is neither.

    Examples
    --------
    >>> from lfrefract.optics.presets import camera_preset
    >>> as_camera_model(camera_preset("tiny")).ray_model
    'thin-lens'
    """
    if isinstance(camera, CameraModel):
        return camera
    if isinstance(camera, LightFieldCamera):
        return CameraModel(camera=camera)
    raise ParameterError(f"camera must be a LightFieldCamera or a CameraModel, got {type(camera).__name__}")
