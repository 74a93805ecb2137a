"""The lens family of ``scenes/lenses/``: convert it from optiland's samples, and print its first-order data.

Eight published main-lens designs of different families, none of which the project was designed
around, as lens files (:func:`lfrefract.formats.paramfile.read_lens_file`): the radii, thicknesses, glasses and
stop of each sample exactly as optiland 0.6.3 (a test dependency) tabulates it. What the sources
do not tabulate is derived here:

* clear semi-apertures: the height on each surface of the real meridional beams (d line) that fill
  the stop at fields from 0 to the design's half field, in steps of at most 0.25 deg, each field
  aimed from the last (:func:`lfrefract.optics.lens._aim_meridional`), plus 2 % rounded up to four
  significant digits; the stop is sized for the design's entrance pupil (its f-number);
* glasses: a SCHOTT glass of :data:`lfrefract.optics.lens.GLASSES` by name; another glass that
  optiland gives by Sellmeier terms (refractiveindex.info formula 2, no constant term, all C >= 0)
  by those terms; any other (a polynomial formula) by ``n_d`` and ``V_d`` from optiland's indices
  at the d, F and C lines.

    python benchmarks/lens_family.py --write     # (re)write scenes/lenses/*.toml from optiland
    python benchmarks/lens_family.py             # first-order data of the files at tiny-2x

The report gives, for each file scaled to the camera's focal length and stopped to its f-number:
entrance and exit pupil z and the front vertex z (camera frame: rear principal plane at z = 0),
total track, the chief-ray angle at the image plane (MLA at z = -f) at the edge and the corner of the
sensor (paraxial, and the real chief ray aimed through the stop centre with the clear apertures
ignored; "vign." where the clear apertures stop that real chief ray), and the share of a beam
filling the paraxial entrance pupil on the axis that passes every clear aperture.
"""

from __future__ import annotations

import argparse
import math
import sys
import warnings
from dataclasses import replace
from decimal import Decimal
from pathlib import Path

import numpy as np

from lfrefract.formats.paramfile import read_lens_file
from lfrefract.optics import camera_preset
from lfrefract.optics import lens as lens_module
from lfrefract.optics.lens import (
    C_LINE_M,
    D_LINE_M,
    F_LINE_M,
    GLASSES,
    LensPrescription,
    Medium,
    Surface,
    trace_lens,
)

LENS_DIR = Path(__file__).resolve().parent.parent / "scenes" / "lenses"
OPTILAND = "optiland 0.6.3 samples"

#: File name -> (optiland class in optiland.samples.objectives, family, where optiland says it is from,
#: the unit optiland's numbers are in).
FAMILY = {
    "cooke-triplet": ("CookeTriplet", "Cooke triplet", "optiland names no source", "mm"),
    "tessar": ("TessarLens", "Tessar", "M. Laikin, Lens Design, 4th ed. (CRC Press, 2007), p. 63", "mm"),
    "heliar": ("HeliarLens", "Heliar", "M. Laikin, Lens Design, 4th ed. (CRC Press, 2007), p. 63", "mm"),
    "petzval": ("PetzvalLens", "Petzval", "M. Laikin, Lens Design, 4th ed. (CRC Press, 2007), p. 75", "inch"),
    "telephoto": ("Telephoto", "telephoto", "M. Laikin, Lens Design, 4th ed. (CRC Press, 2007), p. 91", "inch"),
    "retrofocus": ("ReverseTelephoto", "retrofocus (reverse telephoto)", "optiland names no source", "mm"),
    "telecentric": (
        "ObjectiveUS008879901",
        "nearly image-side telecentric objective",
        "U.S. Patent 8,879,901",
        "mm",
    ),
    "fisheye": ("WideAngle170FOV", "fisheye", "M. Laikin, Lens Design, 4th ed. (CRC Press, 2007), p. 114", "mm"),
}
MARGIN = 0.02  # clear apertures: the beams' heights plus 2 %
FIELD_STEP_DEG = 0.25  # the fisheye's beams cannot be aimed from one field to the next in larger steps


def _exact_m(value: float, unit: str) -> Decimal:
    """A table length in metres, exactly as tabulated: optiland's mm, or the inches it scaled by 25.4."""
    if unit == "inch":
        inches = Decimal(repr(round(value / 25.4, 6)))
        if abs(float(inches) * 25.4 - value) > 1e-9 * max(1.0, abs(value)):
            raise ValueError(f"{value!r} mm is not a tabulated length in inches")
        return inches * Decimal("0.0254")
    return Decimal(repr(value)) / 1000


