"""Water as a physical medium (``[water]``): the index of sea water and where it goes, the
errors, and renders through absorbing and scattering water against Beer-Lambert and a
single-scattering quadrature."""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest

from lfrefract import ParameterError, seawater_index, virtual_camera_for
from lfrefract.formats.jsonio import read_json
from simulator import groundtruth
from simulator.config import RenderSettings, SceneConfig, Water, parse_scene, read_toml
from simulator.job import render_job, render_raw
from simulator.lighting import EVERY_EMITTER
from simulator.rig import embedded_rigs, parse_rig
from simulator.scene import build_scene, check_geometry, integrator, water_medium
from simulator.sensor import plenoptic_sensor_dict
from tests.tolerances import FLOAT64_UNIT, WATER_BEER_LAMBERT_RELATIVE, WATER_INDEX_ABS, WATER_VEIL_RELATIVE

# ----------------------------------------------------------------------------- the index of sea water
# (salinity psu, temperature C, wavelength nm, n relative to air). C. D. Mobley, "The optical
# properties of water", Handbook of Optics, 3rd ed., Vol. IV, ch. 1 (McGraw-Hill, 2010): the table of
# n(S, T, lambda) after R. W. Austin and G. Halikas, "The index of refraction of seawater", SIO Ref.
# 76-1 (1976), the data that Quan and Fry fitted; values as transcribed from that table in
# C. Parrish's water_ior repository (github.com/hokiespurs/water_ior, mobley_table_*.xlsx).
MOBLEY_2010 = [
    (0.0, 0.0, 400.0, 1.34419),
    (0.0, 20.0, 400.0, 1.34317),
    (0.0, 10.0, 500.0, 1.33714),
    (0.0, 20.0, 600.0, 1.33267),
    (0.0, 0.0, 700.0, 1.33108),
    (0.0, 30.0, 700.0, 1.32913),
    (35.0, 0.0, 400.0, 1.35141),
    (35.0, 20.0, 400.0, 1.34994),
    (35.0, 10.0, 500.0, 1.34385),
    (35.0, 20.0, 600.0, 1.33904),
    (35.0, 0.0, 700.0, 1.33791),
    (35.0, 30.0, 700.0, 1.33532),
]
# Distilled water at the sodium D line (589.3 nm), four decimals: L. W. Tilton and J. K. Taylor,
# "Refractive index and dispersion of distilled water for visible radiation, at temperatures 0 to
# 60 C", J. Res. Natl. Bur. Stand. 20, 419 (1938).
TILTON_TAYLOR_1938 = [(10.0, 1.3337), (20.0, 1.3330), (30.0, 1.3319)]


@pytest.mark.parametrize(("salinity", "temperature", "wavelength", "n"), MOBLEY_2010)
def test_index_matches_the_austin_halikas_table(salinity, temperature, wavelength, n):
    water = Water(salinity_psu=salinity, temperature_c=temperature, wavelength_nm=wavelength)
    assert abs(water.n_water - n) <= WATER_INDEX_ABS
    assert water.n_water == seawater_index(salinity_psu=salinity, temperature_c=temperature, wavelength_nm=wavelength)


@pytest.mark.parametrize(("temperature", "n"), TILTON_TAYLOR_1938)
def test_index_of_fresh_water_at_the_default_wavelength_matches_tilton_and_taylor(temperature, n):
    water = Water(salinity_psu=0.0, temperature_c=temperature)
    assert water.wavelength_nm == 589.3
    assert abs(water.n_water - n) <= WATER_INDEX_ABS


def test_salt_and_cold_raise_the_index():
    def n(s, t):
        return seawater_index(salinity_psu=s, temperature_c=t)

    assert n(35.0, 20.0) - n(0.0, 20.0) == pytest.approx(0.0064, abs=2e-4)  # the table's 1.33904 - 1.33267
    assert n(0.0, 5.0) > n(0.0, 25.0)


# ----------------------------------------------------------------------------- [water] in the scene file
LIGHT = {"type": "point", "position_m": [0.12, -0.15, 0.08], "intensity_w_sr": 0.3}
PORT = {"distance_m": 0.02, "thickness_m": 0.006, "tilt_x_deg": 15.0}
SEA = {"salinity_psu": 35.0, "temperature_c": 20.0}


