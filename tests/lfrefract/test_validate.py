"""The shared validators of lfrefract.validate against hostile values (issue 12)."""

from __future__ import annotations

import os

import pytest

from lfrefract import validate as v
from lfrefract.errors import ParameterError


def test_an_integer_beyond_the_float_range_is_a_parameter_error():
    # float(2**1100) raises OverflowError: it must not escape as one.
    with pytest.raises(ParameterError, match=r"x must be finite, got an integer of 1101 bits"):
        v.finite_float("x", 2**1100)
    with pytest.raises(ParameterError, match=r"x\[1\] must be finite"):
        v.finite_vector("x", [0, 10**400, 0], 3)


def test_messages_stay_short_for_huge_values():
    # repr() of an integer of more than 4300 digits raises ValueError; a long list is abbreviated.
    assert v.shown(10**5000).startswith("an integer of 16610 bits")
    assert len(v.shown(list(range(10**6)))) < 100
    with pytest.raises(ParameterError) as err:
        v.finite_vector("p", list(range(10**6)), 3)
    assert len(str(err.value)) < 200


@pytest.mark.parametrize("value", ["abc", b"abc", {"a": 1, "b": 2, "c": 3}, {1.0, 2.0, 3.0}])
def test_a_string_or_table_is_not_a_vector(value):
    with pytest.raises(ParameterError, match=r"p must be a sequence of 3 numbers, got "):
        v.finite_vector("p", value, 3)


def test_tables_and_keys():
    assert v.as_table("t", {"a": 1}) == {"a": 1}
    for value in (3, [("a", 1)], "a=1"):
        with pytest.raises(ParameterError, match=r"t must be a table, got "):
            v.as_table("t", value)
    with pytest.raises(ParameterError, match=r"t must have string keys, got 1"):
        v.as_table("t", {1: 2})
    with pytest.raises(ParameterError, match=r"x must be a table, got \[1\]"):
        v.reject_unknown_keys("x", [1], {"a"})
    with pytest.raises(ParameterError, match=r"unknown key\(s\) in x: \['1', 'b'\]"):
        v.reject_unknown_keys("x", {1: 0, "b": 0, "a": 0}, {"a"})  # keys of mixed types sort
    with pytest.raises(ParameterError, match=r"m must be a string, one of \['a', 'b'\], got \['a'\]"):
        v.one_of("m", ["a"], ("a", "b"))  # a list is not hashed, and not compared as if a string


def test_bounded_numbers_name_the_range():
    assert v.bounded_float("s", 2, 1.0, 3.0) == 2.0
    with pytest.raises(ParameterError, match=r"s must lie in \[1, 3\] m, got 4"):
        v.bounded_float("s", 4, 1.0, 3.0, unit="m")
    with pytest.raises(ParameterError, match=r"s must be positive, got 0"):
        v.bounded_float("s", 0, 0.0, 3.0, low_open=True)
    with pytest.raises(ParameterError, match=r"s must be non-negative, got -1"):
        v.bounded_float("s", -1, 0.0, 3.0)
    with pytest.raises(ParameterError, match=r"n must be at most 10, got 4294967297"):
        v.bounded_int("n", 4294967297, 1, 10)
    with pytest.raises(ParameterError, match=r"n must be positive, got 0"):
        v.bounded_int("n", 0, 1, 10)
    with pytest.raises(ParameterError, match=r"n must lie in \[5, 10\], got 2"):
        v.bounded_int("n", 2, 5, 10)
    with pytest.raises(ParameterError, match=r"n must be an integer, got 2.0"):
        v.bounded_int("n", 2.0, 1, 10)


def test_regular_file_names_the_kind(tmp_path):
    good = tmp_path / "a.txt"
    good.write_text("hi")
    assert v.regular_file("the file", good, max_bytes=2) == 2
    with pytest.raises(ParameterError, match=r"holds 2 bytes \(0 MiB\), more than the 1 bytes"):
        v.regular_file("the file", good, max_bytes=1)
    os.mkfifo(tmp_path / "fifo")
    for path, kind in ((tmp_path, "a directory"), (tmp_path / "fifo", r"a named pipe \(FIFO\)")):
        with pytest.raises(ParameterError, match=rf"the file '.*' is {kind}, not a regular file"):
            v.regular_file("the file", path, max_bytes=10)
    with pytest.raises(ParameterError, match=r"the file '.*nothing' does not exist"):
        v.regular_file("the file", tmp_path / "nothing", max_bytes=10)
    with pytest.raises(ParameterError, match=r"contains a NUL character"):
        v.regular_file("the file", "a\0b", max_bytes=10)
    loop = tmp_path / "loop"
    loop.symlink_to(loop)
    with pytest.raises(ParameterError, match=r"the file '.*loop' cannot be examined: "):
        v.regular_file("the file", loop, max_bytes=10)


def test_fields_by_flag_names_the_first_invalid_flag_and_skips_options_not_given():
    from dataclasses import dataclass

    from lfrefract.validate import fields_by_flag, named

    @dataclass(frozen=True)
    class Options:
        k: int = 8
        spp: int = 1

        def __post_init__(self):
            v.positive_int("k", self.k)
            v.positive_int("spp", self.spp)

    assert fields_by_flag(Options, {"--k": {"k": 3}, "--spp": {"spp": None}}) == {"k": 3}
    with pytest.raises(ParameterError, match=r"^--spp: spp must be positive, got 0$"):
        fields_by_flag(Options, {"--k": {"k": 3}, "--spp": {"spp": 0}})
    with pytest.raises(ParameterError, match=r"^--k: k must be positive, got 0$"), named("--k"):
        v.positive_int("k", 0)


def test_the_docstring_examples_of_validate_hold():
    import doctest

    import lfrefract.validate

    assert doctest.testmod(lfrefract.validate).failed == 0
