"""Sweep options for learning datasets: constants in [set], the ideal image's spp, ordering
constraints with redraws counted, the image format (parsing and expansion; no rendering)."""

from __future__ import annotations

import pytest

from lfrefract import ParameterError
from simulator.dataset import expand, parse_spec
from simulator.dataset.run import _rejections
from simulator.dataset.spec import key_rng
from tests.simulator.test_dataset_spec import spec_data as spec

#: The default scene's backdrop is object 0 (z = 0.8 m); the chessboard is object 1.
BOARD_Z, BACKDROP_Z = "object.1.position_m.2", "object.0.position_m.2"
SEED = spec()["sweep"]["seed"]


def test_set_keys_reach_every_sample_and_are_not_swept():
    data = spec(grid={"port.tilt_x_deg": [0.0, 10.0]}, set={"port.thickness_m": 0.003, "camera.preset": "tiny"})
    parsed = parse_spec(data)
    samples = expand(parsed)
    assert parsed.set_keys == ("port.thickness_m", "camera.preset")
    assert parsed.swept_keys == ("port.tilt_x_deg",)
    for sample in samples:
        assert sample.config.port.thickness_m == 0.003
        assert sample.config.camera.name == "tiny"
        assert set(sample.params) == {"port.tilt_x_deg"}
        assert sample.config.name == f"t/{sample.id}"
    # The constant is part of every sample's scene, so of its hash.
    other = expand(parse_spec(spec(grid={"port.tilt_x_deg": [0.0, 10.0]}, set={"port.thickness_m": 0.004})))
    assert samples[0].hash != other[0].hash


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (spec(grid={"port.tilt_x_deg": [0.0]}, set={"port.tilt_x_deg": 5.0}), "both in \\[set\\] and swept"),
        (spec(random={"port.tilt_x_deg": {"uniform": [0, 1]}}, set={"port.tilt_x_deg": 5.0}), "both in \\[set\\]"),
        (spec(set={"render.seed": 3}), "set per sample"),
        (spec(set={"scene": "default"}), "sweep.scene"),
        (spec(set={"port..x": 1.0}), "not a dotted scene key"),
        (spec(set=[1]), "\\[set\\] must be a table"),
        (spec(sweep={"ideal_spp": 0}), "sweep.ideal_spp"),
        (spec(sweep={"ideal_spp": 4}, grid={"render.ideal_spp": [8]}), "render.ideal_spp is swept or set"),
        (spec(sweep={"image_format": "tiff"}), "sweep.image_format"),
        (spec(sweep={"max_draws": 0}), "sweep.max_draws"),
        (spec(sweep={"redraw_impossible": 1}), "sweep.redraw_impossible must be true or false"),
        (spec(constraints={"c": {"key": BOARD_Z}}), "exactly one of"),
        (spec(constraints={"c": {"key": BOARD_Z, "less_than": 1.0, "greater_than": 0.0}}), "exactly one of"),
        (spec(constraints={"c": {"key": BOARD_Z, "below": 1.0}}), "unknown key"),
        (spec(constraints={"c": {"key": BOARD_Z, "less_than": 1.0, "margin": -0.1}}), "margin must be >= 0"),
        (spec(constraints={"c": 3}), "must be a table"),
    ],
)
def test_bad_options_are_refused_naming_the_key(data, message):
    with pytest.raises(ParameterError, match=message):
        expand(parse_spec(data))


def test_ideal_spp_sets_the_ideal_image_only():
    (sample,) = expand(parse_spec(spec(sweep={"ideal_spp": 64})))
    assert (sample.config.render.spp, sample.config.render.ideal_spp) == (2, 64)


def test_constraint_redraws_until_it_holds_and_counts_the_refusals():
    data = spec(
        sweep={"repeats": 12},
        random={BOARD_Z: {"uniform": [0.3, 0.9]}},
        constraints={"board_before_backdrop": {"key": BOARD_Z, "less_than": BACKDROP_Z, "margin": 0.05}},
    )
    samples = expand(parse_spec(data))
    z = [s.config.objects[1].placement.position_m[2] for s in samples]
    backdrop = samples[0].config.objects[0].placement.position_m[2]
    assert all(v < backdrop - 0.05 for v in z)
    # The first draws: those at 0.75 m or more were refused and drawn again.
    first = [key_rng(SEED, s.index, BOARD_Z).uniform(0.3, 0.9) for s in samples]
    for sample, value in zip(samples, first, strict=True):
        refused = sample.rejected.get("board_before_backdrop", 0)
        assert (refused > 0) == (value >= backdrop - 0.05)
        if refused == 0:
            assert sample.config.objects[1].placement.position_m[2] == value
    assert any(s.rejected for s in samples)  # a quarter of 0.3-0.9 m fails
    summary = _rejections([s.record() for s in samples])
    assert summary["by_reason"]["board_before_backdrop"] == sum(
        s.rejected.get("board_before_backdrop", 0) for s in samples
    )
    assert summary["samples_redrawn"] == sum(1 for s in samples if s.rejected)
    assert [s.hash for s in expand(parse_spec(data))] == [s.hash for s in samples]  # deterministic
    assert "rejected" not in next(s for s in samples if not s.rejected).record()


def test_a_constraint_never_met_is_refused_after_max_draws():
    data = spec(
        sweep={"max_draws": 5},
        random={BOARD_Z: {"uniform": [0.8, 0.9]}},
        constraints={"impossible": {"key": BOARD_Z, "less_than": BACKDROP_Z}},
    )
    with pytest.raises(ParameterError, match=r"none of 5 draws .*'impossible': 5"):
        expand(parse_spec(data))
    fixed = spec(constraints={"impossible": {"key": "port.tilt_x_deg", "greater_than": 80.0}})
    with pytest.raises(ParameterError, match="breaks \\[constraints\\] 'impossible'; the sample has no \\[random\\]"):
        expand(parse_spec(fixed))


def test_a_constraint_on_a_missing_key_is_a_spec_error():
    data = spec(constraints={"c": {"key": "object.7.position_m.2", "less_than": 1.0}})
    with pytest.raises(ParameterError, match=r"has no 'object\.7'"):
        expand(parse_spec(data))
    data = spec(constraints={"c": {"key": "object.1.position_m", "less_than": 1.0}})
    with pytest.raises(ParameterError, match="not a number; index a vector"):
        expand(parse_spec(data))


def test_redraw_impossible_draws_again_what_the_geometry_check_refuses():
    # Boards drawn on the camera side of the glass (z < 0.03 m) are impossible scenes.
    data = spec(sweep={"repeats": 6}, random={BOARD_Z: {"uniform": [-0.2, 0.6]}})
    with pytest.raises(ParameterError, match="sample s0000"):
        expand(parse_spec(data))
    data["sweep"]["redraw_impossible"] = True
    samples = expand(parse_spec(data))
    assert all(s.config.objects[1].placement.position_m[2] > 0.03 for s in samples)
    assert sum(s.rejected.get("geometry", 0) for s in samples) > 0


def test_sensor_settings_are_ordinary_keys():
    data = spec(set={"sensor.preset": "tiny"}, grid={"sensor.iso": [100.0, 800.0]})
    samples = expand(parse_spec(data))
    assert [s.config.sensor.detector.iso for s in samples] == [100.0, 800.0]