def _data(**tables) -> dict:
    data = {"camera": {"preset": "tiny"}, "light": [LIGHT], "port": dict(PORT)}
    data.update(tables)
    return {k: v for k, v in data.items() if v is not None}


def test_the_index_of_the_water_reaches_the_port_the_sensor_and_the_sidecar(mi):
    config = parse_scene(_data(water=SEA))
    n = seawater_index(salinity_psu=35.0, temperature_c=20.0)
    assert config.water.n_water == n
    assert config.port.n_water == n  # FlatPort: the sensor's refraction, ground truth, synthesis
    assert config.to_dict()["port"]["n_water"] == n
    assert config.to_dict()["water"]["n_water"] == n
    sensor = plenoptic_sensor_dict(mi, config.camera, config.pose, spp=1, port=config.port)
    assert sensor["port_n_water"] == n
    # Without [water], or with turbidity only, the port keeps its own index.
    assert parse_scene(_data()).port.n_water == 1.333
    assert parse_scene(_data(water={"absorption_per_m": 0.1})).port.n_water == 1.333


def test_a_port_index_within_the_tolerance_is_replaced_by_the_computed_one():
    n = seawater_index(salinity_psu=35.0, temperature_c=20.0)
    config = parse_scene(_data(port=PORT | {"n_water": round(n, 4)}, water=SEA))
    assert config.port.n_water == n


def test_the_index_relative_to_air_is_scaled_by_the_ports_n_air():
    # Quan and Fry's index is relative to air; refraction depends on n_water / n_air. A port whose
    # indices are relative to vacuum (n_air = 1.0003) took the air-relative index as it was: a ratio
    # 3e-4 off, three times N_WATER_TOLERANCE, accepted silently.
    n = seawater_index(salinity_psu=35.0, temperature_c=20.0)
    config = parse_scene(_data(port=PORT | {"n_air": 1.0003}, water=SEA))
    assert config.port.n_water / config.port.n_air == pytest.approx(n, rel=FLOAT64_UNIT)
    assert config.water.n_water == n  # the table's own index stays relative to air
    with pytest.raises(ParameterError, match=r"port.n_water=1.3394\d* conflicts"):
        parse_scene(_data(port=PORT | {"n_air": 1.0003, "n_water": round(n, 4)}, water=SEA))
    # Programmatic configs are held to the same rule.
    air = dataclasses.replace(config.port, n_air=1.0)
    with pytest.raises(ParameterError, match=r"conflicts with the index of the water"):
        config.with_overrides(port=air)
    assert config.with_overrides(port=dataclasses.replace(air, n_water=n)).port.n_water == n
    rig = read_toml(embedded_rigs()["default"], "rig")
    wall = {k: v for k, v in rig["wall"].items() if k != "n_water"} | {"n_air": 1.0003}
    for camera in parse_rig(rig | {"wall": wall, "water": SEA}).cameras:
        assert camera.scene.port.n_water / camera.scene.port.n_air == pytest.approx(n, rel=FLOAT64_UNIT)


def test_a_conflicting_port_index_is_refused_naming_both():
    with pytest.raises(ParameterError) as err:
        parse_scene(_data(port=PORT | {"n_water": 1.333}, water=SEA))
    message = str(err.value)
    assert "port.n_water=1.333" in message
    assert "n_water=1.339406" in message
    assert "salinity_psu=35.0" in message
    # Programmatic configs are held to the same rule.
    config = parse_scene(_data(water=SEA))
    with pytest.raises(ParameterError, match=r"port.n_water=1.333 conflicts"):
        config.with_overrides(port=dataclasses.replace(config.port, n_water=1.333))
    with pytest.raises(ParameterError, match=r"conflicts with the index of the water"):
        parse_scene(_data()).with_overrides(water=Water(salinity_psu=35.0, temperature_c=5.0))


