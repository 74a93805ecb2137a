"""Sweep specs: parsing, rejection before any work, deterministic expansion; the run's checks of its
output folder (no rendering)."""

from __future__ import annotations

import copy
import fcntl
import os
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

from lfrefract import ParameterError
from simulator.config import default_scene_path
from simulator.dataset import DatasetBusyError, expand, load_spec, parse_spec, run_dataset
from simulator.dataset.manifest import DigestCache, append_record, folder_files
from simulator.dataset.run import _check_target, _plan, _prepare
from simulator.dataset.spec import MAX_SAMPLES, key_rng, sample_seed

BASE = {"sweep": {"name": "t", "seed": 11, "scene": "default", "spp": 2}}


def spec_data(**tables) -> dict:
    """The base [sweep] table with other tables (or [sweep] keys, given as sweep={...}) added."""
    data = copy.deepcopy(BASE)
    for name, table in tables.items():
        if name == "sweep":
            data["sweep"].update(table)
        else:
            data[name] = table
    return data


def build(data: dict, base_dir: Path | str = "."):
    """Parse and expand a spec dict."""
    return expand(parse_spec(data, base_dir=base_dir))


# ---------------------------------------------------------------------------------- rejection
BAD_SPECS = [
    # (id, spec dict, pattern of the message)
    ("empty grid", spec_data(grid={"port.tilt_x_deg": []}), r"grid 'port.tilt_x_deg' = \[\] is an empty range"),
    ("grid not a list", spec_data(grid={"port.tilt_x_deg": 10.0}), r"grid 'port.tilt_x_deg' must be a list"),
    (
        "uniform lo > hi",
        spec_data(random={"port.tilt_x_deg": {"uniform": [20.0, 10.0]}}),
        r"random 'port.tilt_x_deg': uniform = \[20.0, 10.0\] is an empty range",
    ),
    (
        "uniform lo = hi",
        spec_data(random={"port.tilt_x_deg": {"uniform": [10.0, 10.0]}}),
        r"uniform = \[10.0, 10.0\] is an empty range \(needs lo < hi\)",
    ),
    (
        "uniform vectors of different lengths",
        spec_data(random={"object.1.rotation_xyz_deg": {"uniform": [[0, 0, 0], [1, 1]]}}),
        r"random 'object.1.rotation_xyz_deg': uniform .* vectors of different lengths",
    ),
    (
        "uniform vector of one point",
        spec_data(random={"object.1.rotation_xyz_deg": {"uniform": [[0, 5, 0], [0, 5, 0]]}}),
        r"uniform = \[\[0, 5, 0\], \[0, 5, 0\]\] is an empty range",
    ),
    (
        "uniform vector empty in one entry",
        spec_data(random={"object.1.rotation_xyz_deg": {"uniform": [[0, 5, 0], [1, 4, 1]]}}),
        r"uniform = \[\[0, 5, 0\], \[1, 4, 1\]\] is an empty range \(needs lo <= hi in every entry, lo < hi in one\)",
    ),
    ("normal std 0", spec_data(random={"port.distance_m": {"normal": [0.02, 0.0]}}), r"normal = .* needs std > 0"),
    ("choice empty", spec_data(random={"camera.preset": {"choice": []}}), r"choice = \[\] is an empty range"),
    (
        # Sweep seed 2 draws 1.0 for the one sample: the NaN is never drawn, yet the spec is refused.
        "NaN among choices",
        spec_data(sweep={"seed": 2}, random={"port.tilt_y_deg": {"choice": [1.0, float("nan")]}}),
        r"sweep spec: random\.\"port\.tilt_y_deg\"\.choice\[1\] = nan is not a finite number",
    ),
    ("integers lo > hi", spec_data(random={"object.0.texture_seed": {"integers": [5, 1]}}), r"integers = \[5, 1\]"),
    (
        "integers of floats",
        spec_data(random={"object.0.texture_seed": {"integers": [0.5, 3]}}),
        r"integers needs \[lo, hi\] integers",
    ),
    (
        "unknown distribution",
        spec_data(random={"port.tilt_x_deg": {"gauss": [0, 1]}}),
        r"random 'port.tilt_x_deg': unknown distribution 'gauss'",
    ),
    (
        "two distributions",
        spec_data(random={"port.tilt_x_deg": {"uniform": [0, 1], "normal": [0, 1]}}),
        r"random 'port.tilt_x_deg' must be a table with one distribution",
    ),
    ("unknown [sweep] key", spec_data(sweep={"sed": 3}), r"unknown key\(s\) in \[sweep\]: \['sed'\]"),
    ("unknown table", spec_data(grids={"port.tilt_x_deg": [1.0]}), r"unknown key\(s\) in sweep spec: \['grids'\]"),
    ("missing seed", {"sweep": {"name": "t", "scene": "default"}}, r"\[sweep\]: missing key 'seed'"),
    ("negative seed", spec_data(sweep={"seed": -1}), r"sweep.seed must be an integer in \[0, 2\*\*31\), got -1"),
    (
        "seed not an integer",
        spec_data(sweep={"seed": 1.5}),
        r"sweep.seed must be an integer in \[0, 2\*\*31\), got 1.5",
    ),
    ("repeats 0", spec_data(sweep={"repeats": 0}), r"sweep.repeats must be positive, got 0"),
    ("unknown output", spec_data(sweep={"outputs": ["depthmap"]}), r"sweep.outputs: unknown output 'depthmap'"),
    ("unknown scene", spec_data(sweep={"scene": "nowhere"}), r"sweep.scene = 'nowhere' is not an embedded scene"),
    ("missing scene file", spec_data(sweep={"scene": "nope.toml"}), r"sweep.scene = 'nope.toml': no such scene file"),
    (
        "synthesis without the output",
        spec_data(sweep={"synthesis": {"k": 8}}),
        r"\[sweep.synthesis\] is given but 'refraction_free' is not in sweep.outputs",
    ),
    (
        "bad synthesis option",
        spec_data(sweep={"outputs": ["refraction_free"], "synthesis": {"k": 0}}),
        r"\[sweep.synthesis\]: k must be positive, got 0",
    ),
    (
        "unknown synthesis option",
        spec_data(sweep={"outputs": ["refraction_free"], "synthesis": {"kk": 8}}),
        r"unknown key\(s\) in \[sweep.synthesis\]: \['kk'\]",
    ),
    ("render.seed swept", spec_data(grid={"render.seed": [1, 2]}), r"'render.seed' is set per sample"),
    ("malformed key", spec_data(grid={"port..tilt_x_deg": [1.0]}), r"'port..tilt_x_deg' is not a dotted scene key"),
    (
        "key in grid and random",
        spec_data(grid={"port.tilt_x_deg": [1.0]}, random={"port.tilt_x_deg": {"uniform": [0, 1]}}),
        r"key 'port.tilt_x_deg' is both in \[grid\] and in \[random\]",
    ),
    ("spp twice", spec_data(grid={"render.spp": [4, 8]}), r"render.spp is swept or set and sweep.spp is given"),
    (
        "unset of a missing key",
        spec_data(sweep={"unset": ["port.n_glass", "object.7"]}),
        r"sweep.unset: 'object.7': the base scene has no 'object.7'",
    ),
    (
        "unset not a list",
        spec_data(sweep={"unset": "port.n_water"}),
        r"sweep.unset must be a list of dotted scene keys",
    ),
    (
        "scene by uniform",
        spec_data(random={"scene": {"uniform": [0, 1]}}),
        r"random 'scene' chooses among base scenes: use \{ choice",
    ),
    (
        "too many samples",
        spec_data(grid={"port.tilt_x_deg": [0.0] * 1000, "port.tilt_y_deg": [0.0] * 1001}),
        rf"the sweep has 1001000 samples, more than {MAX_SAMPLES}",
    ),
    # Found by expanding: every sample becomes a scene and is checked before anything runs.
    (
        "unknown scene key",
        spec_data(grid={"port.tilt_z_deg": [5.0]}),
        r"sample s000000 \(port.tilt_z_deg=5.0\): unknown key\(s\) in port: \['tilt_z_deg'\]",
    ),
    (
        "unknown nested key",
        spec_data(grid={"camera.pose.rotation_deg": [[0, 0, 0]]}),
        r"sample s000000 \(camera.pose.rotation_deg=\[0, 0, 0\]\): unknown key\(s\) in pose: \['rotation_deg'\]",
    ),
    (
        "unknown object key",
        spec_data(grid={"object.1.colour": [1.0]}),
        r"sample s000000 \(object.1.colour=1.0\): unknown key\(s\) in object\[1\] \(chessboard\): \['colour'\]",
    ),
    (
        "object index out of range",
        spec_data(grid={"object.9.position_m": [[0, 0, 1]]}),
        r"'object.9.position_m': index 9 is out of range: the scene has 4 \[\[object\]\] entries",
    ),
    (
        "array without index",
        spec_data(grid={"object.position_m": [[0, 0, 1]]}),
        r"'object' is an array of tables; address an entry by its index \(e.g. 'object.0.position_m'\)",
    ),
    (
        "port behind the camera",
        spec_data(grid={"port.tilt_x_deg": [10.0, 95.0]}),
        r"sample s000001 \(port.tilt_x_deg=95.0\): port.tilt_x_deg must lie in \(-90, 90\) deg, got 95.0: the port "
        "would be behind the camera",
    ),
    (
        "tilt puts the scene behind the glass",
        spec_data(grid={"port.tilt_x_deg": [80.0]}),
        r"sample s000000 \(port.tilt_x_deg=80.0\): object\[0\] \(textured_plane\) reaches the camera side of the port",
    ),
    (
        "tilt cuts the aperture",
        spec_data(grid={"port.tilt_x_deg": [60.0], "port.distance_m": [0.001], "object": [[]]}),
        r"sample s000000 \(port.tilt_x_deg=60.0, port.distance_m=0.001, object=\[\]\): port.distance_m=0.001 with "
        r"tilt 60.00 deg cuts the main-lens aperture",
    ),
    (
        "every ray totally reflected",
        spec_data(grid={"port.tilt_x_deg": [60.0], "port.n_air": [2.5]}),
        r"sample s000000 \(port.tilt_x_deg=60.0, port.n_air=2.5\): every captured ray is totally internally "
        r"reflected",
    ),
    (
        "random tilt reaching 95 deg",
        spec_data(random={"port.tilt_y_deg": {"uniform": [94.0, 96.0]}}),
        r"sample s000000 \(port.tilt_y_deg=9\d\.\d+\): port.tilt_y_deg must lie in \(-90, 90\) deg, got 9\d\.\d+: "
        "the port would be behind the camera",
    ),
    (
        "unknown preset",
        spec_data(grid={"camera.preset": ["tiny", "lytro9"]}),
        r"sample s000001 \(camera.preset='lytro9'\): camera preset must be one of .*, got 'lytro9'",
    ),
    (
        "object in front of the glass",
        spec_data(grid={"object.0.position_m": [[0.0, 0.0, 0.01]]}),
        r"object\[0\] \(textured_plane\) reaches the camera side of the port",
    ),
    (
        "negative thickness",
        spec_data(random={"port.thickness_m": {"normal": [-0.01, 0.001]}}),
        r"sample s000000 \(port.thickness_m=-0.0\d+\): port.thickness_m must be non-negative",
    ),
    (
        "refraction-free without a port",
        spec_data(sweep={"outputs": ["refraction_free"], "scene": "white"}),
        r"sample s000000 \(no swept keys\): the scene has no \[port\]",
    ),
]


