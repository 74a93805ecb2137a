"""Mitsuba sensor plugins: the plenoptic camera and the ideal OpenCV pinhole, in Dr.Jit.

Both generate rays in the camera frame of :mod:`lfrefract` (OpenCV: +x right, +y down, +z
forward) and map them to the world with the camera pose (``to_world``). Mitsuba's film is
addressed in continuous coordinates with pixel centres at half-integers; OpenCV pixel
``(u, v)`` is film position ``(u + 0.5, v + 0.5)``. This is the single place that conversion
happens. Under a crop window the film sample is mapped back to full-film coordinates.

The plenoptic sensor is an independent Dr.Jit implementation of the physical model whose numpy
twin is :meth:`lfrefract.LightFieldCamera.rays_through_lenses`; the tests compare the two.
"""

from __future__ import annotations

import json
import math
from types import ModuleType

import numpy as np

from lfrefract import FlatPort, LightFieldCamera, MicrolensArray, PinholeCamera, Pose, SensorGeometry
from lfrefract.optics.lens import LensPrescription
from lfrefract.optics.real_lens import RealLensCamera

__all__ = ["pinhole_sensor_dict", "plenoptic_sensor_dict", "register"]

PLENOPTIC = "lfsim_plenoptic"
_CAMERA_PROPS = (
    "focal_length_m",
    "lens_to_mla_m",
    "f_number",
    "mla_pitch_m",
    "mla_focal_length_m",
    "mla_rotation_rad",
    "mla_offset_x_m",
    "mla_offset_y_m",
    "pixel_pitch_m",
)
_PORT_PROPS = ("distance_m", "thickness_m", "tilt_x_rad", "tilt_y_rad", "n_air", "n_glass", "n_water")
PINHOLE = "lfsim_pinhole"


def _film(width: int, height: int, crop: tuple[int, int, int, int] | None) -> dict:
    film = {
        "type": "hdrfilm",
        "width": width,
        "height": height,
        "pixel_format": "rgb",
        "component_format": "float32",
        "rfilter": {"type": "box"},
    }
    if crop is not None:
        x, y, w, h = crop
        film.update(crop_offset_x=x, crop_offset_y=y, crop_width=w, crop_height=h)
    return film


def _to_world(mi: ModuleType, pose: Pose):
    return mi.ScalarTransform4f(pose.matrix.tolist())


def plenoptic_sensor_dict(
    mi: ModuleType,
    camera: LightFieldCamera,
    pose: Pose,
    *,
    spp: int,
    crop: tuple[int, int, int, int] | None = None,
    port: FlatPort | None = None,
    medium: dict | None = None,
    lens: LensPrescription | None = None,
) -> dict:
    """Mitsuba dict of the plenoptic sensor for ``camera`` at ``pose``.

    ``crop`` is ``(x, y, width, height)`` in pixels for band rendering. With ``port`` the sensor
    refracts its rays through the port itself (the ``sensor`` port model): they leave from the
    port's water face, weighted by the Fresnel transmittance and ``(n_air / n_water)^2``, and the
    scene must not contain the glass too. ``medium`` (a Mitsuba medium dict,
    :func:`simulator.scene.water_medium`) is the medium the sensor's rays start in: the turbid
    water for the ``sensor`` port model or a camera without a port, None for a camera in air
    behind port geometry. ``lens`` is a real main lens with the camera's first-order data
    (:class:`lfrefract.optics.real_lens.RealLensCamera` checks the pair), traced exactly in place of
    the thin lens; None keeps the thin lens.
    """
    mla = camera.mla
    extra = {} if medium is None else {"medium": medium}
    if lens is not None:
        RealLensCamera(camera=camera, lens=lens)  # refuse a lens that does not fit before Mitsuba sees it
        extra["lens_json"] = json.dumps(lens.to_dict(), allow_nan=False)
    if port is not None:
        extra.update({f"port_{key}": float(getattr(port, key)) for key in _PORT_PROPS})
    return {
        **extra,
        "type": PLENOPTIC,
        "camera_name": camera.name,
        "to_world": _to_world(mi, pose),
        "focal_length_m": camera.focal_length_m,
        "lens_to_mla_m": camera.lens_to_mla_m,
        "f_number": camera.f_number,
        "grid": mla.grid,
        "mla_pitch_m": mla.pitch_m,
        "mla_focal_length_m": mla.focal_length_m,
        "mla_rotation_rad": mla.rotation_rad,
        "mla_offset_x_m": mla.offset_m[0],
        "mla_offset_y_m": mla.offset_m[1],
        "pixel_pitch_m": camera.sensor.pixel_pitch_m,
        "film": _film(camera.sensor.width_px, camera.sensor.height_px, crop),
        "sampler": {"type": "independent", "sample_count": int(spp)},
    }


