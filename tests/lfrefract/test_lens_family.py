"""The lens family of scenes/lenses/ (lens files: lfrefract.formats.paramfile) against the designs it copies.

Each file is checked against optiland's own sample of the design (its surfaces, its glasses from
optiland's catalogues, its image surface), independently of the conversion: first-order data from
optiland's paraxial module and real rays from its ray tracer. Then each file is scaled to the Illum's
and the tiny-2x camera's focal length and stopped to their f-numbers, as ``lfsim --lens FILE`` does.
"""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from lfrefract.errors import FileFormatError, ParameterError
from lfrefract.formats.paramfile import read_lens_file, write_lens_file
from lfrefract.optics import RealLensCamera, camera_preset
from lfrefract.optics import lens as lens_module
from lfrefract.optics.lens import D_LINE_M, LensPrescription, trace_lens
from tests.tolerances import LENS_AGREE_DIRECTION_RAD, LENS_AGREE_FIRST_ORDER_RELATIVE, LENS_AGREE_POSITION_M

LENS_DIR = Path(__file__).resolve().parents[2] / "scenes" / "lenses"
#: File stem -> optiland.samples.objectives class it copies.
FAMILY = {
    "cooke-triplet": "CookeTriplet",
    "tessar": "TessarLens",
    "heliar": "HeliarLens",
    "petzval": "PetzvalLens",
    "telephoto": "Telephoto",
    "retrofocus": "ReverseTelephoto",
    "telecentric": "ObjectiveUS008879901",
    "fisheye": "WideAngle170FOV",
}
#: Designs slower than f/2.2: no clear apertures can pass an f/2.2 axial beam through them (their
#: front spheres or element edges are too small; benchmarks/lens_family.py), so their files keep the
#: design's and a camera's f/2 or f/2.2 stop is cut by them (docs/lenses.md, "Lens files").
SLOW = {"cooke-triplet", "tessar", "heliar", "telephoto", "retrofocus"}
ILLUM_F_M = 9.993e-3


@pytest.fixture(scope="module")
def samples():
    """Each design's optiland sample, d line primary: (optic, d-line focal length mm, entrance pupil
    diameter mm, half field deg)."""
    from optiland.samples import objectives

    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # optiland's notes on its material look-ups
        for stem, cls in FAMILY.items():
            op = getattr(objectives, cls)()
            # The design's entrance pupil at its own primary wavelength (optiland's f-number is stated
            # there), the rest at the d line, where the files' first-order data are computed.
            epd = float(np.ravel(op.paraxial.EPD())[0])
            op.wavelengths.add(value=D_LINE_M * 1e6, is_primary=True)
            out[stem] = (op, float(np.ravel(op.paraxial.f2())[0]), epd, float(op.fields.max_field))
    return out


def _design(stem: str) -> LensPrescription:
    return read_lens_file(LENS_DIR / f"{stem}.toml")


def test_the_family_holds_its_designs_and_says_where_each_comes_from():
    assert sorted(p.stem for p in LENS_DIR.glob("*.toml")) == sorted(FAMILY)
    for stem, cls in FAMILY.items():
        lens = _design(stem)
        assert lens.name == stem
        assert f"via optiland 0.6.3 samples, optiland.samples.objectives.{cls} " in lens.source
    # Different designs: no two share their surface count and first-order data.
    signatures = {(len(_design(s).surfaces), round(_design(s).first_order().f_number, 2)) for s in FAMILY}
    assert len(signatures) == len(FAMILY)


@pytest.mark.parametrize("stem", sorted(FAMILY))
def test_first_order_data_agree_with_optiland_sample(samples, stem):
    op, efl_mm, epd_mm, _ = samples[stem]
    p = op.paraxial
    image_gap_mm = float(np.ravel(op.surfaces.surfaces[-2].thickness)[0])  # last vertex to the image surface
    fo = _design(stem).first_order()
    theirs = {
        "efl_m": efl_mm,
        "bfd_m": float(np.ravel(p.F2())[0]) + image_gap_mm,  # optiland: from the image surface
        "entrance_pupil_m": float(np.ravel(p.EPL())[0]),
        "entrance_pupil_diameter_m": epd_mm,
        "exit_pupil_m": float(np.ravel(p.XPL())[0]) + image_gap_mm,
        "f_number": efl_mm / epd_mm,
    }
    for key, value in theirs.items():
        scale = 1.0 if key == "f_number" else 1e-3
        assert getattr(fo, key) == pytest.approx(value * scale, rel=LENS_AGREE_FIRST_ORDER_RELATIVE), key


