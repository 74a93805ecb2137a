"""Property-based checks of the flat port trace (issue 12).

Random ports (normals within the allowed tilt, distances, thicknesses including 0, indices) and
random rays, grazing ones and ones at the critical angle included, from either side:

* any parameters give a ParameterError naming the field and its value, or a port whose traces are
  finite wherever their mask says valid (and NaN with zero transmittance elsewhere);
* where valid, Snell's law holds at every face (the tangential part of ``n d`` is conserved: equal
  sines and coplanarity), the points lie on the faces and on the incoming ray, and tracing the
  outgoing ray back from the far side gives the incoming ray again;
* a ray is totally internally reflected exactly when ``n1 sin1`` exceeds the index of a medium it
  must enter (outside a band of :data:`PORT_TIR_BAND` around the critical angle), and misses the
  port exactly when it starts past the first face or meets it at a cosine below
  :data:`GRAZING_COS_MIN`.

Expected values come from the geometry of the drawn rays (cosines, sines, index products), not from
the trace under test.
"""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, note, settings
from hypothesis import strategies as st

from lfrefract import FlatPort, ParameterError
from lfrefract.optics.port import GRAZING_COS_MIN, MAX_DISTANCE_M, MAX_THICKNESS_M, N_MAX, N_MIN
from tests.tolerances import (
    FLOAT64_UNIT,
    PORT_REVERSAL_CONDITION,
    PORT_REVERSAL_RELATIVE,
    PORT_SNELL_INVARIANT,
    PORT_TIR_BAND,
)

RAYS = 16  # rays traced per example (vectorised)
DRAWN = 4  # of which drawn by hypothesis strategies
FIELDS = ("distance_m", "thickness_m", "tilt_x_rad", "tilt_y_rad", "n_air", "n_glass", "n_water")

# Cosines of a ray with the normal of the face it meets first: anything, away from the port,
# decades down to grazing, and the threshold itself.
COSINES = st.one_of(
    st.floats(0.0, 1.0),
    st.floats(-1.0, 0.0),
    st.floats(0.0, 30.0).map(lambda e: 10.0**-e),
    st.sampled_from(
        [0.0, 5e-324, 1e-300, 1e-10, GRAZING_COS_MIN * (1 - 1e-6), GRAZING_COS_MIN * (1 + 1e-6), 1e-5, 1.0]
    ),
)
# Relative offsets of n1 sin1 from a critical index: on it, within round-off, inside and outside the band.
CRITICAL_OFFSETS = st.one_of(
    st.just(0.0),
    st.floats(0.0, 17.0).map(lambda e: 10.0**-e),
    st.floats(0.0, 17.0).map(lambda e: -(10.0**-e)),
)
INDICES = st.one_of(st.floats(N_MIN, N_MAX), st.floats(N_MIN, 1.6), st.sampled_from([N_MIN, 1.333, 1.5, N_MAX]))


