"""Values the core's commands print for people: rounded to a sensible number of significant digits,
with their units (``describe illum`` printed ``mla_f_number: 1.7999999999999998`` and the MLA as a
Python dict)."""

from __future__ import annotations

import json
import re

import pytest

from lfrefract import FlatPort, camera_preset
from lfrefract.cli import main
from lfrefract.formats.jsonio import write_json

#: ``describe`` prints floats to this many significant digits: the presets' parameters have at most
#: five (9.993 mm), so six show every one exactly and hide binary round-off (1.7999999999999998).
PRINTED_SIGNIFICANT_DIGITS = 6
#: A printed value matches its JSON value to this relative difference (rounding to six digits).
PRINTED_RELATIVE = 5e-6
#: The unit each key's suffix names, as printed after the value.
UNITS = {"_m": "m", "_deg": "deg", "_rad": "rad", "_px": "px"}
NUMBER = re.compile(r"-?\d+(?:\.\d*)?(?:e[-+]?\d+)?")


def _significant_digits(number: str) -> int:
    mantissa = number.lstrip("-").split("e")[0].replace(".", "").lstrip("0")
    return len(mantissa)


def _leaves(info: dict, path: tuple[str, ...] = ()) -> dict[tuple[str, ...], object]:
    out: dict[tuple[str, ...], object] = {}
    for key, value in info.items():
        if isinstance(value, dict):
            out.update(_leaves(value, (*path, key)))
        else:
            out[(*path, key)] = value
    return out


def _printed(text: str) -> dict[tuple[str, ...], str]:
    """``describe``'s text as ``path -> printed value``, nesting by two-space indentation."""
    out: dict[tuple[str, ...], str] = {}
    stack: list[str] = []
    for line in text.splitlines():
        depth = (len(line) - len(line.lstrip(" "))) // 2
        key, _, value = line.strip().partition(":")
        stack = [*stack[:depth], key]
        if value.strip():
            out[tuple(stack)] = value.strip()
    return out


def _flat(value: object) -> list[float]:
    if isinstance(value, list | tuple):
        return [x for v in value for x in _flat(v)]
    return [float(value)]  # type: ignore[arg-type]


@pytest.mark.parametrize("source", ["illum", "tiny", "f01", "meta"])
def test_describe_prints_rounded_values_with_their_units(tmp_path, capsys, source):
    if source == "meta":
        port = FlatPort.from_degrees(distance_m=0.03, thickness_m=0.005, tilt_x_deg=20.0)
        source = str(tmp_path / "meta.json")
        write_json(source, {"camera": camera_preset("tiny").to_dict(), "port": port.to_dict()})
    assert main(["describe", source, "--json"]) == 0
    leaves = _leaves(json.loads(capsys.readouterr().out))
    assert main(["describe", source]) == 0
    text = capsys.readouterr().out
    assert "{" not in text, text  # no Python reprs of dicts
    assert "'" not in text, text
    printed = _printed(text)
    for path, value in leaves.items():
        if path[0] in ("schema_version", "kind"):
            continue
        shown = printed[path]
        if isinstance(value, str):
            assert shown == value
            continue
        unit = next((u for suffix, u in UNITS.items() if path[-1].endswith(suffix)), None)
        if path[-1] == "K":
            unit = "px"
        if unit is not None:
            assert shown.endswith(f" {unit}"), (path, shown)
        numbers = NUMBER.findall(shown)
        assert [float(n) for n in numbers] == pytest.approx(_flat(value), rel=PRINTED_RELATIVE, abs=1e-12), path
        for n in numbers:
            assert _significant_digits(n) <= PRINTED_SIGNIFICANT_DIGITS or "." not in n, (path, shown)
    assert set(printed) == {p for p in leaves if p[0] not in ("schema_version", "kind")}


def test_describe_illum_prints_the_mla_f_number_as_1_8(capsys):
    assert main(["describe", "illum"]) == 0
    text = capsys.readouterr().out
    assert "mla_f_number: 1.8\n" in text
    assert "  mla:\n    grid: hex\n    pitch_m: 2e-05 m\n" in text
