"""Multi-element main lenses (lfrefract.optics.lens): media, validation, first-order data, the exact trace.

The trace and the first-order data are checked against optiland, an independent optics library
(its real-ray tracer and its paraxial module), on the same prescriptions and the same rays.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from lfrefract.errors import ParameterError
from lfrefract.optics.lens import (
    C_LINE_M,
    D_LINE_M,
    F_LINE_M,
    GLASSES,
    LENS_PRESETS,
    LensPrescription,
    Medium,
    Surface,
    exit_pupil_bounds,
    lens_preset,
    trace_lens,
)
from tests.tolerances import (
    FLOAT64_RELATIVE,
    LENS_AGREE_DIRECTION_RAD,
    LENS_AGREE_FIRST_ORDER_RELATIVE,
    LENS_AGREE_POSITION_M,
    LENS_PARAXIAL_RELATIVE,
)

ILLUM_F_M = 9.993e-3


def _optiland(lens: LensPrescription, wavelength_m: float = D_LINE_M):
    """The same prescription in optiland (mm), media as ideal indices at ``wavelength_m``, image at the last vertex."""
    from optiland.materials import IdealMaterial
    from optiland.optic import Optic

    n = lens.indices(wavelength_m)
    op = Optic()
    op.surfaces.add(index=0, radius=np.inf, thickness=np.inf)
    for i, s in enumerate(lens.surfaces):
        op.surfaces.add(
            index=i + 1,
            radius=s.radius_m * 1e3,
            thickness=s.thickness_m * 1e3,
            material="air" if s.medium.model == "air" else IdealMaterial(n=float(n[i + 1])),
            is_stop=s.stop,
            aperture=2.0 * s.semi_aperture_m * 1e3,  # optiland takes a clear diameter
        )
    op.surfaces.add(index=len(lens.surfaces) + 1)
    op.set_aperture(
        aperture_type="float_by_stop_size", value=2.0 * lens.surfaces[lens.stop_index].semi_aperture_m * 1e3
    )
    op.fields.set_type(field_type="angle")
    op.fields.add(y=0.0)
    op.wavelengths.add(value=wavelength_m * 1e6, is_primary=True)
    return op


def _optiland_trace(lens, op, origins_cam, directions_cam, wavelength_m):
    """Trace camera-frame rays with optiland's real-ray tracer; per-surface points, last directions, passed mask."""
    from numba.core.errors import NumbaIRAssumptionWarning
    from optiland.rays import RealRays

    z_front = lens.first_order().front_vertex_z_m
    o, d = origins_cam, directions_cam
    rays = RealRays(
        o[:, 0] * 1e3,
        o[:, 1] * 1e3,
        (z_front - o[:, 2]) * 1e3,  # optiland's z runs from the first vertex towards the image, as -z
        d[:, 0],
        d[:, 1],
        -d[:, 2],
        np.ones(len(o)),
        np.full(len(o), wavelength_m * 1e6),
    )
    with warnings.catch_warnings():
        # numba's internal pedantic check warns while it compiles optiland's conic-intersection
        # kernel (the first trace of a session); it is about numba's IR, not about the results.
        warnings.simplefilter("ignore", NumbaIRAssumptionWarning)
        op.surfaces.trace(rays)
    count = len(lens.surfaces)
    g = op.surfaces
    points = np.stack(
        [np.asarray(g.x)[1 : count + 1], np.asarray(g.y)[1 : count + 1], np.asarray(g.z)[1 : count + 1]], axis=2
    )
    points = np.concatenate([points[..., :2] * 1e-3, z_front - points[..., 2:] * 1e-3], axis=2)
    last = count
    directions = np.column_stack([np.asarray(g.L)[last], np.asarray(g.M)[last], -np.asarray(g.N)[last]])
    passed = np.asarray(g.intensity)[last] > 0
    return points, directions, passed