def _medium(material) -> Medium:
    """The project's medium for an optiland material (see the module docstring)."""
    if type(material).__name__ == "IdealMaterial":
        if float(np.ravel(material.n(0.5876))[0]) != 1.0:
            raise ValueError("an ideal material other than air")
        return Medium.air()
    catalogue = Path(material.filename).parent.name
    label = f"{material.name} ({catalogue.upper()})"
    coefficients = [float(np.ravel(c)[0]) for c in material.coefficients]
    b, c = tuple(coefficients[1::2]), tuple(coefficients[2::2])
    if material._n_formula == "formula 2" and coefficients[0] == 0.0 and all(x >= 0.0 for x in c):
        if catalogue == "schott" and GLASSES.get(material.name) == (b, c):
            return Medium.named(material.name)
        return Medium.sellmeier(b=b, c_um2=c, name=label)
    n_d, n_f, n_c = (float(np.ravel(material.n(w * 1e6))[0]) for w in (D_LINE_M, F_LINE_M, C_LINE_M))
    return Medium.abbe(n_d=n_d, v_d=(n_d - 1.0) / (n_f - n_c), name=label)


def optiland_sample(key: str):
    """The optiland sample of ``key``."""
    from optiland.samples import objectives

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return getattr(objectives, FAMILY[key][0])()


def design_of(op) -> tuple[float, float, float]:
    """Effective focal length and entrance pupil diameter (optiland's units) and half field (deg) of a sample."""
    paraxial = op.paraxial
    efl = float(np.ravel(paraxial.f2())[0])
    epd = float(np.ravel(paraxial.EPD())[0])
    return efl, epd, float(op.fields.max_field)


def convert(key: str) -> tuple[LensPrescription, list[tuple[Decimal, Decimal]], float]:
    """The lens of ``key`` (metres), its radii and thicknesses as exact decimals, and its half field (deg)."""
    cls, family, source, unit = FAMILY[key]
    op = optiland_sample(key)
    efl, epd, half_field = design_of(op)
    rows = op.surfaces.surfaces[1:-1]
    exact, surfaces = [], []
    for i, s in enumerate(rows):
        radius = float(np.ravel(s.geometry.radius)[0])
        thickness = 0.0 if i == len(rows) - 1 else float(np.ravel(s.thickness)[0])
        r_m = Decimal("Infinity") if math.isinf(radius) else _exact_m(radius, unit)
        t_m = _exact_m(thickness, unit)
        exact.append((r_m, t_m))
        surfaces.append(
            Surface(
                radius_m=float(r_m),
                thickness_m=float(t_m),
                medium=_medium(s.material_post),
                semi_aperture_m=efl * 1e-8,  # provisional, to compute the first-order data
                stop=bool(s.is_stop),
            )
        )
    units = {"mm": "mm", "inch": "inches scaled to mm by optiland"}[unit]
    described = (
        f"{family}: {source}; via {OPTILAND}, optiland.samples.objectives.{cls} (lengths as optiland "
        f"tabulates them, in {units}); clear apertures fitted to its {half_field:g} deg half field"
    )
    draft = LensPrescription(name=key, source=described, surfaces=tuple(surfaces))
    draft = draft.with_f_number(draft.first_order().efl_m / (epd * 1e-3))
    fields = np.deg2rad(np.linspace(0.0, half_field, math.ceil(half_field / FIELD_STEP_DEG) + 1))
    need = lens_module._aim_meridional(draft, fields, np.linspace(-1.0, 1.0, 21)).max(axis=(1, 2)) * (1.0 + MARGIN)
    fitted = []
    for s, h in zip(draft.surfaces, need, strict=True):
        if s.stop:
            fitted.append(s)
            continue
        digits = 3 - math.floor(math.log10(h))
        fitted.append(replace(s, semi_aperture_m=math.ceil(h * 10**digits) / 10**digits))
    return replace(draft, surfaces=tuple(fitted)), exact, half_field