def _basis(m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors perpendicular to the unit vector ``m`` and to each other."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(m[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(m, helper)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(m, e1)


def _tangential(v: np.ndarray, m: np.ndarray) -> np.ndarray:
    return v - (v @ m)[:, None] * m


@st.composite
def scenarios(draw):
    """A valid port, a side, and RAYS rays from that side (origins, unit directions).

    The first DRAWN rays come from hypothesis strategies (so that it can shrink them and hunt
    boundaries); the rest from a seeded generator with the same mix, which is cheaper to draw.
    """
    tilt = math.radians(draw(st.one_of(st.floats(0.0, 89.99), st.sampled_from([0.0, 89.9999]))))
    azimuth = draw(st.floats(0.0, 2 * math.pi))
    normal = [math.sin(tilt) * math.cos(azimuth), math.sin(tilt) * math.sin(azimuth), math.cos(tilt)]
    distance = draw(st.one_of(st.floats(1e-4, 0.3), st.floats(1e-4, MAX_DISTANCE_M), st.just(MAX_DISTANCE_M)))
    thickness = draw(st.one_of(st.just(0.0), st.floats(1e-9, 0.05), st.floats(0.0, MAX_THICKNESS_M)))
    n_air, n_glass, n_water = draw(INDICES), draw(INDICES), draw(INDICES)
    port = FlatPort.from_normal(
        normal, distance_m=distance, thickness_m=thickness, n_air=n_air, n_glass=n_glass, n_water=n_water
    )
    from_air = draw(st.booleans())
    media = _media(port, from_air)
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    kind = np.concatenate(
        [[draw(st.integers(0, 3)) for _ in range(DRAWN)], rng.choice(4, RAYS - DRAWN, p=[0.25, 0.45, 0.2, 0.1])]
    )
    # Cosines with the travel normal: 0 = at a critical angle of a medium the ray enters (n1 sin1
    # = n_c (1 + offset)), 1 = anywhere towards the port, 2 = grazing (decades down to 1e-30),
    # 3 = away from the port or the threshold itself. Without a critical angle, 0 is 1.
    critical_indices = [nc for nc in media[1:] if nc < media[0]]
    cos = np.empty(RAYS)
    for i, k in enumerate(kind):
        if k == 0 and critical_indices:
            pick = draw(st.integers(0, len(critical_indices) - 1)) if i < DRAWN else rng.integers(len(critical_indices))
            critical = critical_indices[pick]
            offset = draw(CRITICAL_OFFSETS) if i < DRAWN else rng.choice([-1.0, 1.0]) * 10.0 ** -rng.uniform(0, 17)
            sin = min(1.0, critical / media[0] * (1.0 + offset))
            cos[i] = math.sqrt(1.0 - sin * sin)
        elif i < DRAWN:
            cos[i] = draw(COSINES)
        elif k <= 1:
            cos[i] = rng.uniform(0.0, 1.0)
        elif k == 2:
            cos[i] = 10.0 ** -rng.uniform(0.0, 30.0)
        else:
            cos[i] = rng.choice([-rng.uniform(), GRAZING_COS_MIN * (1 - 1e-6), GRAZING_COS_MIN * (1 + 1e-6)])
    phi = np.array(
        [draw(st.floats(0.0, 2 * math.pi)) for _ in range(DRAWN)] + list(rng.uniform(0, 2 * math.pi, RAYS - DRAWN))
    )
    # Before the first face (u > 0), on it (u = 0) or already past it (u < 0); lateral offsets.
    u = np.array(
        [draw(st.one_of(st.just(0.0), st.floats(1e-3, 2.0), st.floats(-0.5, -1e-3))) for _ in range(DRAWN)]
        + list(rng.choice([0.0, -1.0, *[1.0] * 8], RAYS - DRAWN) * rng.uniform(1e-3, 2.0, RAYS - DRAWN))
    )
    ab = rng.uniform(-0.05, 0.05, (RAYS, 2))
    n = port.normal
    m = n if from_air else -n
    e1, e2 = _basis(m)
    sin = np.sqrt(1.0 - cos**2)
    directions = cos[:, None] * m + sin[:, None] * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2)
    first_face = port.faces[0][0] if from_air else port.faces[-1][0]
    origins = ab[:, :1] * e1 + ab[:, 1:] * e2 + first_face * n - (u * max(distance, 0.01))[:, None] * m
    return port, from_air, origins, directions


def _media(port: FlatPort, from_air: bool) -> list[float]:
    """Indices along the travel: the start medium first."""
    media = [port.n_air, port.n_glass, port.n_water] if port.thickness_m > 0.0 else [port.n_air, port.n_water]
    return media if from_air else media[::-1]


def _trace(port: FlatPort, from_air: bool, origins: np.ndarray, directions: np.ndarray):
    return port.trace_from_air(origins, directions) if from_air else port.trace_from_water(origins, directions)