def _rays_through_pupil(lens, *, half_field_deg, count, seed, pupil_fill=1.3):
    """Rays from a distant scene (directions up to ``half_field_deg`` off the axis) through the entrance pupil plane.

    Points fill ``pupil_fill`` times the paraxial entrance pupil, so some rays are vignetted; origins lie
    in front of the first vertex.
    """
    fo = lens.first_order()
    rng = np.random.default_rng(seed)
    angle = np.deg2rad(half_field_deg) * np.sqrt(rng.uniform(0.0, 1.0, count))
    phi = rng.uniform(0.0, 2.0 * np.pi, count)
    d = np.column_stack([np.sin(angle) * np.cos(phi), np.sin(angle) * np.sin(phi), -np.cos(angle)])
    r = np.sqrt(rng.uniform(0.0, 1.0, count)) * fo.entrance_pupil_diameter_m / 2.0 * pupil_fill
    psi = rng.uniform(0.0, 2.0 * np.pi, count)
    on_pupil = np.column_stack([r * np.cos(psi), r * np.sin(psi), np.full(count, fo.entrance_pupil_z_m)])
    back = fo.front_vertex_z_m + fo.total_track_m - fo.entrance_pupil_z_m  # well in front of the lens
    return on_pupil - d * (back / -d[:, 2])[:, None], d


# ----------------------------------------------------------------------------- media


def test_catalogue_glasses_match_their_published_d_line_indices():
    # SCHOTT data sheets: n_d of N-BK7 1.51680, F2 1.62004, SF5 1.67270, N-SK16 1.62041, N-LAK9 1.69100.
    published = {"N-BK7": 1.51680, "F2": 1.62004, "SF5": 1.67270, "N-SK16": 1.62041, "N-LAK9": 1.69100}
    for name, n_d in published.items():
        assert Medium.named(name).index() == pytest.approx(n_d, abs=2e-5), name


def test_catalogue_glasses_match_the_schott_catalogue_as_optiland_ships_it():
    # optiland ships the SCHOTT catalogue (refractiveindex.info files); its Sellmeier terms must be ours.
    import optiland

    folder = Path(optiland.__file__).parent / "database" / "data-nk" / "glass" / "schott"
    for name, (b, c) in GLASSES.items():
        lines = (folder / f"{name}.yml").read_text(encoding="utf-8").splitlines()
        formula = lines.index(next(x for x in lines if "type: formula 2" in x))
        terms = [float(x) for x in lines[formula + 2].split(":")[1].split()]
        assert terms[0] == 0.0, name
        assert tuple(terms[1::2]) == b, name
        assert tuple(terms[2::2]) == c, name


def test_abbe_medium_has_its_n_d_and_v_d():
    m = Medium.abbe(n_d=1.67, v_d=47.1)
    assert m.index(D_LINE_M) == pytest.approx(1.67, abs=1e-14)
    v_d = (m.index(D_LINE_M) - 1.0) / (m.index(F_LINE_M) - m.index(C_LINE_M))
    assert v_d == pytest.approx(47.1, rel=FLOAT64_RELATIVE)
    flat = Medium.abbe(n_d=1.5, v_d=math.inf)
    assert flat.index(400e-9) == flat.index(700e-9) == 1.5
    assert Medium.air().index(400e-9) == 1.0


def test_sellmeier_medium_equals_the_catalogue_glass_it_copies():
    b, c = GLASSES["N-BK7"]
    mine = Medium.sellmeier(b=b, c_um2=c, name="my-bk7")
    assert mine.index(500e-9) == Medium.named("N-BK7").index(500e-9)


@pytest.mark.parametrize(
    "medium",
    [Medium.air(), Medium.named("SF5"), Medium.abbe(n_d=1.6, v_d=40.0, name="g"), Medium.abbe(n_d=1.6, v_d=math.inf)],
)
def test_medium_round_trips_through_its_dict(medium):
    assert Medium.from_dict(medium.to_dict()) == medium
    custom = Medium.sellmeier(b=(1.0, 0.2), c_um2=(0.01, 100.0), name="two-term")
    assert Medium.from_dict(custom.to_dict()) == custom