@pytest.mark.parametrize(
    ("table", "message"),
    [
        ({"salinity_psu": 36.0, "temperature_c": 20.0}, "water.salinity_psu=36.0 is outside"),
        ({"salinity_psu": -0.5, "temperature_c": 20.0}, "water.salinity_psu=-0.5 is outside"),
        ({"salinity_psu": 10.0, "temperature_c": 31.0}, "water.temperature_c=31.0 is outside"),
        ({"salinity_psu": 10.0, "temperature_c": -2.0}, "water.temperature_c=-2.0 is outside"),
        ({"salinity_psu": 10.0, "temperature_c": 5.0, "wavelength_nm": 380.0}, "water.wavelength_nm=380.0 is outside"),
        ({"salinity_psu": 10.0, "temperature_c": 5.0, "wavelength_nm": 701.0}, "water.wavelength_nm=701.0 is outside"),
        ({"salinity_psu": float("nan"), "temperature_c": 5.0}, "water.salinity_psu must be finite, got nan"),
    ],
)
def test_values_outside_the_equations_ranges_are_refused(table, message):
    with pytest.raises(ParameterError) as err:
        parse_scene(_data(water=table))
    assert message in str(err.value)


@pytest.mark.parametrize(
    ("table", "message"),
    [
        ({"turbidity": 1.0}, "unknown key(s) in water: ['turbidity']"),
        ({"n_water": 1.34}, "unknown key(s) in water: ['n_water']"),
        ({"salinity_psu": 35.0}, "water.salinity_psu and water.temperature_c go together"),
        ({"temperature_c": 12.0}, "water.salinity_psu and water.temperature_c go together"),
        ({"wavelength_nm": 500.0}, "water.wavelength_nm=500.0 is the wavelength of the index"),
        ({"absorption_per_m": -0.1}, "water.absorption_per_m[0] must be non-negative, got -0.1"),
        ({"scattering_per_m": [0.1, 0.2]}, "water.scattering_per_m must have 3 entries"),
        ({"scattering_per_m": [0.1, float("inf"), 0.2]}, "water.scattering_per_m[1] must be finite"),
        ({"phase_g": 1.0}, "water.phase_g must lie in (-1, 1), got 1.0"),
        ({"phase_g": "forward"}, "water.phase_g must be a real number, got 'forward'"),
        (3.0, "[water] must be a table, got 3.0"),
    ],
)
def test_malformed_water_tables_are_refused_by_name(table, message):
    with pytest.raises(ParameterError) as err:
        parse_scene(_data(water=table))
    assert message in str(err.value)


@pytest.mark.parametrize(
    ("table", "channels"),
    [
        ({"absorption_per_m": [2.0, 1.0, 0.0]}, "[2]"),
        ({"scattering_per_m": [1.0, 1.0, 0.0]}, "[2]"),
        ({"absorption_per_m": [0.0, 0.0, 0.3], "scattering_per_m": [0.0, 0.0, 0.2]}, "[0, 1]"),
    ],
)
def test_a_channel_without_extinction_beside_turbid_ones_is_refused(table, channels):
    # Mitsuba's volpath divides by every channel's extinction at each interaction in the medium:
    # one channel at 0 beside a positive one rendered every pixel NaN (measured: 97-100 % of the
    # ideal image of the lamp scene). Refused by name, not repaired.
    with pytest.raises(ParameterError) as err:
        parse_scene(_data(water=table))
    message = str(err.value)
    assert f"channel(s) {channels}" in message
    assert "water.absorption_per_m" in message
    # All channels positive, or all zero (clear), stay allowed.
    assert parse_scene(_data(water={"absorption_per_m": [2.0, 1.0, 1e-3]})).water.has_medium
    assert not parse_scene(_data(water={"absorption_per_m": 0.0, "scattering_per_m": 0.0})).water.has_medium


def test_an_environment_light_cannot_reach_into_turbid_water():
    data = {"camera": {"preset": "tiny"}, "light": [{"type": "constant", "radiance": 1.0}]}
    assert parse_scene(data | {"water": {"absorption_per_m": 0.0}}).water is not None  # clear: allowed
    with pytest.raises(ParameterError, match=r"constant .* light lies at infinity"):
        parse_scene(data | {"water": {"scattering_per_m": 0.2}})