def _assert_finite_where_valid(tr) -> None:
    valid = tr.valid
    assert not np.any(tr.misses & tr.tir)
    for arr in (tr.entry_points_cam, tr.exit_points_cam, tr.directions_cam):
        assert np.all(np.isfinite(arr[valid]))
        assert np.all(np.isnan(arr[~valid]))
    assert np.all(np.isfinite(tr.transmittance))
    assert np.all((tr.transmittance[valid] >= 0.0) & (tr.transmittance[valid] <= 1.0))
    assert np.all(tr.transmittance[~valid] == 0.0)


@settings(max_examples=200, deadline=None)
@given(scenario=scenarios())
def test_snell_reversal_tir_and_misses(scenario):
    port, from_air, o, d = scenario
    note(f"port={port!r}, from_air={from_air}")
    n = port.normal
    m = n if from_air else -n
    faces = [f for f, _, _ in port.faces]
    faces = faces if from_air else faces[::-1]
    media = _media(port, from_air)
    tr = _trace(port, from_air, o, d)
    _assert_finite_where_valid(tr)

    # ---- classification, from the drawn geometry
    start = o @ n - faces[0]
    past = start > 1e-12 if from_air else start < -1e-12
    cos = d @ m
    sin = np.linalg.norm(np.cross(d, m), axis=1)
    q = media[0] * sin
    grazing = cos < GRAZING_COS_MIN
    tir = ~past & ~grazing & (q > min(media[1:]))
    near_critical = np.any([np.abs(q / nc - 1.0) <= PORT_TIR_BAND for nc in media[1:]], axis=0)
    near_threshold = np.abs(cos - GRAZING_COS_MIN) <= 1e-15
    sure = ~near_critical & ~near_threshold
    np.testing.assert_array_equal(tr.misses[sure], (past | grazing)[sure])
    np.testing.assert_array_equal(tr.tir[sure], tir[sure])
    valid = tr.valid
    if not valid.any():
        return

    # ---- Snell at every face, points on faces and on the incoming ray
    dv, ov, w = d[valid], o[valid], tr.directions_cam[valid]
    entry, exit_ = tr.entry_points_cam[valid], tr.exit_points_cam[valid]
    scale = np.linalg.norm(ov, axis=1) + np.linalg.norm(entry, axis=1) + np.linalg.norm(exit_, axis=1)
    np.testing.assert_allclose(np.linalg.norm(w, axis=1), 1.0, rtol=0, atol=PORT_SNELL_INVARIANT)
    assert np.all(w @ m >= -FLOAT64_UNIT)  # transmitted onwards (along the face at the critical angle)
    np.testing.assert_allclose(
        media[0] * _tangential(dv, m), media[-1] * _tangential(w, m), rtol=0, atol=PORT_SNELL_INVARIANT
    )
    np.testing.assert_allclose(np.einsum("ij,ij->i", dv, np.cross(m, w)), 0.0, atol=PORT_SNELL_INVARIANT)  # coplanar
    assert np.all(np.abs(entry @ n - faces[0]) <= PORT_REVERSAL_RELATIVE * scale)
    assert np.all(np.abs(exit_ @ n - faces[-1]) <= PORT_REVERSAL_RELATIVE * scale)
    assert np.all(np.linalg.norm(np.cross(entry - ov, dv), axis=1) <= PORT_REVERSAL_RELATIVE * scale)
    if len(media) == 3:
        # The direction inside the glass, from the points where the ray crosses it (well
        # conditioned only where they are far apart compared with their size).
        span = exit_ - entry
        length = np.linalg.norm(span, axis=1)
        ok = length >= 1e-5 * scale
        g = span[ok] / length[ok, None]
        assert np.all(g @ m > 0.0)
        np.testing.assert_allclose(
            media[0] * _tangential(dv[ok], m), media[1] * _tangential(g, m), rtol=0, atol=PORT_SNELL_INVARIANT
        )
        np.testing.assert_allclose(
            media[1] * _tangential(g, m), media[2] * _tangential(w[ok], m), rtol=0, atol=PORT_SNELL_INVARIANT
        )

    # ---- reversal: the outgoing ray traced back from the far side
    cos_path = [cos[valid], w @ m]
    if len(media) == 3:
        cos_path.append(np.sqrt(np.maximum(0.0, 1.0 - (q[valid] / media[1]) ** 2)))
    c_min = np.min(cos_path, axis=0)
    reach = 0.1 + np.linalg.norm(exit_, axis=1)
    far = exit_ + reach[:, None] * w
    back = _trace(port, not from_air, far, -w)
    _assert_finite_where_valid(back)
    assert back.valid[c_min >= 2 * GRAZING_COS_MIN].all()
    condition = np.finfo(np.float64).eps * (max(media) / min(media)) ** 2 / np.maximum(c_min, 1e-150) ** 2
    k = condition <= PORT_REVERSAL_CONDITION
    scale = scale + np.linalg.norm(far, axis=1)
    np.testing.assert_allclose(back.directions_cam[k], -dv[k], rtol=0, atol=PORT_REVERSAL_RELATIVE)
    assert np.all(np.linalg.norm(back.entry_points_cam[k] - exit_[k], axis=1) <= PORT_REVERSAL_RELATIVE * scale[k])
    assert np.all(np.linalg.norm(back.exit_points_cam[k] - entry[k], axis=1) <= PORT_REVERSAL_RELATIVE * scale[k])
    # The reversed light passes through the original ray's origin.
    miss = np.linalg.norm(np.cross(ov[k] - back.exit_points_cam[k], back.directions_cam[k]), axis=1)
    assert np.all(miss <= PORT_REVERSAL_RELATIVE * scale[k])
    # Fresnel transmittance is reciprocal.
    np.testing.assert_allclose(back.transmittance[k], tr.transmittance[valid][k], rtol=0, atol=PORT_SNELL_INVARIANT)