@pytest.mark.parametrize(
    ("data", "fragment"),
    [
        ("N-BK8", "N-BK8"),
        ({"n_d": 0.9, "v_d": 40}, "n_d"),
        ({"n_d": 1.5, "v_d": -3}, "v_d"),
        ({"sellmeier_b": [1.0], "sellmeier_c_um2": [0.1, 0.2]}, "same number"),
        ({"n_d": 1.5, "sellmeier_b": [1.0], "sellmeier_c_um2": [0.1]}, "not both"),
        ({"sellmeier_b": [-5.0], "sellmeier_c_um2": [0.0]}, "not a real medium"),
        ({"nd": 1.5}, "nd"),
        ({"n_d": 1.5, "v_d": "fifty"}, "v_d"),
    ],
)
def test_bad_media_are_refused_with_the_value_named(data, fragment):
    with pytest.raises(ParameterError, match=fragment):
        Medium.from_dict(data)


def test_index_refuses_wavelengths_outside_the_catalogue_range():
    with pytest.raises(ParameterError, match="wavelength_m"):
        Medium.named("N-BK7").index(100e-9)


# ----------------------------------------------------------------------------- prescriptions


def _singlet(**changes):
    rows = {
        "surfaces": [
            {"radius_m": 0.05, "thickness_m": 0.004, "medium": "N-BK7", "semi_aperture_m": 0.01, "stop": True},
            {"radius_m": -0.05, "thickness_m": 0.0, "medium": "air", "semi_aperture_m": 0.01},
        ],
        "name": "singlet",
        "source": "",
    }
    rows.update(changes)
    return rows


def test_presets_round_trip_through_their_dicts_and_cite_a_source():
    for name in LENS_PRESETS:
        lens = lens_preset(name)
        assert LensPrescription.from_dict(lens.to_dict()) == lens
        assert len(lens.source) > 30, name
    assert "2,673,491" in lens_preset("double-gauss").source
    assert "Laikin" in lens_preset("wide-angle").source
    assert "p. 108" in lens_preset("wide-angle").source


def test_flat_surfaces_are_inf_whether_given_as_0_or_inf():
    a = Surface(radius_m=0, thickness_m=0.0, medium=Medium.air(), semi_aperture_m=1e-3, stop=True)
    b = Surface.from_dict({"radius_m": "inf", "thickness_m": 0.0, "semi_aperture_m": 1e-3, "stop": True})
    assert a.radius_m == b.radius_m == math.inf
    assert a.curvature_per_m == 0.0
    with pytest.raises(ParameterError, match="radius_m"):
        Surface(radius_m=False, thickness_m=0.0, medium=Medium.air(), semi_aperture_m=1e-3)  # type: ignore[arg-type]


def test_a_window_has_no_focal_length():
    window = LensPrescription.from_dict(
        _singlet(
            surfaces=[
                {"radius_m": "inf", "thickness_m": 0.004, "medium": "N-BK7", "semi_aperture_m": 0.01, "stop": True},
                {"radius_m": "inf", "thickness_m": 0.0, "semi_aperture_m": 0.01},
            ]
        )
    )
    with pytest.raises(ParameterError, match="afocal"):
        window.first_order()