def test_the_rig_has_one_water_for_every_camera():
    data = read_toml(embedded_rigs()["default"], "rig")
    with pytest.raises(ParameterError, match=r"wall.n_water=1.333 conflicts"):
        parse_rig(data | {"water": SEA})
    wall = {k: v for k, v in data["wall"].items() if k != "n_water"}
    rig = parse_rig(data | {"wall": wall, "water": SEA | {"absorption_per_m": [0.3, 0.05, 0.02]}})
    n = seawater_index(salinity_psu=35.0, temperature_c=20.0)
    assert rig.wall.n_water == n
    assert rig.water.n_water == n
    for camera in rig.cameras:
        assert camera.scene.port.n_water == n
        assert camera.scene.water == rig.water
    assert parse_rig(data).water is None


# ----------------------------------------------------------------------------- the Mitsuba medium
def test_clear_water_keeps_the_integrators_of_clear_scenes():
    port = parse_scene(_data()).port
    for water in (None, Water(), Water(absorption_per_m=0.0, scattering_per_m=0.0, phase_g=0.7), Water(**SEA)):
        assert water_medium(water) is None
        assert integrator(None, water=water) == {"type": EVERY_EMITTER, "max_delta_depth": 0, "hide_emitters": False}
        assert integrator(port, water=water) == {"type": EVERY_EMITTER, "max_delta_depth": 2, "hide_emitters": False}


def test_turbid_water_is_a_homogeneous_medium_with_volpath():
    water = Water(absorption_per_m=[2.0, 0.5, 0.1], scattering_per_m=0.5, phase_g=0.8)
    medium = water_medium(water)
    sigma_t = np.asarray(medium["sigma_t"]["value"]) * medium["scale"]
    np.testing.assert_allclose(sigma_t, [2.5, 1.0, 0.6], rtol=1e-12)
    np.testing.assert_allclose(medium["albedo"]["value"], [0.2, 0.5, 0.5 / 0.6], rtol=1e-12)
    assert medium["phase"] == {"type": "hg", "g": 0.8}
    assert water_medium(Water(scattering_per_m=1.0)) == {
        "type": "homogeneous",
        "sigma_t": 1.0,
        "scale": 1.0,
        "albedo": 1.0,
        "phase": {"type": "isotropic"},
    }
    port = parse_scene(_data()).port
    assert integrator(None, water=water) == {"type": "volpath", "max_depth": 2, "rr_depth": 3, "hide_emitters": False}
    assert integrator(port, water=water) == {"type": "volpath", "max_depth": 4, "rr_depth": 5, "hide_emitters": False}


# ----------------------------------------------------------------------------- renders
# A slanted disc (35 deg about y) half a metre away, filling the view: lines of sight from 0.40 to
# 0.75 m long.
DISC = {"type": "disc", "position_m": [0.0, 0.0, 0.5], "rotation_xyz_deg": [0.0, 35.0, 0.0], "radius_m": 0.5}
SIGMA_A = np.array([2.0, 1.0, 0.5])  # per metre, red absorbed most, as in water


def _disc_scene(kind: str, *, port: bool, water: dict | None, model: str = "sensor", spp: int = 16) -> SceneConfig:
    """The slanted disc, luminous (``emitter``, lit by nothing else) or diffuse and lit by the point light."""
    if kind == "emitter":
        objects = [DISC | {"radiance": 1.0, "reflectance": 0.0}]
        lights = [LIGHT | {"intensity_w_sr": 0.0}]
    else:
        objects = [DISC | {"reflectance": 0.8}]
        lights = [LIGHT]
    data = {
        "camera": {"preset": "tiny"},
        "render": {"spp": spp, "seed": 3, "port_model": model},
        "light": lights,
        "object": objects,
        "port": PORT if port else None,
        "water": water,
    }
    config = parse_scene({k: v for k, v in data.items() if v is not None})
    check_geometry(config)  # everything in the water
    return config


def _light_leg(points: np.ndarray, kind: str) -> np.ndarray:
    """Length (m) of the light-to-surface leg for each surface point (N, 3): 0 for the emitter."""
    if kind == "emitter":
        return np.zeros(len(points))
    return np.linalg.norm(points - np.asarray(LIGHT["position_m"]), axis=1)