# Any float, the awkward ones included, or a value inside the field's range.
WILD = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -0.0, 1e-300, 1e300, -1e300, math.pi / 2, math.pi, 5e-324, float("nan"), float("inf")]),
)
IN_RANGE = {
    "distance_m": st.floats(1e-4, MAX_DISTANCE_M),
    "thickness_m": st.one_of(st.just(0.0), st.floats(0.0, MAX_THICKNESS_M)),
    "tilt_x_rad": st.floats(-1.5, 1.5),
    "tilt_y_rad": st.floats(-1.5, 1.5),
    "n_air": st.floats(N_MIN, N_MAX),
    "n_glass": st.floats(N_MIN, N_MAX),
    "n_water": st.floats(N_MIN, N_MAX),
}


@st.composite
def any_fields(draw):
    return {name: draw(st.one_of(IN_RANGE[name], IN_RANGE[name], WILD)) for name in FIELDS}


@st.composite
def any_rays(draw):
    """Rays anywhere near the camera, in any direction; half of them along one drawn direction
    (grazing ones on purpose)."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    directions = rng.normal(size=(RAYS, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    tilt = draw(st.one_of(st.floats(0.0, math.pi / 2), st.just(math.pi / 2 - 1e-10)))
    directions[: RAYS // 2] = [0.0, math.sin(tilt), math.cos(tilt)]
    origins = rng.uniform(-0.2, 0.2, (RAYS, 3))
    return origins, directions


@settings(max_examples=150, deadline=None)
@given(fields=any_fields(), rays=any_rays(), from_air=st.booleans())
def test_any_parameters_give_a_clear_error_or_finite_traces(fields, rays, from_air):
    try:
        port = FlatPort(**fields)
    except ParameterError as exc:
        message = str(exc)
        # The message names a field and shows its value.
        assert any(name in message and repr(value) in message for name, value in fields.items()), message
        return
    tr = _trace(port, from_air, *rays)
    _assert_finite_where_valid(tr)
    # The same port through its plain-data form: the same checks, the same port.
    assert FlatPort.from_dict(port.to_dict()) == port