@pytest.mark.parametrize(
    ("surfaces", "fragment"),
    [
        ([], "non-empty"),
        (
            [
                {"radius_m": 0.05, "thickness_m": 0.004, "medium": "N-BK7", "semi_aperture_m": 0.01},
                {"radius_m": -0.05, "thickness_m": 0.0, "semi_aperture_m": 0.01},
            ],
            "exactly one surface must be the stop, got 0",
        ),
        (
            [
                {"radius_m": 0.05, "thickness_m": 0.004, "medium": "N-BK7", "semi_aperture_m": 0.01, "stop": True},
                {"radius_m": -0.05, "thickness_m": 0.0, "semi_aperture_m": 0.01, "stop": True},
            ],
            "exactly one surface must be the stop, got 2",
        ),
        (
            [
                {"radius_m": 0.05, "thickness_m": 0.001, "medium": "N-BK7", "semi_aperture_m": 0.02, "stop": True},
                {"radius_m": -0.05, "thickness_m": 0.0, "semi_aperture_m": 0.02},
            ],
            "cross at height",
        ),
        (
            [
                {"radius_m": 0.05, "thickness_m": 0.004, "medium": "N-BK7", "semi_aperture_m": 0.01, "stop": True},
                {"radius_m": -0.05, "thickness_m": 0.0, "medium": "F2", "semi_aperture_m": 0.01},
            ],
            "must be air",
        ),
        (
            [
                {"radius_m": 0.05, "thickness_m": 0.004, "medium": "N-BK7", "semi_aperture_m": 0.01, "stop": True},
                {"radius_m": -0.05, "thickness_m": 0.03, "semi_aperture_m": 0.01},
            ],
            "thickness_m must be 0",
        ),
        (
            [{"radius_m": 0.005, "thickness_m": 0.0, "semi_aperture_m": 0.01, "stop": True}],
            "semi_aperture_m=0.01 exceeds",
        ),
        ([{"radius_m": 0.05, "thickness_m": 0.0, "semi_aperture_m": -0.01, "stop": True}], "semi_aperture_m"),
        ([{"radius_m": 0.05, "thickness_m": -1.0, "semi_aperture_m": 0.01, "stop": True}], "thickness_m"),
        ([{"radius_m": 0.05, "thickness_m": 0.0, "semi_aperture_m": 0.01, "glass": "F2"}], "glass"),
    ],
)
def test_bad_prescriptions_are_refused_with_the_reason(surfaces, fragment):
    with pytest.raises(ParameterError, match=fragment):
        LensPrescription.from_dict(_singlet(surfaces=surfaces))


def test_a_lens_needs_a_name():
    with pytest.raises(ParameterError, match="lens name"):
        LensPrescription.from_dict(_singlet(name=" "))


@pytest.mark.parametrize("name", sorted(LENS_PRESETS))
def test_placement_puts_the_rear_principal_plane_at_the_camera_origin(name):
    lens = lens_preset(name, focal_length_m=ILLUM_F_M)
    fo = lens.first_order()
    z = lens.vertex_z_m()
    assert (z[0], z[-1]) == (fo.front_vertex_z_m, pytest.approx(fo.rear_vertex_z_m, abs=1e-15))
    assert np.all(np.diff(z) <= 0.0)  # surfaces in order from the scene (+z) towards the sensor
    assert fo.rear_vertex_z_m - fo.rear_principal_m == pytest.approx(0.0, abs=1e-15)
    assert fo.entrance_pupil_z_m == pytest.approx(fo.front_vertex_z_m - fo.entrance_pupil_m, abs=1e-15)
    assert fo.front_principal_z_m == pytest.approx(fo.front_vertex_z_m - fo.front_principal_m, abs=1e-15)
    # The placement is a mechanical fact: at another wavelength the lens stays where it is.
    assert lens.first_order(F_LINE_M).front_vertex_z_m == fo.front_vertex_z_m