def _rays_through_the_stop(lens: LensPrescription, half_field_deg: float, count: int, seed: int):
    """Camera-frame rays from a distant scene that cross the stop within 0.9 of its radius, at field
    angles up to 0.9 of the design's half field, starting in front of the lens.

    Made backwards: from random points of the stop in random directions, traced out through the
    surfaces in front of it (towards the object, apertures ignored), kept where they leave within
    the field; a paraxial entrance pupil is no guide at a wide-angle design's field edge.
    """
    fo = lens.first_order()
    stop = lens.stop_index
    rng = np.random.default_rng(seed)
    tries = 100 * count
    radius = 0.9 * lens.surfaces[stop].semi_aperture_m * np.sqrt(rng.uniform(0.0, 1.0, tries))
    psi = rng.uniform(0.0, 2.0 * np.pi, tries)
    x, y = radius * np.cos(psi), radius * np.sin(psi)
    # Directions about the axis out to the paraxial chief ray's stop-space angle at the field edge.
    widest = min(
        math.radians(80.0),
        math.atan(
            math.tan(math.radians(half_field_deg))
            * fo.entrance_pupil_diameter_m
            / (2.0 * lens.surfaces[stop].semi_aperture_m)
        ),
    )
    theta = widest * np.sqrt(rng.uniform(0.0, 1.0, tries))
    phi = rng.uniform(0.0, 2.0 * np.pi, tries)
    # The surfaces in front of the stop, reversed: t' = t_stop - t, radii negated, media swapped.
    t_stop = lens.vertex_t_m[stop]
    curvature = np.array([s.curvature_per_m for s in lens.surfaces])
    origins = np.column_stack([x, y, -lens.surfaces[stop].sag_m(radius)])
    dirs = np.column_stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])
    points, out, *_ = lens_module._trace_design(
        -curvature[:stop][::-1],
        t_stop - lens.vertex_t_m[:stop][::-1],
        np.full(stop, np.inf),
        lens.indices()[: stop + 1][::-1],
        origins,
        dirs,
        False,
    )
    field = np.degrees(np.arccos(np.clip(out[:, 2], -1.0, 1.0)))
    keep = np.flatnonzero(np.isfinite(field) & (field <= 0.9 * half_field_deg))[:count]
    # Forward in the camera frame (design t = z_front - z): the reverse of each ray, from the object side.
    t = t_stop - points[keep, 2]
    d = np.column_stack([-out[keep, 0], -out[keep, 1], -out[keep, 2]])  # camera z = -(design t direction)
    p = np.column_stack([points[keep, 0], points[keep, 1], fo.front_vertex_z_m - t])
    front = lens.surfaces[0]
    start = fo.front_vertex_z_m + max(0.0, -float(front.sag_m(front.semi_aperture_m))) + 0.01 * fo.efl_m
    return p + d * ((start - p[:, 2]) / d[:, 2])[:, None], d