def _toml_medium(medium: Medium) -> str:
    data = medium.to_dict()
    if isinstance(data, str):
        return f'"{data}"'
    if "n_d" in data:
        return f'{{ name = "{data["name"]}", n_d = {data["n_d"]!r}, v_d = {data["v_d"]!r} }}'
    b = ", ".join(repr(x) for x in data["sellmeier_b"])
    c = ", ".join(repr(x) for x in data["sellmeier_c_um2"])
    return f'{{ name = "{data["name"]}", sellmeier_b = [{b}], sellmeier_c_um2 = [{c}] }}'


def lens_file_text(lens: LensPrescription, exact: list[tuple[Decimal, Decimal]], half_field: float) -> str:
    """The TOML lens file of ``lens`` (radii and thicknesses written as the exact decimals)."""
    first = lens.first_order()
    lines = [
        f"# {lens.name}: a main-lens design as a lens file (docs/lenses.md, 'Lens files').",
        f"# As tabulated: f = {first.efl_m * 1e3:.4f} mm, f/{first.f_number:.3g}, {half_field:g} deg half field.",
        "# Lengths in metres. Written by benchmarks/lens_family.py --write from optiland's sample.",
        "schema_version = 1",
        "",
        "[lens]",
        f'name = "{lens.name}"',
        f'source = "{lens.source}"',
    ]
    for i, (s, (r_m, t_m)) in enumerate(zip(lens.surfaces, exact, strict=True)):
        lines += ["", f"[[lens.surfaces]]  # {i}{' (stop)' if s.stop else ''}"]
        lines.append(f"radius_m = {'inf' if r_m.is_infinite() else format(r_m.normalize(), 'f')}")
        lines.append(f"thickness_m = {format(t_m.normalize(), 'f') if t_m else '0.0'}")
        lines.append(f"medium = {_toml_medium(s.medium)}")
        lines.append(f"semi_aperture_m = {s.semi_aperture_m!r}")
        if s.stop:
            lines.append("stop = true")
    return "\n".join(lines) + "\n"


def write_family() -> None:
    """(Re)write ``scenes/lenses/<name>.toml`` for every design of :data:`FAMILY`, each read back and checked."""
    LENS_DIR.mkdir(exist_ok=True)
    for key in FAMILY:
        lens, exact, half_field = convert(key)
        path = LENS_DIR / f"{key}.toml"
        path.write_text(lens_file_text(lens, exact, half_field), encoding="utf-8")
        back = read_lens_file(path)
        if back != lens:
            raise SystemExit(f"{path}: reads back as another lens")
        print(f"wrote {path}")


def _chief_ray_angle_deg(lens: LensPrescription, image_height_m: float) -> tuple[float, bool]:
    """Angle to the axis at the image plane (the rear focal plane) of the real meridional chief ray
    (through the stop's centre) landing at ``image_height_m``, clear apertures ignored, and whether
    the clear apertures pass it."""
    first = lens.first_order()
    curvature = np.array([s.curvature_per_m for s in lens.surfaces])
    vertex_t = lens.vertex_t_m
    n = lens.indices()
    stop = lens.stop_index
    unlimited = np.full(len(curvature), np.inf)
    t_image = first.total_track_m + first.bfd_m
    t0 = -first.total_track_m - abs(first.entrance_pupil_m)

    def trace(angle: float) -> tuple[float, float, np.ndarray]:
        # Aim through the stop centre: Newton steps on the height at the first vertex plane.
        y1, step = -first.entrance_pupil_m * math.tan(angle), 1e-9 * first.efl_m
        for _ in range(50):
            both = np.array([y1, y1 + step])
            origins = np.column_stack([np.zeros(2), both + t0 * math.tan(angle), np.full(2, t0)])
            dirs = np.tile([0.0, math.sin(angle), math.cos(angle)], (2, 1))
            pts, d, _, _, sp = lens_module._trace_design(curvature, vertex_t, unlimited, n, origins, dirs, True)
            f0, f1 = sp[stop, 0, 1], sp[stop, 1, 1]
            if not (np.isfinite(f0) and np.isfinite(f1)):
                return math.nan, math.nan, sp
            if abs(f0) < 1e-13 * first.efl_m:
                break
            y1 -= f0 / ((f1 - f0) / step)
        height = pts[0, 1] + (t_image - pts[0, 2]) * d[0, 1] / d[0, 2]
        return float(height), float(math.atan2(d[0, 1], d[0, 2])), sp[:, 0, :]

    # Secant on the object-space angle for the image height (heights are negative: an inverted image).
    a0 = math.atan(image_height_m / first.efl_m)
    a1 = 1.01 * a0
    h0, _, _ = trace(a0)
    h1, _, _ = trace(a1)
    for _ in range(60):
        if not (np.isfinite(h0) and np.isfinite(h1)) or h1 == h0:
            return math.nan, False
        a0, a1, h0 = a1, a1 - (h1 + image_height_m) * (a1 - a0) / (h1 - h0), h1
        h1, angle, points = trace(a1)
        if np.isfinite(h1) and abs(h1 + image_height_m) < 1e-12:
            break
    if not np.isfinite(h1):
        return math.nan, False
    semi = np.array([s.semi_aperture_m for s in lens.surfaces])
    passes = bool(np.all(np.abs(points[:, 1]) <= semi))
    return abs(math.degrees(angle)), passes