def test_scaling_to_a_focal_length_keeps_the_f_number_and_the_shape():
    base = lens_preset("double-gauss")
    lens = lens_preset("double-gauss", focal_length_m=ILLUM_F_M)
    fo, fo0 = lens.first_order(), base.first_order()
    assert fo.efl_m == pytest.approx(ILLUM_F_M, rel=FLOAT64_RELATIVE)
    assert fo.f_number == pytest.approx(fo0.f_number, rel=FLOAT64_RELATIVE)
    assert fo.bfd_m / fo.efl_m == pytest.approx(fo0.bfd_m / fo0.efl_m, rel=FLOAT64_RELATIVE)
    stopped = lens_preset("wide-angle", focal_length_m=ILLUM_F_M, f_number=5.6)
    assert stopped.first_order().f_number == pytest.approx(5.6, rel=FLOAT64_RELATIVE)
    assert stopped.first_order().efl_m == pytest.approx(ILLUM_F_M, rel=FLOAT64_RELATIVE)


def test_published_character_of_the_presets():
    # The double Gauss is tabulated as f/2 at 50 mm; the wide angle as f/4 (stop sized here for it).
    dg = lens_preset("double-gauss").first_order()
    assert dg.efl_m == pytest.approx(50e-3, rel=0.01)
    assert dg.f_number == pytest.approx(2.0, rel=0.02)
    wa = lens_preset("wide-angle").first_order()
    assert wa.f_number == pytest.approx(4.0, rel=FLOAT64_RELATIVE)
    # A retrofocus wide angle: its back focal distance exceeds its focal length.
    assert wa.bfd_m > wa.efl_m


def test_unknown_preset_is_named():
    with pytest.raises(ParameterError, match="tessar"):
        lens_preset("tessar")


# ----------------------------------------------------------------------------- against optiland


@pytest.mark.parametrize("name", sorted(LENS_PRESETS))
@pytest.mark.parametrize("wavelength_m", [D_LINE_M, F_LINE_M])
def test_first_order_data_agree_with_optiland(name, wavelength_m):
    lens = lens_preset(name, focal_length_m=ILLUM_F_M)
    fo = lens.first_order(wavelength_m)
    p = _optiland(lens, wavelength_m).paraxial
    theirs = {
        "efl_m": float(p.f2()) * 1e-3,
        "bfd_m": float(p.F2()) * 1e-3,  # from the image surface, which sits at the last vertex
        "ffd_m": -float(p.F1()) * 1e-3,  # optiland: position from the first vertex
        "front_principal_m": float(p.P1()) * 1e-3,
        "rear_principal_m": float(p.P2()) * 1e-3,
        "entrance_pupil_m": float(p.EPL()) * 1e-3,
        "entrance_pupil_diameter_m": float(np.ravel(p.EPD())[0]) * 1e-3,
        "exit_pupil_m": float(p.XPL()) * 1e-3,
        "exit_pupil_diameter_m": float(np.ravel(p.XPD())[0]) * 1e-3,
        "f_number": float(np.ravel(p.FNO())[0]),
    }
    for key, value in theirs.items():
        assert getattr(fo, key) == pytest.approx(value, rel=LENS_AGREE_FIRST_ORDER_RELATIVE), key


@pytest.mark.parametrize(("name", "half_field_deg"), [("double-gauss", 24.0), ("wide-angle", 52.0)])
def test_real_rays_agree_with_optiland_at_every_surface(name, half_field_deg):
    lens = lens_preset(name, focal_length_m=ILLUM_F_M)
    origins, directions = _rays_through_pupil(lens, half_field_deg=half_field_deg, count=3000, seed=1)
    for wavelength_m in (D_LINE_M, C_LINE_M):
        mine = trace_lens(lens, origins, directions, wavelength_m=wavelength_m, record=True)
        points, dirs, passed = _optiland_trace(lens, _optiland(lens, wavelength_m), origins, directions, wavelength_m)
        # Both vignette the same rays; the samples hold rays of both kinds.
        np.testing.assert_array_equal(mine.passed, passed)
        assert 0.2 < mine.passed.mean() < 0.95
        ok = mine.passed
        assert mine.surface_points_cam is not None
        assert np.max(np.abs(mine.surface_points_cam[:, ok] - points[:, ok])) < LENS_AGREE_POSITION_M
        np.testing.assert_array_equal(mine.points_cam[ok], mine.surface_points_cam[-1, ok])
        assert np.max(np.abs(mine.directions_cam[ok] - dirs[ok])) < LENS_AGREE_DIRECTION_RAD
        assert np.all(np.isnan(mine.points_cam[~ok]))
        assert np.all(mine.blocked_at[~ok] >= 0)


