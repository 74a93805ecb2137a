"""The k-d tree candidate search of the refraction-free synthesis (the general-case fallback).

Every usable captured ray (inside the usable aperture, reaching the port's air-side face) is a
point ``(P', lambda * r')`` in R^6: where it meets the face and its unit direction scaled by
``lambda``. The Euclidean distance there, ``sqrt(|P' - P|^2 + lambda^2 |r' - r|^2)``, never
exceeds ``D = |P' - P| + lambda * angle(r', r)`` (the chord ``|r' - r|`` is at most the angle, and
``sqrt(a^2 + b^2) <= a + b``), so querying more neighbours than ``k`` and re-ranking by D is exact
once the farthest neighbour queried lies beyond the k-th best D; samples where it does not are
queried again with twice as many.
"""

from __future__ import annotations

import threading

import numpy as np
from scipy.spatial import cKDTree

from lfrefract.optics.camera import LightFieldCamera
from lfrefract.optics.port import FlatPort
from lfrefract.optics.ray_correction import Correction
from lfrefract.synthesis._kernels import angle_from_chord

__all__ = ["LazyRayTree", "RayTree"]


class RayTree:
    """All usable captured rays of a camera behind a port, for exact k-nearest queries by D.

    Parameters
    ----------
    camera : LightFieldCamera
    port : FlatPort
    usable_radius_m : float
        Main-lens radius inside which a pixel's ray is used (the aperture less the rim margin).
    lambda_m_per_rad : float
        Weight of the angle term of D.
    sites : ndarray of bool, shape (2, 2), optional
        Raw pixels ``(u, v)`` are used only where ``sites[v % 2, u % 2]`` (one colour of a CFA);
        default all.
    correction : RayCorrection or PolynomialCorrection, optional
        The camera's calibrated rays instead of its thin-lens ones (which pixels are usable is
        still the thin-lens model's).
    """

    def __init__(
        self,
        camera: LightFieldCamera,
        port: FlatPort,
        *,
        usable_radius_m: float,
        lambda_m_per_rad: float,
        sites: np.ndarray | None = None,
        correction: Correction | None = None,
    ):
        rays = camera.captured_rays()
        keep = np.hypot(rays.origins_cam[:, 0], rays.origins_cam[:, 1]) <= usable_radius_m
        if correction is not None:
            rays = correction.corrected(rays)
        o, d = rays.origins_cam, rays.directions_cam
        n = port.normal
        cos = d @ n
        keep &= cos > 0.0
        if sites is not None:
            v, u = np.divmod(np.arange(len(o)), camera.sensor.width_px)
            keep &= np.asarray(sites, dtype=bool)[v % 2, u % 2]
        self.raw_index = np.flatnonzero(keep)
        t = (port.distance_m - o[keep] @ n) / cos[keep]
        self.points_cam = o[keep] + t[:, None] * d[keep]
        self.directions_cam = d[keep]
        self.lam = float(lambda_m_per_rad)
        self._tree = cKDTree(self._features(self.points_cam, self.directions_cam), balanced_tree=False)

    def _features(self, points: np.ndarray, directions: np.ndarray) -> np.ndarray:
        return np.concatenate([points, self.lam * directions], axis=1) if self.lam > 0 else points

    def distances(self, rows: np.ndarray, points: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """D (metres) between captured rays ``rows`` (N, m) and necessary rays (N, 3) + (N, 3)."""
        dist = np.linalg.norm(self.points_cam[rows] - points[:, None, :], axis=2)
        if self.lam > 0:
            chord = np.linalg.norm(self.directions_cam[rows] - directions[:, None, :], axis=2)
            dist += self.lam * angle_from_chord(chord)
        return dist

    def nearest(self, points: np.ndarray, directions: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        """The k captured rays of smallest D for each necessary ray.

        Parameters
        ----------
        points : ndarray, shape (N, 3)
            Where the necessary air rays leave the air-side face (P), camera frame, metres.
        directions : ndarray, shape (N, 3)
            Their unit directions, outwards.
        k : int

        Returns
        -------
        raw_index : ndarray of int64, shape (N, k)
            Raw flat pixel indices, best first (ties by the smaller index); -1 where fewer exist.
        dist : ndarray, shape (N, k)
            Their D, metres (inf where -1).
        """
        n_rays = len(self.raw_index)
        out_index = np.full((len(points), k), -1, dtype=np.int64)
        out_dist = np.full((len(points), k), np.inf)
        todo = np.arange(len(points))
        queried = min(n_rays, 4 * k + 8)
        features = self._features(points, directions)
        while len(todo) and n_rays:
            proxy, rows = self._tree.query(features[todo], k=queried)
            proxy, rows = proxy.reshape(len(todo), -1), rows.reshape(len(todo), -1)
            dist = self.distances(rows, points[todo], directions[todo])
            raw = self.raw_index[rows]
            order = np.lexsort((raw, dist), axis=-1)[:, :k]
            best_raw = np.take_along_axis(raw, order, axis=1)
            best_dist = np.take_along_axis(dist, order, axis=1)
            # Exact when every ray not queried (proxy beyond the last one) is farther than the
            # k-th best, or when all rays were queried.
            done = (proxy[:, -1] > best_dist[:, -1]) | (queried >= n_rays)
            width = best_raw.shape[1]
            out_index[todo[done], :width] = best_raw[done]
            out_dist[todo[done], :width] = best_dist[done]
            todo = todo[~done]
            queried = min(n_rays, 2 * queried)
        return out_index, out_dist


class LazyRayTree:
    """Builds the :class:`RayTree` on first use, once, from any thread."""

    def __init__(
        self,
        camera: LightFieldCamera,
        port: FlatPort,
        *,
        usable_radius_m: float,
        lambda_m_per_rad: float,
        sites: np.ndarray | None = None,
        correction: Correction | None = None,
    ):
        self._camera, self._port = camera, port
        self._usable_radius_m, self._lambda_m_per_rad = usable_radius_m, lambda_m_per_rad
        self._sites, self._correction = sites, correction
        self._tree: RayTree | None = None
        self._lock = threading.Lock()

    def get(self) -> RayTree:
        with self._lock:
            if self._tree is None:
                self._tree = RayTree(
                    self._camera,
                    self._port,
                    usable_radius_m=self._usable_radius_m,
                    lambda_m_per_rad=self._lambda_m_per_rad,
                    sites=self._sites,
                    correction=self._correction,
                )
            return self._tree