def _assert_beer_lambert(clear: np.ndarray, turbid: np.ndarray, path_m: np.ndarray) -> None:
    """Per quartile of path length and per channel: turbid / clear radiance against the mean of
    exp(-sigma_a * path) weighted like the clear radiance (pixels (N, 3), paths (N,) in metres)."""
    ok = np.isfinite(path_m) & (clear.sum(axis=1) > 0.0)
    edges = np.quantile(path_m[ok], [0.0, 0.25, 0.5, 0.75, 1.0])
    assert edges[-1] - edges[0] > 0.2  # the paths differ enough for exp(-sigma * path) to vary
    for lo, hi in itertools.pairwise(edges):
        m = ok & (path_m >= lo) & (path_m <= hi)
        measured = turbid[m].sum(axis=0) / clear[m].sum(axis=0)
        expected = (clear[m] * np.exp(-path_m[m, None] * SIGMA_A)).sum(axis=0) / clear[m].sum(axis=0)
        np.testing.assert_allclose(measured, expected, rtol=WATER_BEER_LAMBERT_RELATIVE)


@pytest.mark.render
@pytest.mark.parametrize("kind", ["emitter", "point"])
def test_beer_lambert_in_the_ideal_image(mi, kind):
    images = {}
    for water in (None, {"absorption_per_m": SIGMA_A.tolist()}):
        config = _disc_scene(kind, port=False, water=water)
        pinhole = virtual_camera_for(config.camera)
        scene = build_scene(mi, config, port_geometry=False)
        truth = groundtruth.compute(mi, scene, config, pinhole, spp=64, seed=3, progress=False)
        images[water is None] = truth
    # Path length per pixel from the depth ground truth: the pinhole sits in the water.
    directions = pinhole.pixel_directions()
    depth = images[True].depth_m.reshape(-1).astype(np.float64)
    np.testing.assert_array_equal(depth, images[False].depth_m.reshape(-1))  # depth stays geometric
    points = directions / directions[:, 2:] * depth[:, None]
    path = np.linalg.norm(points, axis=1) + _light_leg(points, kind)
    _assert_beer_lambert(images[True].ideal.reshape(-1, 3), images[False].ideal.reshape(-1, 3), path)


def _raw_water_path(mi, config: SceneConfig, kind: str) -> np.ndarray:
    """Water path (m) of every raw pixel's captured ray (pixel centre through its microlens centre):
    from the port's water face to the first surface, traced in the glass-free scene like the depth
    ground truth, plus the light leg. NaN where the ray is vignetted or does not get through."""
    camera, port = config.camera, config.port
    rays = camera.captured_rays()
    trace = port.trace_from_air(rays.origins_cam, rays.directions_cam)
    ok = rays.in_aperture & trace.valid
    origins, directions = trace.exit_points_cam[ok], trace.directions_cam[ok]  # identity pose: world
    scene = build_scene(mi, config, port_geometry=False)
    ray = mi.Ray3f(mi.Point3f(origins.T.astype(np.float32)), mi.Vector3f(directions.T.astype(np.float32)))
    si = scene.ray_intersect(ray)
    t = np.where(np.asarray(si.is_valid(), dtype=bool), np.asarray(si.t, dtype=np.float64), np.nan)
    path = np.full(len(ok), np.nan)
    path[ok] = t + _light_leg(origins + t[:, None] * directions, kind)
    return path


@pytest.mark.render
@pytest.mark.parametrize(("model", "kind"), [("sensor", "emitter"), ("sensor", "point"), ("geometry", "point")])
def test_beer_lambert_in_the_raw_image(mi, model, kind):
    raws = {}
    for water in (None, {"absorption_per_m": SIGMA_A.tolist()}):
        config = _disc_scene(kind, port=True, water=water, model=model)
        raws[water is None] = render_raw(mi, config, progress=False).reshape(-1, 3)
    path = _raw_water_path(mi, config, kind)
    _assert_beer_lambert(raws[True], raws[False], path)


# A diffuse disc straight ahead and a lamp beside and just in front of the camera, out of view:
# the backscatter of an underwater strobe veils the empty water around the disc.
LAMP = np.array([0.08, -0.06, 0.03])
LAMP_W_SR = 0.2