# ----------------------------------------------------------------------------- the trace's own properties


@pytest.mark.parametrize("name", sorted(LENS_PRESETS))
def test_rays_traced_back_from_the_sensor_side_retrace_their_path(name):
    lens = lens_preset(name, focal_length_m=ILLUM_F_M)
    origins, directions = _rays_through_pupil(lens, half_field_deg=20.0, count=2000, seed=2, pupil_fill=0.9)
    forward = trace_lens(lens, origins, directions, record=True)
    ok = forward.passed
    assert ok.mean() > 0.5
    start = forward.points_cam[ok] + 1e-3 * forward.directions_cam[ok]  # 1 mm behind the lens
    back = trace_lens(lens, start, -forward.directions_cam[ok], toward="object", record=True)
    assert np.all(back.passed)
    assert forward.surface_points_cam is not None
    assert back.surface_points_cam is not None
    assert np.max(np.abs(back.surface_points_cam - forward.surface_points_cam[:, ok])) < LENS_AGREE_POSITION_M
    assert np.max(np.abs(back.directions_cam + directions[ok])) < LENS_AGREE_DIRECTION_RAD


@pytest.mark.parametrize("name", sorted(LENS_PRESETS))
def test_in_the_paraxial_limit_the_thick_lens_maps_rays_like_the_thin_lens_of_its_first_order_data(name):
    # The thin lens of today's model: a ray meeting the lens plane at height h with slope s leaves it
    # at h with slope s - h / f. For the thick lens the lens plane splits into the front principal
    # plane (object side) and the rear one (z = 0 by the placement, where the thin lens sits).
    lens = lens_preset(name, focal_length_m=ILLUM_F_M)
    fo = lens.first_order()
    f = fo.efl_m
    rng = np.random.default_rng(3)
    count = 500
    h_in = rng.uniform(-1.0, 1.0, (count, 2)) * 1e-6 * f
    slope_in = rng.uniform(-1.0, 1.0, (count, 2)) * 1e-6  # dx/d(-z): travel towards -z
    d = np.column_stack([slope_in, -np.ones(count)])
    on_front_plane = np.column_stack([h_in, np.full(count, fo.front_principal_z_m)])
    origins = on_front_plane - d * (fo.front_vertex_z_m + 1e-3 - fo.front_principal_z_m)  # 1 mm before the lens
    out = trace_lens(lens, origins, d)
    assert np.all(out.passed)
    slope_out = out.directions_cam[:, :2] / -out.directions_cam[:, 2:]
    h_out = out.points_cam[:, :2] + slope_out * out.points_cam[:, 2:]  # back along the ray to z = 0
    scale = 1e-6 * f
    assert np.max(np.abs(h_out - h_in)) < LENS_PARAXIAL_RELATIVE * scale
    assert np.max(np.abs(slope_out - (slope_in - h_in / f))) < LENS_PARAXIAL_RELATIVE * 1e-6
    # Rays parallel to the axis meet it at z = -f: the microlens array of a camera focused at infinity.
    par = trace_lens(
        lens, np.column_stack([h_in, np.full(count, fo.front_vertex_z_m + 1e-3)]), np.tile([0, 0, -1.0], (count, 1))
    )
    s = par.directions_cam[:, :2] / -par.directions_cam[:, 2:]
    z_cross = par.points_cam[:, 2] + (par.points_cam[:, 0] / s[:, 0])
    assert np.max(np.abs(z_cross + f)) < 1e-9 * f