@pytest.mark.parametrize(("data", "pattern"), [c[1:] for c in BAD_SPECS], ids=[c[0] for c in BAD_SPECS])
def test_bad_spec_rejected_with_key_and_value(data, pattern, tmp_path):
    with pytest.raises(ParameterError, match=pattern):
        build(data, tmp_path)
    # ... and run_dataset refuses it before it writes anything.
    out = tmp_path / "out"
    with pytest.raises(ParameterError, match=pattern):
        run_dataset(parse_spec(data, base_dir=tmp_path), out, progress=False)
    assert not out.exists()


def test_views_output_options_are_checked():
    data = spec_data(sweep={"outputs": ["views"], "views": {"grid": 3}})
    assert parse_spec(data).views.to_dict() == {"grid": 3}
    for views, pattern in (
        ({"grid": 4}, r"sweep.views.grid must be an odd integer >= 3, got 4"),
        ({"image_format": "tiff"}, r"sweep.views.image_format must be one of \['png', 'exr'\], got 'tiff'"),
        ({"grid": 9, "spacing_px": 4.0}, r"sample s000000 .*: sweep.views.spacing_px=4.0 puts the corner views"),
    ):
        with pytest.raises(ParameterError, match=pattern):
            build(spec_data(sweep={"outputs": ["views"], "views": views}))
    with pytest.raises(ParameterError, match=r"unknown key\(s\) in \[sweep.views\]: \['size'\]"):
        parse_spec(spec_data(sweep={"outputs": ["views"], "views": {"size": 3}}))