@pytest.mark.parametrize("stem", sorted(FAMILY))
def test_real_rays_agree_with_optiland_sample_on_every_surface_and_the_image(samples, stem):
    from optiland.rays import RealRays

    op, _, _, half_field = samples[stem]
    lens = _design(stem)
    fo = lens.first_order()
    origins, directions = _rays_through_the_stop(lens, half_field, count=200, seed=3)
    assert len(origins) == 200
    mine = trace_lens(lens, origins, directions, record=True)
    ok = mine.passed
    assert ok.mean() > 0.8  # inside the stop and the field: the rims clip only some skew rays
    # optiland's frame: z from the first vertex towards the image (camera -z), millimetres.
    rays = RealRays(
        origins[:, 0] * 1e3,
        origins[:, 1] * 1e3,
        (fo.front_vertex_z_m - origins[:, 2]) * 1e3,
        directions[:, 0],
        directions[:, 1],
        -directions[:, 2],
        np.ones(len(origins)),
        np.full(len(origins), D_LINE_M * 1e6),
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # numba's notes while it compiles optiland's kernels
        op.surfaces.trace(rays)
    g = op.surfaces
    count = len(lens.surfaces)
    theirs = np.stack([np.asarray(g.x), np.asarray(g.y), np.asarray(g.z)], axis=2)[1:]  # (count + 1, N, 3), mm
    theirs = np.concatenate([theirs[..., :2] * 1e-3, fo.front_vertex_z_m - theirs[..., 2:] * 1e-3], axis=2)
    assert np.all(np.asarray(g.intensity)[-1][ok] > 0)  # optiland (no clear apertures) passes them too
    assert mine.surface_points_cam is not None
    assert np.max(np.abs(mine.surface_points_cam[:, ok] - theirs[:count, ok])) < LENS_AGREE_POSITION_M
    # On optiland's image surface: our rays continued from the last surface to its plane.
    image_z = theirs[count, 0, 2]
    s = (image_z - mine.points_cam[ok, 2]) / mine.directions_cam[ok, 2]
    on_image = mine.points_cam[ok] + s[:, None] * mine.directions_cam[ok]
    assert np.max(np.abs(on_image - theirs[count, ok])) < LENS_AGREE_POSITION_M
    last = np.column_stack([np.asarray(g.L)[count], np.asarray(g.M)[count], -np.asarray(g.N)[count]])
    assert np.max(np.abs(mine.directions_cam[ok] - last[ok])) < LENS_AGREE_DIRECTION_RAD
    # Traced back from the image towards the object (as a renderer's camera traces), they retrace their path.
    back = trace_lens(lens, on_image, -mine.directions_cam[ok], toward="object", record=True)
    assert back.passed.all()
    assert back.surface_points_cam is not None
    assert np.max(np.abs(back.surface_points_cam - mine.surface_points_cam[:, ok])) < LENS_AGREE_POSITION_M
    assert np.max(np.abs(back.directions_cam + directions[ok])) < LENS_AGREE_DIRECTION_RAD


def _stop_relative_share(lens: LensPrescription, count: int = 81) -> float:
    """Of a beam parallel to the axis (over 1.2 times the paraxial entrance pupil), the share of the
    rays the stop alone passes (the other clear apertures ignored) that every clear aperture passes."""
    fo = lens.first_order()
    g = np.linspace(-1.2, 1.2, count) * fo.entrance_pupil_diameter_m / 2.0
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    origins = np.column_stack([x, y, np.full(x.size, -fo.efl_m)])  # design frame: t from the first vertex
    dirs = np.tile([0.0, 0.0, 1.0], (x.size, 1))
    curvature = np.array([s.curvature_per_m for s in lens.surfaces])
    semi = np.array([s.semi_aperture_m for s in lens.surfaces])
    stop_only = np.where(np.arange(semi.size) == lens.stop_index, semi, np.inf)
    n = lens.indices()
    through_stop, through_all = (
        lens_module._trace_design(curvature, lens.vertex_t_m, apertures, n, origins, dirs, False)[3] < 0
        for apertures in (stop_only, semi)
    )
    assert through_stop.sum() > 500
    return float(through_all.sum() / through_stop.sum())


@pytest.mark.parametrize("stem", sorted(FAMILY))
def test_each_lens_fits_the_illum_and_the_tiny_2x_camera_and_its_rims_pass_the_design_beam(stem):
    design = _design(stem)
    assert _stop_relative_share(design) == 1.0  # the design's own axial beam: only its stop limits it
    for camera in (camera_preset("illum"), camera_preset("tiny-2x")):
        lens = read_lens_file(LENS_DIR / f"{stem}.toml", focal_length_m=camera.focal_length_m, f_number=camera.f_number)
        fo = lens.first_order()
        assert fo.efl_m == pytest.approx(camera.focal_length_m, rel=1e-12)
        assert fo.f_number == pytest.approx(camera.f_number, rel=1e-12)
        real = RealLensCamera(camera=camera, lens=lens)  # refuses a lens that does not fit the camera
        assert real.image_side_f_number == pytest.approx(camera.f_number, rel=1e-9)
        # Opened to the camera's f-number, a design of f/2.2 or faster passes the whole axial beam; a slower
        # one's rims cut it (its files keep the design's clear apertures), but never below its design beam.
        share = _stop_relative_share(lens)
        if stem in SLOW:
            assert share < 0.9
            assert share * (camera.f_number / design.first_order().f_number) ** -2 > 1.0 - 0.05
        else:
            assert share == 1.0
    assert read_lens_file(LENS_DIR / f"{stem}.toml", focal_length_m=ILLUM_F_M).first_order().efl_m == pytest.approx(
        ILLUM_F_M, rel=1e-12
    )


# ----------------------------------------------------------------------------- the lens-file reader


def _write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


SINGLET = """[lens]
name = "singlet"
source = "a test"
[[lens.surfaces]]
radius_m = 0.05
thickness_m = 0.004
medium = "N-BK7"
semi_aperture_m = 0.01
stop = true
[[lens.surfaces]]
radius_m = -0.05
thickness_m = 0.0
semi_aperture_m = 0.01
"""


def test_a_lens_file_reads_and_writes_in_toml_and_json_alike(tmp_path):
    lens = read_lens_file(_write(tmp_path / "singlet.toml", SINGLET))
    assert lens.name == "singlet"
    assert lens.first_order().efl_m == pytest.approx(0.04904, abs=1e-5)  # docs/lenses.md's singlet
    flat = _write(tmp_path / "flat.toml", SINGLET.replace("radius_m = -0.05", "radius_m = inf"))
    assert math.isinf(read_lens_file(flat).surfaces[1].radius_m)
    for name in ("design.toml", "design.json"):
        design = _design("telecentric")  # every kind of medium: by name, Sellmeier terms, n_d and V_d
        assert read_lens_file(write_lens_file(tmp_path / name, design)) == design
    document = {"schema_version": 1, "lens": lens.to_dict()}  # JSON without a kind, as in other files
    assert read_lens_file(_write(tmp_path / "singlet.lens", json.dumps(document))) == lens


@pytest.mark.parametrize(
    ("name", "text", "fragment"),
    [
        ("lens.toml", SINGLET.replace("radius_m = 0.05", "radius_m = [1]"), "key 'lens.surfaces[0]': radius_m"),
        ("lens.toml", SINGLET.replace('medium = "N-BK7"', 'medium = "unobtainium"'), "key 'lens.surfaces[0]'"),
        ("lens.toml", SINGLET.replace("stop = true", ""), "key 'lens.surfaces': lens 'singlet': exactly one"),
        ("lens.toml", SINGLET.replace('name = "singlet"', 'name = ""'), "key 'lens.name'"),
        ("lens.toml", SINGLET.replace('name = "singlet"', "name = 3"), "key 'lens.name' must be a string"),
        ("lens.toml", SINGLET.replace('name = "singlet"\n', ""), "key 'lens.name' is missing"),
        ("lens.toml", SINGLET.replace("[lens]", "[lens]\nfocal_length_m = 0.05"), "unknown keys ['focal_length_m']"),
        ("lens.toml", "f_number = 2.0\n" + SINGLET, "unknown top-level keys ['f_number']"),
        ("lens.toml", "schema_version = 2\n" + SINGLET, "key 'schema_version' is 2"),
        ("lens.toml", SINGLET + "[[[", "is not valid TOML"),
        ("lens.toml", "schema_version = 1\n", "has no key 'lens'"),
        ("lens.json", SINGLET, "is not valid JSON"),
        ("lens.json", json.dumps({"schema_version": 1, "kind": "lfrefract.lens", "lens": {}, "x": 1}), "['x']"),
    ],
)
def test_a_bad_lens_file_is_refused_naming_the_file_and_the_key(tmp_path, name, text, fragment):
    path = _write(tmp_path / name, text)
    with pytest.raises(FileFormatError, match=str(path).replace(".", r"\.")) as info:
        read_lens_file(path)
    assert fragment in str(info.value)


def test_a_missing_lens_file_and_a_folder_are_named(tmp_path):
    with pytest.raises(FileFormatError, match="no such file"):
        read_lens_file(tmp_path / "none.toml")
    (tmp_path / "dir.toml").mkdir()
    with pytest.raises(FileFormatError, match="is a directory"):
        read_lens_file(tmp_path / "dir.toml")


def test_a_lens_that_cannot_be_stopped_as_asked_names_the_file(tmp_path):
    path = _write(tmp_path / "singlet.toml", SINGLET)
    with pytest.raises(ParameterError, match=f"lens file {str(path)!r}: lens 'singlet': f_number=0.1"):
        read_lens_file(path, f_number=0.1)