def test_total_internal_reflection_is_flagged_at_its_surface():
    # A plano-convex lens of index 1.9 with its curved face towards the image: a ray parallel to the
    # axis at 0.9 of the radius meets that face at asin(0.9) = 64 deg, beyond the critical 31.8 deg.
    lens = LensPrescription(
        name="tir",
        source="",
        surfaces=(
            Surface(
                radius_m=math.inf,
                thickness_m=0.01,
                medium=Medium.abbe(n_d=1.9, v_d=math.inf),
                semi_aperture_m=0.01,
                stop=True,
            ),
            Surface(radius_m=-0.01, thickness_m=0.0, medium=Medium.air(), semi_aperture_m=0.0099),
        ),
    )
    z0 = lens.first_order().front_vertex_z_m + 1e-3
    heights = np.array([0.0, 0.001, 0.009])
    origins = np.column_stack([np.zeros(3), heights, np.full(3, z0)])
    out = trace_lens(lens, origins, np.tile([0.0, 0.0, -1.0], (3, 1)))
    np.testing.assert_array_equal(out.tir, [False, False, True])
    np.testing.assert_array_equal(out.blocked_at, [-1, -1, 1])
    assert not out.vignetted.any()
    assert np.all(np.isnan(out.directions_cam[2]))


def test_vignetting_by_the_clear_apertures_grows_with_the_field():
    # The double Gauss's clear apertures cut the oblique beams: the fraction of a beam filling the
    # entrance pupil that gets through falls with the field angle (mechanical vignetting).
    lens = lens_preset("double-gauss", focal_length_m=ILLUM_F_M)
    fo = lens.first_order()
    grid = np.linspace(-1.0, 1.0, 41)
    px, py = np.meshgrid(grid, grid)
    inside = px**2 + py**2 <= 1.0
    on_pupil = np.column_stack([px[inside], py[inside], np.zeros(inside.sum())]) * fo.entrance_pupil_diameter_m / 2
    on_pupil[:, 2] = fo.entrance_pupil_z_m
    passed = []
    for angle in np.deg2rad([0.0, 10.0, 20.0, 30.0]):
        d = np.tile([0.0, math.sin(angle), -math.cos(angle)], (len(on_pupil), 1))
        origins = on_pupil - d * ((fo.front_vertex_z_m + 2e-3 - fo.entrance_pupil_z_m) / math.cos(angle))
        passed.append(trace_lens(lens, origins, d).passed.mean())
    assert passed[0] > 0.99
    assert passed[0] > passed[1] > passed[2] > passed[3]


def test_trace_refuses_bad_arrays():
    lens = lens_preset("double-gauss")
    with pytest.raises(ParameterError, match="shape"):
        trace_lens(lens, np.zeros((3, 2)), np.zeros((3, 2)))
    with pytest.raises(ParameterError, match="zero"):
        trace_lens(lens, np.zeros((1, 3)), np.zeros((1, 3)))
    with pytest.raises(ParameterError, match="toward"):
        trace_lens(lens, np.zeros((1, 3)), np.ones((1, 3)), toward="sideways")  # type: ignore[arg-type]


@pytest.mark.parametrize(("toward", "z_direction"), [("image", 1.0), ("image", 0.0), ("object", -1.0)])
def test_trace_refuses_rays_aimed_away_from_the_lens(toward, z_direction):
    """Such a ray never meets the lens: it used to be reported as vignetted at the first surface."""
    lens = lens_preset("double-gauss")
    fo = lens.first_order()
    z = fo.front_vertex_z_m + 0.01 if toward == "image" else fo.rear_vertex_z_m - 0.01
    origins = np.array([[0.0, 0.0, z], [0.0, 0.0, z]])
    directions = np.array([[0.0, 0.0, -1.0 if toward == "image" else 1.0], [0.1, 0.0, z_direction]])
    with pytest.raises(ParameterError, match=r"directions_cam\[1\].*toward"):
        trace_lens(lens, origins, directions, toward=toward)