def test_cli_refuses_a_bad_spec_and_writes_nothing(tmp_path):
    spec = tmp_path / "bad.toml"
    spec.write_text('[sweep]\nname = "b"\nseed = 1\nscene = "default"\n[grid]\n"port.tilt_x_deg" = [10.0, 95.0]\n')
    out = tmp_path / "out"
    proc = subprocess.run(
        [sys.executable, "-m", "simulator.cli", "dataset", "run", str(spec), "--out", str(out)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert proc.returncode == 2
    assert "sample s000001 (port.tilt_x_deg=95.0)" in proc.stderr
    assert not out.exists()


# --------------------------------------------------------------------------------- expansion
def test_embedded_tilt_spec():
    spec = load_spec("tilt")
    samples = expand(spec)
    assert [s.id for s in samples] == ["s000000", "s000001", "s000002", "s000003"]
    assert [s.params["port.tilt_x_deg"] for s in samples] == [0.0, 10.0, 20.0, 30.0]
    for s in samples:
        assert -3.0 <= s.params["port.tilt_y_deg"] <= 3.0
        assert s.config.render.spp == 4
        assert s.config.render.seed == s.seed
        assert np.degrees(s.config.port.tilt_x_rad) == pytest.approx(s.params["port.tilt_x_deg"], abs=1e-12)
        assert np.degrees(s.config.port.tilt_y_rad) == pytest.approx(s.params["port.tilt_y_deg"], abs=1e-12)
    assert spec.outputs == ("refraction_free",)


def test_expansion_is_deterministic_and_seeded_per_sample():
    data = spec_data(
        sweep={"repeats": 2},
        grid={"port.tilt_x_deg": [0.0, 15.0], "camera.preset": ["tiny", "tiny-2x"]},
        random={
            "port.tilt_y_deg": {"uniform": [-5.0, 5.0]},
            "object.1.rotation_xyz_deg": {"uniform": [[0, -20, 0], [10, -10, 5]]},
            "object.0.texture_seed": {"integers": [0, 1000]},
            "port.thickness_m": {"normal": [0.006, 0.0005]},
            "light.0.intensity_w_sr": {"choice": [0.4, [0.5, 0.5, 0.45]]},
        },
    )
    a, b = build(data), build(copy.deepcopy(data))
    assert len(a) == 2 * 2 * 2
    assert [(s.id, s.seed, dict(s.params), s.hash) for s in a] == [(s.id, s.seed, dict(s.params), s.hash) for s in b]
    # Cartesian product, first key slowest, each point repeated.
    assert [(s.params["port.tilt_x_deg"], s.params["camera.preset"]) for s in a] == [
        (0.0, "tiny"), (0.0, "tiny"), (0.0, "tiny-2x"), (0.0, "tiny-2x"),
        (15.0, "tiny"), (15.0, "tiny"), (15.0, "tiny-2x"), (15.0, "tiny-2x"),
    ]  # fmt: skip
    for s in a:
        assert s.seed == sample_seed(11, s.index)
        assert s.seed == int(np.random.SeedSequence([11, s.index]).generate_state(1, np.uint32)[0]) % 2**31
        assert s.config.render.seed == s.seed
        assert s.id == f"s{s.index:06d}"
        assert s.params["port.tilt_y_deg"] == key_rng(11, s.index, "port.tilt_y_deg").uniform(-5.0, 5.0)
        rot = s.params["object.1.rotation_xyz_deg"]
        assert len(rot) == 3
        assert np.all((np.array([0, -20, 0]) <= rot) & (rot <= np.array([10, -10, 5])))
        assert s.config.objects[1].placement.rotation_xyz_deg == tuple(rot)
        assert 0 <= s.params["object.0.texture_seed"] <= 1000
        assert s.config.objects[0].texture_seed == s.params["object.0.texture_seed"]
        assert s.config.camera.name == s.params["camera.preset"]
    assert len({s.seed for s in a}) == len(a)
    assert len({s.hash for s in a}) == len(a)
    assert len({s.params["port.tilt_y_deg"] for s in a}) == len(a)


def test_a_random_key_draws_do_not_depend_on_other_keys():
    one = build(spec_data(random={"port.tilt_y_deg": {"uniform": [-5.0, 5.0]}}))
    two = build(
        spec_data(random={"port.distance_m": {"uniform": [0.02, 0.03]}, "port.tilt_y_deg": {"uniform": [-5.0, 5.0]}})
    )
    assert one[0].params["port.tilt_y_deg"] == two[0].params["port.tilt_y_deg"]
    assert one[0].hash != two[0].hash


def test_another_sweep_seed_gives_other_seeds_and_draws_but_the_same_grid():
    a = build(spec_data(grid={"port.tilt_x_deg": [0.0, 20.0]}, random={"port.tilt_y_deg": {"uniform": [-5, 5]}}))
    data = spec_data(grid={"port.tilt_x_deg": [0.0, 20.0]}, random={"port.tilt_y_deg": {"uniform": [-5, 5]}})
    data["sweep"]["seed"] = 12
    b = build(data)
    assert [s.params["port.tilt_x_deg"] for s in a] == [s.params["port.tilt_x_deg"] for s in b]
    assert all(x.seed != y.seed for x, y in zip(a, b, strict=True))
    assert all(x.params["port.tilt_y_deg"] != y.params["port.tilt_y_deg"] for x, y in zip(a, b, strict=True))
    assert parse_spec(data).hash != parse_spec(spec_data()).hash


def test_spec_hash_ignores_formatting_but_not_content(tmp_path):
    text = '[sweep]\nname = "t"\nseed = 3\nscene = "default"\n[grid]\n"port.tilt_x_deg" = [0.0, 10.0]\n'
    (tmp_path / "a.toml").write_text(text)
    (tmp_path / "b.toml").write_text("# a comment\n" + text.replace(" = ", "=").replace("[0.0, 10.0]", "[0.0,10.0]"))
    (tmp_path / "c.toml").write_text(text.replace("10.0]", "10.5]"))
    a, b, c = (load_spec(tmp_path / f"{n}.toml") for n in "abc")
    assert a.hash == b.hash != c.hash


def test_sample_hash_follows_the_base_scene_file(tmp_path):
    scene = tomllib.loads(default_scene_path().read_text())
    scene_text = default_scene_path().read_text()
    (tmp_path / "base.toml").write_text(scene_text)
    data = spec_data(sweep={"scene": "base.toml"}, grid={"port.tilt_x_deg": [5.0]})
    before = build(data, tmp_path)[0]
    assert before.config.objects[0].size_m == tuple(scene["object"][0]["size_m"])
    (tmp_path / "base.toml").write_text(scene_text.replace("size_m = [1.2, 0.9]", "size_m = [1.3, 0.9]"))
    after = build(data, tmp_path)[0]
    assert after.config.objects[0].size_m == (1.3, 0.9)
    assert after.hash != before.hash
    assert (after.id, after.seed, dict(after.params)) == (before.id, before.seed, dict(before.params))


def test_scene_key_chooses_the_base_scene_and_tables_replace_whole(tmp_path):
    plane = {"type": "textured_plane", "position_m": [0.0, 0.0, 0.6], "size_m": [1.0, 0.8]}
    disc = {"type": "disc", "position_m": [0.05, 0.0, 0.4], "radius_m": 0.02}
    scene_text = default_scene_path().read_text()
    (tmp_path / "scenes").mkdir()
    (tmp_path / "scenes" / "near.toml").write_text(scene_text.replace("[0.0, 0.0, 0.8]", "[0.0, 0.0, 0.7]"))
    samples = build(
        spec_data(grid={"scene": ["default", "scenes/near.toml"], "object": [[plane], [plane, disc]]}), tmp_path
    )
    assert [(s.params["scene"], len(s.config.objects)) for s in samples] == [
        ("default", 1), ("default", 2), ("scenes/near.toml", 1), ("scenes/near.toml", 2),
    ]  # fmt: skip
    # The base scene's other tables stay: its lights and port.
    assert all(len(s.config.lights) == 2 and s.config.port is not None for s in samples)
    chosen = build(
        spec_data(random={"scene": {"choice": ["default", "scenes/near.toml"]}}, sweep={"repeats": 6}), tmp_path
    )
    assert {s.params["scene"] for s in chosen} == {"default", "scenes/near.toml"}
    for s in chosen:
        z = s.config.objects[0].placement.position_m[2]
        assert z == (0.8 if s.params["scene"] == "default" else 0.7)


def test_sample_names_and_records():
    spec = parse_spec(spec_data(grid={"port.tilt_x_deg": [7.0]}))
    (s,) = expand(spec)
    assert s.config.name == "t/s000000"
    assert s.record() == {
        "id": "s000000",
        "index": 0,
        "seed": s.seed,
        "params": {"port.tilt_x_deg": 7.0},
        "hash": s.hash,
        "inputs": [str(default_scene_path())],  # the base scene file (a sample read no mesh)
    }
    assert re.fullmatch(r"[0-9a-f]{64}", s.hash)
    with pytest.raises(TypeError):
        s.params["port.tilt_x_deg"] = 8.0  # read-only


def test_unset_removes_keys_and_entries_of_the_base_scene():
    (kept,) = build(spec_data())
    (s,) = build(
        spec_data(sweep={"unset": ["object.3", "object.1", "port.n_glass"]}, grid={"object.1.radius_m": [0.05]})
    )
    # object.1 and object.3 of the base scene (chessboard, figurine) are gone; the bowl is now object 1.
    assert [type(o).__name__ for o in kept.config.objects] == ["TexturedPlane", "Chessboard", "Bowl", "Figurine"]
    assert [type(o).__name__ for o in s.config.objects] == ["TexturedPlane", "Bowl"]
    assert s.config.objects[1].radius_m == 0.05
    assert s.config.port.n_glass == 1.5  # FlatPort's default once the key is gone
    assert "n_glass" not in s.scene_data["port"]


def test_water_keys_set_the_water_and_the_port_index():
    """``water.*`` keys go into the scene's [water] table; salinity and temperature set n_water."""
    from lfrefract import seawater_index

    data = spec_data(
        sweep={"unset": ["port.n_water"]},
        grid={"water.temperature_c": [5.0, 25.0], "water.salinity_psu": [35.0]},
        random={"water.absorption_per_m": {"uniform": [[0.1, 0.02, 0.01], [0.5, 0.1, 0.05]]}},
    )
    samples = build(data)
    for s in samples:
        water = s.config.water
        n = seawater_index(salinity_psu=35.0, temperature_c=s.params["water.temperature_c"])
        assert s.config.port.n_water == pytest.approx(n, abs=1e-12)
        assert water.absorption_per_m == tuple(s.params["water.absorption_per_m"])
    assert samples[0].config.port.n_water > samples[1].config.port.n_water  # colder water refracts more
    # The default scene states port.n_water = 1.333, which a salinity and temperature contradict.
    with pytest.raises(ParameterError, match=r"sample s000000 \(water.temperature_c=5.0, .*port.n_water=1.333"):
        build(spec_data(grid={"water.temperature_c": [5.0], "water.salinity_psu": [35.0]}))
    with pytest.raises(ParameterError, match=r"sample s000000 \(water.scattering_per_m=-0.1\): .*water.scattering"):
        build(spec_data(grid={"water.scattering_per_m": [-0.1]}))


def test_the_documented_spec_is_valid():
    """The sweep spec in docs/datasets.md parses and expands (16 samples, water included)."""
    text = (Path(__file__).resolve().parents[2] / "docs" / "datasets.md").read_text()
    block = re.search(r"```toml\n(.*?)```", text, re.S).group(1)
    samples = build(tomllib.loads(block))
    assert len(samples) == 4 * 2 * 2
    rot = np.array([s.params["object.1.rotation_xyz_deg"] for s in samples])
    assert np.all(rot[:, 2] == 0.0)
    assert len(set(rot[:, 0])) == len(samples)
    assert all(s.config.water is not None and s.config.port.n_water == s.config.water.n_water for s in samples)


# ------------------------------------------------------------------------- the output folder
def test_a_folder_holding_only_a_staging_leftover_is_empty(tmp_path):
    """A run killed while creating dataset.json leaves its temporary file: the next run goes on."""
    spec = load_spec("tilt")
    planned, inputs = _plan(spec, DigestCache(), False)
    out = tmp_path / "out"
    out.mkdir()
    (out / ".dataset.json.k1ll3d.tmp").write_text('{"schema_')
    _check_target(out, spec, planned, inputs)
    assert _prepare(out, spec, planned, inputs)[0] == {}
    assert sorted(p.name for p in out.iterdir()) == ["dataset.json"]


def test_resume_keeps_only_done_records_of_the_planned_sample(tmp_path):
    """A done record whose hash is not the planned sample's is not kept: its folder is removed and
    rendered again (check_dataset would call it corrupt for ever otherwise)."""
    spec = load_spec("tilt")
    samples = expand(spec)
    planned, inputs = _plan(spec, DigestCache(), False)
    out = tmp_path / "out"
    _prepare(out, spec, planned, inputs)
    folder = out / samples[0].id
    for recorded_hash, kept in (("0" * 64, False), (samples[0].hash, True)):
        folder.mkdir()
        (folder / "raw.exr").write_bytes(b"pixels")
        record = {**samples[0].record(), "hash": recorded_hash, "status": "done", "files": folder_files(folder)}
        append_record(out / "manifest.jsonl", record)
        assert (samples[0].id in _prepare(out, spec, planned, inputs)[0]) is kept
        assert folder.exists() is kept


def test_a_second_run_on_a_folder_in_use_is_refused(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    fd = os.open(out, os.O_RDONLY)  # as a running lfsim dataset run holds it
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        with pytest.raises(DatasetBusyError, match=r"is in use by another lfsim dataset run"):
            run_dataset("tilt", out, progress=False)
    finally:
        os.close(fd)
    assert list(out.iterdir()) == []


def test_a_malformed_scheduler_address_is_a_parameter_error(tmp_path):
    out = tmp_path / "out"
    with pytest.raises(ParameterError, match=r"scheduler='head:port': cannot reach a Dask scheduler there"):
        run_dataset("tilt", out, scheduler="head:port", progress=False)
    assert not out.exists()


def test_view_options_are_typed_once_and_keep_the_table_as_given():
    # [sweep.views] was a dict checked at parse time, and its defaults (grid 9) repeated by the
    # per-sample check and the worker; now one typed value that later code trusts.
    from simulator.dataset.spec import DEFAULT_VIEW_GRID, ViewOptions

    views = parse_spec(spec_data(sweep={"outputs": ["views"], "views": {"spacing_px": 2, "white_level": 0.5}})).views
    assert isinstance(views, ViewOptions)
    assert views.grid_size == DEFAULT_VIEW_GRID
    assert views.stack_options() == {"spacing_px": 2}
    assert views.write_options() == {"white_level": 0.5}
    assert views.to_dict() == {"spacing_px": 2, "white_level": 0.5}
    assert type(views.to_dict()["spacing_px"]) is int  # as given: the sample hash covers it
    assert parse_spec(spec_data()).views == ViewOptions()
    with pytest.raises(ParameterError, match=r"sweep.views.grid must be an odd integer >= 3, got 4"):
        ViewOptions(grid=4)