def pinhole_sensor_dict(
    mi: ModuleType,
    pinhole: PinholeCamera,
    pose: Pose,
    *,
    spp: int,
    crop: tuple[int, int, int, int] | None = None,
    medium: dict | None = None,
) -> dict:
    """Mitsuba dict of the ideal pinhole sensor with OpenCV intrinsics.

    ``medium`` (a Mitsuba medium dict, :func:`simulator.scene.water_medium`) is the medium its
    rays start in: the pinhole stands in the water, so turbid water attenuates the whole way from
    the main-lens centre.
    """
    extra = {} if medium is None else {"medium": medium}
    return {
        **extra,
        "type": PINHOLE,
        "to_world": _to_world(mi, pose),
        "focal_px": pinhole.focal_px,
        "cx_px": pinhole.cx_px,
        "cy_px": pinhole.cy_px,
        "film": _film(pinhole.width_px, pinhole.height_px, crop),
        "sampler": {"type": "independent", "sample_count": int(spp)},
    }


def register(mi: ModuleType) -> None:
    """Define and register both sensors for the current Mitsuba variant."""
    import drjit as dr

    class _CameraSensor(mi.Sensor):
        """Shared parts: world transform, crop-aware film coordinates, ray differentials."""

        def __init__(self, props):
            mi.Sensor.__init__(self, props)
            matrix = np.array(props["to_world"].matrix, dtype=np.float64)
            self._rot = mi.ScalarMatrix3f(matrix[:3, :3].tolist())
            self._pos = mi.ScalarPoint3f(matrix[:3, 3].tolist())

        def _film_pixels(self, position_sample):
            """OpenCV pixel coordinates (u, v) of a film sample, crop-aware."""
            film = self.film()
            size = mi.ScalarVector2f(film.size())
            offset = mi.ScalarVector2f(film.crop_offset())
            crop = mi.ScalarVector2f(film.crop_size())
            p = offset + position_sample * crop
            return p.x - 0.5, p.y - 0.5, size

        def _ray(self, time, origin_cam, direction_cam, maxt=None):
            ray = mi.Ray3f(self._rot @ origin_cam + self._pos, self._rot @ direction_cam, time, [])
            if maxt is not None:
                ray.maxt = maxt
            return ray

        def sample_ray_differential(self, time, wavelength_sample, position_sample, aperture_sample, active=True):
            ray, weight = self.sample_ray(time, wavelength_sample, position_sample, aperture_sample, active)
            return mi.RayDifferential3f(ray), weight

    class PlenopticSensor(_CameraSensor):
        """Raw lenslet image of a plenoptic 1.0 camera (see :mod:`lfrefract.optics.camera`).

        Each sample picks a point in the pixel (film sample) and a point on the aperture of the
        microlens whose micro-image holds it (aperture sample, uniform over the lattice cell).
        The path is bent by the thin microlens and the thin main lens, and, with a port, refracted
        through the port's faces. Paths that miss the main-lens aperture or the port, or are
        totally internally reflected, get zero weight and a zero-length ray, so they cost no
        traversal. Otherwise the weight is 1 (times the port's transmittance): pixel values are
        mean radiance, like Mitsuba's cameras.

        The parameters are validated by building the lfrefract types from the properties, but
        every quantity used per sample (micro-image scale, aperture radius, lattice, port normal,
        faces, radiance scale) is derived here again from the raw properties, so that this is an
        independent implementation of the model that the tests compare with numpy's.
        """

        def __init__(self, props):
            _CameraSensor.__init__(self, props)
            width, height = self.film().size()
            raw = {key: float(props[key]) for key in _CAMERA_PROPS}
            grid = str(props["grid"])
            self.camera = LightFieldCamera(
                name=str(props["camera_name"]),
                focal_length_m=raw["focal_length_m"],
                lens_to_mla_m=raw["lens_to_mla_m"],
                f_number=raw["f_number"],
                mla=MicrolensArray(
                    grid=grid,
                    pitch_m=raw["mla_pitch_m"],
                    focal_length_m=raw["mla_focal_length_m"],
                    rotation_rad=raw["mla_rotation_rad"],
                    offset_m=(raw["mla_offset_x_m"], raw["mla_offset_y_m"]),
                ),
                sensor=SensorGeometry(width_px=int(width), height_px=int(height), pixel_pitch_m=raw["pixel_pitch_m"]),
            )
            self.m_needs_sample_3 = True
            self._f = raw["focal_length_m"]
            self._f_prime = raw["lens_to_mla_m"]
            self._f_mla = raw["mla_focal_length_m"]
            self._pitch_px_m = raw["pixel_pitch_m"]
            self._scale = (self._f_prime + self._f_mla) / self._f_prime
            self._aperture_r2 = (self._f / (2.0 * raw["f_number"])) ** 2
            self._offset = (raw["mla_offset_x_m"], raw["mla_offset_y_m"])
            c, s = math.cos(raw["mla_rotation_rad"]), math.sin(raw["mla_rotation_rad"])
            p = raw["mla_pitch_m"]
            a2 = (0.5 * p, 0.5 * math.sqrt(3.0) * p) if grid == "hex" else (0.0, p)
            # Lattice vectors a1 = R (p, 0), a2 = R a2_unrotated, and the inverse of [a1 a2].
            self._a1 = (c * p, s * p)
            self._a2 = (c * a2[0] - s * a2[1], s * a2[0] + c * a2[1])
            det = self._a1[0] * self._a2[1] - self._a2[0] * self._a1[1]
            self._inv = ((self._a2[1] / det, -self._a2[0] / det), (-self._a1[1] / det, self._a1[0] / det))
            self._grid, self._rot_cs, self._pitch = grid, (c, s), p
            self._port = None
            if "port_distance_m" in props:
                port = {key: float(props[f"port_{key}"]) for key in _PORT_PROPS}
                FlatPort(**port)  # validation only
                tx, ty = port["tilt_x_rad"], port["tilt_y_rad"]
                normal = (math.sin(ty) * math.cos(tx), -math.sin(tx), math.cos(ty) * math.cos(tx))
                d, t = port["distance_m"], port["thickness_m"]
                if t > 0.0:
                    faces = [(d, port["n_air"], port["n_glass"]), (d + t, port["n_glass"], port["n_water"])]
                else:
                    faces = [(d, port["n_air"], port["n_water"])]
                self._port = (normal, faces, (port["n_air"] / port["n_water"]) ** 2)
            self._lens = None
            if "lens_json" in props:
                real = RealLensCamera(
                    camera=self.camera, lens=LensPrescription.from_dict(json.loads(props["lens_json"]))
                )
                lens = real.lens
                indices = lens.indices()
                # Surfaces in the order a path from the sensor meets them (last to first): camera-frame
                # vertex z, curvature (design sign), clear semi-aperture squared, index after and before.
                self._lens = [
                    (float(z), s.curvature_per_m, s.semi_aperture_m**2, float(indices[i + 1]), float(indices[i]))
                    for i, (s, z) in reversed(list(enumerate(zip(lens.surfaces, lens.vertex_z_m(), strict=True))))
                ]
                self._scale = real.micro_image_scale

        def through_port(self, origin, direction):
            """Refract camera-frame rays through the port's faces (Snell, vector form).

            Returns the ray leaving the water face, the product of the faces' unpolarised Fresnel
            transmittances times ``(n_air / n_water)^2``, and whether the ray got through (it
            reaches the port and is not totally internally reflected).
            """
            normal, faces, radiance_scale = self._port
            n = mi.Vector3f(*normal)
            passed = dr.dot(direction, n) > 0.0
            weight = mi.Float(radiance_scale)
            for offset, n_from, n_to in faces:
                t = (offset - dr.dot(origin, n)) / dr.dot(direction, n)
                origin = dr.fma(direction, t, origin)
                cos_i = dr.dot(direction, n)
                eta = n_from / n_to
                sin2_t = eta * eta * (1.0 - cos_i * cos_i)
                passed &= sin2_t <= 1.0
                cos_t = dr.safe_sqrt(1.0 - sin2_t)
                direction = dr.normalize(eta * direction + (cos_t - eta * cos_i) * n)
                r_s = dr.square((n_from * cos_i - n_to * cos_t) / (n_from * cos_i + n_to * cos_t))
                r_p = dr.square((n_from * cos_t - n_to * cos_i) / (n_from * cos_t + n_to * cos_i))
                weight *= 1.0 - 0.5 * (r_s + r_p)
            return origin, direction, dr.select(passed, weight, 0.0), passed

        def through_lens(self, origin, direction):
            """Trace camera-frame rays from behind the real main lens out through every surface.

            Each surface is the sphere ``c |q|^2 + 2 q_z = 0`` about its vertex (``q`` relative to
            the vertex, camera frame; light from the sensor travels towards +z); the nearer root of
            the ray's quadratic is taken in the form that is stable for any curvature (a plane at
            ``c = 0``), whatever the sign of its denominator (a path that enters a strongly curved
            surface's sphere through its far side, as in a fisheye, has a negative one; the normal
            test refuses a root on the far hemisphere). A path is stopped where it misses a sphere,
            falls outside a clear aperture or is totally reflected. Returns the point on the front
            surface, the direction into the scene and whether the path got through (stopped paths:
            the origin and +z, finite).
            """
            passed = mi.Bool(True)
            for vertex_z, c, aperture2, n_from, n_to in self._lens:
                q = origin - mi.Vector3f(0.0, 0.0, vertex_z)
                big_b = direction.z + c * dr.dot(q, direction)
                big_c = c * dr.squared_norm(q) + 2.0 * q.z
                disc = big_b * big_b - c * big_c
                denom = big_b + dr.safe_sqrt(disc)
                s = -big_c / denom
                hit = dr.fma(direction, s, q)
                passed &= (disc >= 0.0) & dr.isfinite(s) & (s >= -1e-9)
                passed &= hit.x * hit.x + hit.y * hit.y <= aperture2
                normal = mi.Vector3f(c * hit.x, c * hit.y, 1.0 + c * hit.z)
                cos_i = dr.dot(direction, normal)
                passed &= cos_i > 0.0
                eta = n_from / n_to
                sin2_t = eta * eta * (1.0 - cos_i * cos_i)
                passed &= sin2_t <= 1.0
                cos_t = dr.safe_sqrt(1.0 - sin2_t)
                direction = dr.normalize(eta * direction + (cos_t - eta * cos_i) * normal)
                origin = hit + mi.Vector3f(0.0, 0.0, vertex_z)
            # A stopped path may hold NaN (a missed sphere): give it a finite ray (it gets weight 0 anyway).
            origin = dr.select(passed, origin, mi.Point3f(0.0))
            direction = dr.select(passed, direction, mi.Vector3f(0.0, 0.0, 1.0))
            return origin, direction, passed

        def sample_lens_offset(self, aperture_sample):
            """Image-plane offset from the lens centre (metres) for an aperture sample.

            Uniform over the lattice cell: a square, or a regular hexagon split into three rhombi
            spanned from the centre by vertices ``V[2k]`` and ``V[2k + 2]`` (``3 * s.x`` picks
            ``k`` and the first coordinate). The rotated vertices are precomputed, so no
            trigonometry runs per sample.
            """
            c, s = self._rot_cs
            if self._grid == "square":
                lx = (aperture_sample.x - 0.5) * self._pitch
                ly = (aperture_sample.y - 0.5) * self._pitch
                return mi.Vector2f(c * lx - s * ly, s * lx + c * ly)
            radius = self._pitch / math.sqrt(3.0)
            rotation = math.atan2(s, c)
            vertices = []
            for j in range(4):  # V[0], V[2], V[4], V[6] = V[0]
                ang = rotation + math.pi / 6.0 + j * 2.0 * math.pi / 3.0
                vertices.append(mi.Vector2f(radius * math.cos(ang), radius * math.sin(ang)))
            scaled = 3.0 * aperture_sample.x
            k = dr.minimum(dr.floor(scaled), 2.0)
            first = dr.select(k == 0.0, vertices[0], dr.select(k == 1.0, vertices[1], vertices[2]))
            second = dr.select(k == 0.0, vertices[1], dr.select(k == 1.0, vertices[2], vertices[3]))
            return (scaled - k) * first + aperture_sample.y * second

        def nearest_lens_centre(self, point):
            """Image-plane centre of the lattice point nearest to ``point`` (Vector2f).

            The nearest lattice point is a corner of the lattice cell (parallelogram) holding the
            point, so the four corners are compared.
            """
            (i00, i01), (i10, i11) = self._inv
            a1, a2 = self._a1, self._a2
            rel = point - mi.Vector2f(*self._offset)
            fa = dr.floor(i00 * rel.x + i01 * rel.y)
            fb = dr.floor(i10 * rel.x + i11 * rel.y)
            best = mi.Vector2f(0.0)
            best_d2 = mi.Float(dr.inf)
            for da, db in ((0, 0), (1, 0), (0, 1), (1, 1)):
                ia, ib = fa + da, fb + db
                cand = mi.Vector2f(a1[0] * ia + a2[0] * ib, a1[1] * ia + a2[1] * ib)
                d2 = dr.squared_norm(cand - rel)
                closer = d2 < best_d2
                best = dr.select(closer, cand, best)
                best_d2 = dr.select(closer, d2, best_d2)
            return best + mi.Vector2f(*self._offset)

        def sample_ray(self, time, wavelength_sample, position_sample, aperture_sample, active=True):
            u, v, size = self._film_pixels(position_sample)
            pitch = self._pitch_px_m
            sensor_img = mi.Vector2f((u - 0.5 * (size.x - 1.0)) * pitch, (v - 0.5 * (size.y - 1.0)) * pitch)
            centre_img = self.nearest_lens_centre(sensor_img / self._scale)
            through_img = centre_img + self.sample_lens_offset(aperture_sample)
            # Image-plane -> camera frame: x = -xi, y = -eta.
            slope_in = (sensor_img - centre_img) / self._f_mla
            if self._lens is None:
                hit = -through_img + slope_in * self._f_prime
                inside = dr.squared_norm(hit) <= self._aperture_r2
                slope_out = slope_in - hit / self._f
                direction = dr.normalize(mi.Vector3f(slope_out.x, slope_out.y, 1.0))
                origin = mi.Point3f(hit.x, hit.y, 0.0)
            else:
                origin, direction, inside = self.through_lens(
                    mi.Point3f(-through_img.x, -through_img.y, -self._f_prime),
                    dr.normalize(mi.Vector3f(slope_in.x, slope_in.y, 1.0)),
                )
            weight = mi.Float(1.0)
            if self._port is not None:
                origin, direction, weight, passed = self.through_port(origin, direction)
                inside &= passed
            ray = self._ray(time, origin, direction, maxt=dr.select(inside, dr.largest(mi.Float), 0.0))
            return ray, mi.Spectrum(dr.select(inside & active, weight, 0.0))

        def to_string(self):
            lens = "thin" if self._lens is None else f"{len(self._lens)} surfaces"
            return f"PlenopticSensor[camera={self.camera!r}, lens={lens}, port={self._port!r}]"

    class PinholeSensor(_CameraSensor):
        """Ideal central projection with OpenCV intrinsics, centre at the main-lens centre."""

        def __init__(self, props):
            _CameraSensor.__init__(self, props)
            self.focal_px = float(props["focal_px"])
            self.cx_px = float(props["cx_px"])
            self.cy_px = float(props["cy_px"])

        def sample_ray(self, time, wavelength_sample, position_sample, aperture_sample, active=True):
            u, v, _ = self._film_pixels(position_sample)
            direction = dr.normalize(
                mi.Vector3f((u - self.cx_px) / self.focal_px, (v - self.cy_px) / self.focal_px, 1.0)
            )
            return self._ray(time, mi.Point3f(0.0), direction), mi.Spectrum(1.0)

        def to_string(self):
            return f"PinholeSensor[f={self.focal_px}, c=({self.cx_px}, {self.cy_px})]"

    mi.register_sensor(PLENOPTIC, lambda props: PlenopticSensor(props))
    mi.register_sensor(PINHOLE, lambda props: PinholeSensor(props))