# ----------------------------------------------------------------------------- exit pupil bounds


@pytest.mark.parametrize("name", sorted(LENS_PRESETS))
def test_exit_pupil_bounds_hold_every_ray_that_passes(name):
    lens = lens_preset(name, focal_length_m=ILLUM_F_M)
    fo = lens.first_order()
    plane_z = -ILLUM_F_M  # the MLA of a camera focused at infinity
    radii = np.array([0.0, 1.5e-3, 3.0e-3, 4.5e-3])
    bounds = exit_pupil_bounds(lens, plane_z_m=plane_z, radii_m=radii, grid=64)
    rng = np.random.default_rng(4)
    half = 1.5 * lens.surfaces[-1].semi_aperture_m
    for r, (x0, x1, y0, y1) in zip(radii, bounds, strict=True):
        phi = rng.uniform(0.0, 2.0 * np.pi)
        c, s = math.cos(phi), math.sin(phi)
        local = rng.uniform(-half, half, (20000, 2))  # targets in the frame turned by phi
        targets = np.column_stack([c * local[:, 0] - s * local[:, 1], s * local[:, 0] + c * local[:, 1]])
        origin = np.array([c * r, s * r, plane_z])
        aim = np.column_stack([targets, np.full(len(targets), fo.rear_vertex_z_m)])
        passed = trace_lens(lens, np.broadcast_to(origin, aim.shape), aim - origin, toward="object").passed
        assert passed.sum() > 100
        inside = (local[:, 0] >= x0) & (local[:, 0] <= x1) & (local[:, 1] >= y0) & (local[:, 1] <= y1)
        assert np.all(inside[passed]), (name, r)
        # The box is much smaller than the square a renderer would sample otherwise.
        assert passed.sum() / inside.sum() > 2.0 * passed.mean()


def test_exit_pupil_bounds_on_the_axis_are_the_paraxial_exit_pupil_seen_from_the_image_plane():
    # Stopped down to f/16 the pupil's aberrations vanish: from an axial point the beam through the
    # exit pupil crosses the rear vertex plane in a disc of radius (XPD / 2) (z_rear - z) / (z_xp - z).
    lens = lens_preset("double-gauss", focal_length_m=ILLUM_F_M, f_number=16.0)
    fo = lens.first_order()
    plane_z = -ILLUM_F_M
    grid = 512
    (x0, x1, y0, y1), *_ = exit_pupil_bounds(lens, plane_z_m=plane_z, radii_m=np.array([0.0]), grid=grid)
    expected = fo.exit_pupil_diameter_m / 2.0 * (fo.rear_vertex_z_m - plane_z) / (fo.exit_pupil_z_m - plane_z)
    spacing = 3.0 * lens.surfaces[-1].semi_aperture_m / grid
    for edge in (x1, -x0, y1, -y0):
        assert expected <= edge <= expected + 2.0 * spacing


def test_exit_pupil_bounds_refuse_a_plane_in_front_of_the_rear_vertex():
    lens = lens_preset("double-gauss", focal_length_m=ILLUM_F_M)
    with pytest.raises(ParameterError, match="plane_z_m"):
        exit_pupil_bounds(lens, plane_z_m=0.0, radii_m=np.array([0.0]))
    with pytest.raises(ParameterError, match="radii_m"):
        exit_pupil_bounds(lens, plane_z_m=-ILLUM_F_M, radii_m=np.array([-1e-3]))


def test_a_medium_without_dispersion_takes_a_numeric_infinity():
    """TOML spells an infinite Abbe number inf, a float; Medium.from_dict refused it ('must be finite')."""
    assert Medium.from_dict({"n_d": 1.5, "v_d": float("inf")}) == Medium.from_dict({"n_d": 1.5, "v_d": "inf"})
    with pytest.raises(ParameterError, match="v_d"):
        Medium.from_dict({"n_d": 1.5, "v_d": float("nan")})