def axial_f_number(lens: LensPrescription, count: int = 301) -> float:
    """Working f-number of the axial beam: the effective focal length over the diameter of the disc of
    the same area as the part of a beam parallel to the axis that passes every clear aperture (a
    square grid of ``count`` x ``count`` rays over 1.5 times the paraxial entrance pupil). It is the
    paraxial f-number where only the stop limits the beam (to the stop's pupil aberration), and larger
    where other clear apertures cut the axial beam."""
    first = lens.first_order()
    half = 1.5 * first.entrance_pupil_diameter_m / 2.0
    g = np.linspace(-half, half, count)
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    origins = np.column_stack([x, y, np.full(x.size, first.front_vertex_z_m + first.efl_m)])
    passed = trace_lens(lens, origins, np.tile([0.0, 0.0, -1.0], (x.size, 1))).passed
    area = passed.sum() * (g[1] - g[0]) ** 2
    return first.efl_m / (2.0 * math.sqrt(area / math.pi))


def report(camera_name: str) -> None:
    camera = camera_preset(camera_name)
    half_w = camera.sensor.width_px * camera.sensor.pixel_pitch_m / 2.0
    half_d = math.hypot(half_w, camera.sensor.height_px * camera.sensor.pixel_pitch_m / 2.0)
    f, big_n = camera.focal_length_m, camera.f_number
    size = f"sensor half width {half_w * 1e3:g} mm, corner {half_d * 1e3:g} mm"
    print(f"{camera_name}: f = {f * 1e3:g} mm, f/{big_n:g}; {size}")
    print(
        "lens            design f  f/#   field  EP z mm   XP z mm   track mm  front z mm  CRA edge par/real deg   "
        f"CRA corner par/real deg   axial beam's working f/# stopped to design, f/{big_n:g}, f/2"
    )
    for key in FAMILY:
        design = read_lens_file(LENS_DIR / f"{key}.toml")
        d = design.first_order()
        lens = read_lens_file(LENS_DIR / f"{key}.toml", focal_length_m=f, f_number=big_n)
        fo = lens.first_order()
        field = design_of(optiland_sample(key))[2]
        cells = []
        for h in (half_w, half_d):
            paraxial = math.degrees(math.atan(h / (fo.exit_pupil_z_m + f)))
            real, passes = _chief_ray_angle_deg(lens, h)
            shown = " none" if math.isnan(real) else f"{real:5.2f}"
            cells.append(f"{paraxial:5.2f} / {shown}{'' if passes else ' vign.'}")
        share = axial_f_number(design), axial_f_number(lens), axial_f_number(design.with_f_number(2.0))
        print(
            f"{key:15s} {d.efl_m * 1e3:8.3f} {d.f_number:5.2f} {field:6.2f} {fo.entrance_pupil_z_m * 1e3:8.3f} "
            f"{fo.exit_pupil_z_m * 1e3:9.3f} {fo.total_track_m * 1e3:9.3f} {fo.front_vertex_z_m * 1e3:10.3f}  "
            f"{cells[0]:>22s}   {cells[1]:>22s}   f/{share[0]:.2f}  f/{share[1]:.2f}  f/{share[2]:.2f}"
        )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--write", action="store_true", help="(re)write scenes/lenses/*.toml from optiland's samples")
    parser.add_argument("--camera", default="tiny-2x", help="camera preset of the report")
    args = parser.parse_args(argv)
    if args.write:
        write_family()
    report(args.camera)
    return 0


if __name__ == "__main__":
    sys.exit(main())