def _lamp_scene(water: dict | None, *, seed: int = 3, spp: int = 32, port: bool = False) -> SceneConfig:
    data = {
        "camera": {"preset": "tiny"},
        "render": {"spp": spp, "seed": seed},
        "object": [{"type": "disc", "position_m": [0.0, 0.0, 0.4], "radius_m": 0.07, "reflectance": 0.9}],
        "light": [{"type": "point", "position_m": LAMP.tolist(), "intensity_w_sr": LAMP_W_SR}],
    }
    if water is not None:
        data["water"] = water
    if port:
        data["port"] = {"distance_m": 0.015, "thickness_m": 0.004}
    return parse_scene(data)


def _ideal(mi, config: SceneConfig):
    pinhole = virtual_camera_for(config.camera)
    scene = build_scene(mi, config, port_geometry=False)
    truth = groundtruth.compute(
        mi, scene, config, pinhole, spp=config.render.spp, seed=config.render.seed, progress=False
    )
    return truth, pinhole


def _single_scattering_veil(water: Water, directions: np.ndarray) -> np.ndarray:
    """Radiance (N, 3) scattered once towards the camera along unit rays from the origin through
    empty water, by numerical quadrature of

        L = int_0^inf sigma_s p(cos) I / d(t)^2 exp(-sigma_t (t + d(t))) dt,

    d(t) the distance from the ray point to the lamp, p the Henyey-Greenstein phase function of the
    angle between the lamp's light and the direction back to the camera (g > 0: forward). The
    trapezoid rule on these 370 nodes is within 1e-4 of one on 12,000."""
    sigma_t, sigma_s, g = np.asarray(water.extinction_per_m), np.asarray(water.scattering_per_m), water.phase_g
    t = np.concatenate([np.linspace(0.0, 0.5, 250, endpoint=False), np.geomspace(0.5, 40.0 / sigma_t.min(), 120)])
    out = []
    for chunk in np.array_split(directions, max(1, len(directions) // 1000)):
        to_x = t[None, :, None] * chunk[:, None, :] - LAMP
        d = np.linalg.norm(to_x, axis=-1)
        cos = np.sum(to_x / d[..., None] * -chunk[:, None, :], axis=-1)
        phase = (1.0 - g * g) / (4.0 * np.pi * (1.0 + g * g - 2.0 * g * cos) ** 1.5)
        attenuation = np.exp(-sigma_t * (t[None, :, None] + d[..., None]))
        out.append(np.trapezoid((phase * LAMP_W_SR / d**2)[..., None] * sigma_s * attenuation, t, axis=1))
    return np.concatenate(out)


@pytest.mark.render
def test_scattering_veils_the_view_as_single_scattering_predicts(mi):
    clear, pinhole = _ideal(mi, _lamp_scene(None))
    empty = clear.ideal.reshape(-1, 3).max(axis=1) == 0.0  # pixels that see no part of the disc
    on_disc = np.isfinite(clear.depth_m.reshape(-1))
    directions = pinhole.pixel_directions()[empty]

    def contrast(image):
        disc, water = image[on_disc].mean(), image[empty].mean()
        return (disc - water) / (disc + water)

    veils = {}
    for name, table in {
        "isotropic": {"scattering_per_m": 1.0, "absorption_per_m": 0.2},
        "forward": {"scattering_per_m": 1.0, "absorption_per_m": 0.2, "phase_g": 0.8},
        "rgb": {"scattering_per_m": [1.5, 1.0, 0.5], "absorption_per_m": [0.3, 0.1, 0.05], "phase_g": 0.5},
    }.items():
        config = _lamp_scene(table)
        image = _ideal(mi, config)[0].ideal.reshape(-1, 3)
        predicted = _single_scattering_veil(config.water, directions).mean(axis=0)
        measured = image[empty].mean(axis=0)
        np.testing.assert_allclose(measured, predicted, rtol=WATER_VEIL_RELATIVE, err_msg=name)
        veils[name] = measured
        assert contrast(image) < 0.9 * contrast(clear.ideal.reshape(-1, 3))  # the veil eats contrast (clear: 1)
    # A lamp beside the camera lights the water from behind the view: forward-scattering water
    # sends less of it back (the underwater photographer's reason to hold strobes out).
    assert np.all(veils["forward"] < 0.3 * veils["isotropic"])
    # Absorption alone darkens the disc but adds no veil: the empty water stays black.
    absorbing = _ideal(mi, _lamp_scene({"absorption_per_m": 1.2}))[0].ideal.reshape(-1, 3)
    assert np.all(absorbing[empty] == 0.0)
    assert absorbing[on_disc].mean() < 0.5 * clear.ideal.reshape(-1, 3)[on_disc].mean()


@pytest.mark.render
def test_turbid_renders_are_deterministic_with_the_seed(mi):
    water = {"scattering_per_m": [0.8, 0.6, 0.4], "absorption_per_m": 0.3, "phase_g": 0.6}
    config = _lamp_scene(water, spp=4, port=True)
    first = render_raw(mi, config, progress=False)
    again = render_raw(mi, config, progress=False)
    other = render_raw(mi, config.with_overrides(render=RenderSettings(spp=4, seed=4)), progress=False)
    assert first.tobytes() == again.tobytes()
    assert not np.array_equal(first, other)
    # The veil reaches the raw image too: lines of sight that meet nothing are black in clear
    # water and glow in turbid water (about half of the pixels that see no surface are inside a
    # micro-image; the rest are vignetted and stay black).
    clear = render_raw(mi, _lamp_scene(None, spp=4, port=True), progress=False).max(axis=2)
    veil = first.max(axis=2)[clear == 0.0]
    assert np.mean(veil > 0.0) > 0.3


@pytest.mark.render
@pytest.mark.parametrize("model", ["sensor", "geometry"])
def test_clear_water_renders_bit_identical_to_no_water(mi, model):
    base = _disc_scene("point", port=True, water=None, model=model, spp=4)
    zero = {"absorption_per_m": 0.0, "scattering_per_m": [0.0, 0.0, 0.0], "phase_g": 0.4}
    clear = base.with_overrides(water=Water.from_dict(zero))
    assert render_raw(mi, base, progress=False).tobytes() == render_raw(mi, clear, progress=False).tobytes()
    pinhole = virtual_camera_for(base.camera)
    a, b = (
        groundtruth.compute(mi, build_scene(mi, c, port_geometry=False), c, pinhole, spp=4, seed=1, progress=False)
        for c in (base, clear)
    )
    assert a.ideal.tobytes() == b.ideal.tobytes()
    assert a.depth_m.tobytes() == b.depth_m.tobytes()


@pytest.mark.render
def test_render_job_records_the_water(tmp_path):
    config = _disc_scene("point", port=True, water=SEA | {"scattering_per_m": 0.2, "phase_g": 0.9}, spp=2)
    render_job(config, tmp_path / "run", progress=False, write_previews=False)
    meta = read_json(tmp_path / "run" / "meta.json")
    n = seawater_index(salinity_psu=35.0, temperature_c=20.0)
    assert meta["port"]["n_water"] == n  # what the synthesis reads
    assert meta["scene"]["water"]["n_water"] == n
    assert meta["scene"]["water"]["scattering_per_m"] == [0.2, 0.2, 0.2]
    volpath = {"type": "volpath", "max_depth": 2, "rr_depth": 3, "hide_emitters": False}
    assert meta["render"]["integrator_raw"] == volpath  # the sensor port model: no glass in the scene
    assert meta["render"]["integrator_ideal"]["type"] == "volpath"
    assert meta["render"]["medium"]["phase"] == {"type": "hg", "g": 0.9}


def test_the_water_index_is_checked_once_whichever_way_the_config_is_built():
    # The parser checked a stated port index against [water], then SceneConfig checked it again;
    # only a parsed port within the tolerance got the computed index. Now SceneConfig is the one
    # check, and it gives every port within the tolerance the computed index.
    n = seawater_index(salinity_psu=35.0, temperature_c=20.0)
    config = parse_scene(_data(water=SEA))
    near = dataclasses.replace(config.port, n_water=round(n, 4))
    assert config.with_overrides(port=near).port.n_water == n
    assert parse_scene(_data(port=PORT | {"n_water": round(n, 4)}, water=SEA)).port.n_water == n
