"""The one YAML loader (quadctl.config.yamlio): numbers, duplicate keys, and the bounds it keeps.

Configs and sweep files go through the same :func:`quadctl.config.yamlio.load`; the CLI tests of both
are in test_config_loading.py and test_errors.py.
"""

from __future__ import annotations

import math
import os
import time

import pytest

from quadctl.config import yamlio
from quadctl.errors import ConfigError, SweepError


def load(text: str):
    return yamlio.load(text, "c.yaml")


@pytest.mark.parametrize("text,value", [
    ("68e-3", 0.068), ("5e0", 5.0), ("1E5", 1e5), ("+2e-1", 0.2), ("0.068", 0.068), (".5", 0.5),
    ("-.inf", -math.inf), ("1_000", 1000), ("010", 10), ("0o17", 15), ("0x1F", 31), ("0b101", 5),
    ("-7", -7), ("1e400", math.inf),
])
def test_numbers_read_as_yaml_1_2(text, value):
    """YAML 1.1 (PyYAML) reads 68e-3 as text, 010 as eight and 1:30 as ninety."""
    got = load(f"x: {text}")["x"]
    assert got == value and type(got) is type(value)


@pytest.mark.parametrize("text", ["1:30", "2024-01-01", "1e", "e5", "0x", "inf", "nan", "10**30"])
def test_text_that_is_not_a_number_stays_text(text):
    assert load(f"x: {text}")["x"] == text


def test_nan():
    assert math.isnan(load("x: .nan")["x"])


def test_a_huge_whole_number_is_refused_before_conversion():
    with pytest.raises(ConfigError, match=r"^c\.yaml: line 1: a whole number of 5000 digits "
                                          r"\(quadctl reads at most 400\)"):
        load("x: " + "9" * 5000)


@pytest.mark.parametrize("text,message", [
    ("vehicle:\n  mass: 0.068\n  gravity: 9.81\n  mass: 0.5\n",
     r"^c\.yaml: vehicle\.mass: duplicate key at lines 2 and 4; keep one \(YAML would silently take the last\)$"),
    ("a: 1\na: 1\n", r"^c\.yaml: a: duplicate key at lines 1 and 2"),
    ("lqr: {roll: {Q: [1], Q: [2]}}\n", r"^c\.yaml: lqr\.roll\.Q: duplicate key at lines 1 and 1"),
    ("s:\n  - {x: 1}\n  - {x: 1, y: 2, 'x': 3}\n", r"^c\.yaml: s\[1\]\.x: duplicate key at lines 3 and 3"),
])
def test_duplicate_keys_are_refused_with_both_lines(text, message):
    with pytest.raises(ConfigError, match=message):
        load(text)


def test_a_merge_key_overridden_is_not_a_duplicate():
    assert load("base: &b {mass: 1}\nv: {<<: *b, mass: 2}\n")["v"] == {"mass": 2}


def test_the_error_class_is_the_callers():
    with pytest.raises(SweepError, match=r"^s\.yaml: a: duplicate key"):
        yamlio.load("a: 1\na: 2\n", "s.yaml", SweepError)


def billion_laughs(levels: int = 9) -> str:
    """The classic: 9 levels of 9 aliases each, 9^9 strings from about 1.6 kB."""
    lines = ['lol0: &lol0 "lol"']
    lines += [f"lol{i}: &lol{i} [" + ", ".join([f"*lol{i - 1}"] * 9) + "]" for i in range(1, levels + 1)]
    return "\n".join(lines) + "\n"


def test_an_alias_bomb_is_refused_while_parsing():
    text = billion_laughs()
    assert len(text) < 1700
    start = time.perf_counter()
    with pytest.raises(ConfigError, match=r"^c\.yaml: lol6: at line 7 the aliases \(\*name\) expand the document "
                                          r"past 2,000,000 values and characters: a YAML alias bomb\?"):
        load(text)
    assert time.perf_counter() - start < 5  # refused before anything is built from it


def test_aliases_that_expand_modestly_are_fine():
    data = load("q: &q [1, 50, 1]\nroll: {Q: *q}\npitch: {Q: *q}\n" + billion_laughs(4))
    assert data["pitch"]["Q"] == [1, 50, 1] and len(data["lol4"]) == 9


def test_a_long_string_repeated_by_aliases_counts_its_characters():
    text = f"s: &s {'x' * 100_000}\nl: [{', '.join(['*s'] * 30)}]\n"
    with pytest.raises(ConfigError, match=r"^c\.yaml: l: .*past 2,000,000 values and characters"):
        load(text)


def test_a_recursive_alias_is_refused():
    with pytest.raises(ConfigError, match=r"^c\.yaml: x\[0\]: the alias at line 1 refers to a mapping or list that "
                                          r"contains it \(a recursive alias\)"):
        load("x: &a [*a]")


@pytest.mark.parametrize("text", ["x: " + "[" * 5000 + "]" * 5000, "x: " + "{a: " * 5000 + "1" + "}" * 5000,
                                  "? " * 3000 + "a"])
def test_deep_nesting_is_refused_before_recursing(text):
    with pytest.raises(ConfigError, match=rf"nested more than {yamlio.MAX_DEPTH} levels deep at line 1; "
                                          r"a config nests about 5"):
        load(text)


def test_nesting_a_config_needs_is_fine():
    depth = yamlio.MAX_DEPTH - 1
    assert load("[" * depth + "]" * depth) is not None


@pytest.mark.parametrize("text,message", [
    ("name: [forward\n", r"^c\.yaml: YAML syntax error at line 1, column 7: .*; fix the YAML$"),
    ("\x1fname: x\n", r"^c\.yaml: YAML syntax error: .*special characters are not allowed"),
    ("a: !!python/object:os.system x\n", r"^c\.yaml: YAML error at line 1, column 4: could not determine a "
                                         r"constructor"),
    ("a: 1\n---\nb: 2\n", r"^c\.yaml: YAML error at line 2, column 1: but found another document"),
])
def test_yaml_errors_are_one_line(text, message):
    with pytest.raises(ConfigError, match=message) as info:
        load(text)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("text,message", [
    ("vehicle:\n  mass: 0.068\n\tgravity: 9.81\n",
     "c.yaml: YAML syntax error at line 3, column 1: a tab character; YAML indents with spaces, not tabs: "
     "replace the tab with spaces"),
    ("vehicle:\n  mass:0.068      # kg\n  gravity: 9.81\n",
     "c.yaml: YAML syntax error at line 3, column 3: expected <block end>, but found '<block mapping start>'; "
     "line 2 has `mass:0.068`, one word to YAML: write `key: value` with a space after the colon"),
    ("name:forward\ndescription: a\n",
     "c.yaml: YAML syntax error at line 2, column 12: mapping values are not allowed here; line 1 has "
     "`name:forward`, one word to YAML: write `key: value` with a space after the colon"),
])
def test_a_tab_or_a_missing_space_after_a_colon_is_told_in_plain_words(text, message):
    with pytest.raises(ConfigError) as info:
        load(text)
    assert str(info.value) == message


@pytest.mark.parametrize("text,message", [
    ("name: hover\nvehicle\n  mass: 0.068\n",
     "c.yaml: YAML syntax error at line 2, column 1: while scanning a simple key, could not find expected ':' "
     "(reading stopped at line 3, column 7); fix the YAML"),
    ("name: hover\nseed: 1\ninertia: [6.9e-5, 7.75e-5\ndrag: 0.2\n",
     "c.yaml: YAML syntax error at line 3, column 10: while parsing a flow sequence, expected ',' or ']', but got "
     "':' (reading stopped at line 4, column 5); fix the YAML"),
    ("name: 'hover\nseed: 1\n",
     "c.yaml: YAML syntax error at line 1, column 7: while scanning a quoted scalar, found unexpected end of "
     "stream (reading stopped at line 3, column 1); fix the YAML"),
])
def test_a_syntax_error_points_at_the_line_where_the_problem_starts(text, message):
    with pytest.raises(ConfigError) as info:
        load(text)
    assert str(info.value) == message


def test_text_longer_than_the_cap_is_refused():
    with pytest.raises(ConfigError, match=r"^c\.yaml: 1,000,001 characters, more than the 1,000,000 quadctl reads; "
                                          r"a config or sweep file is a few kB: check the file$"):
        load("#" * (yamlio.MAX_BYTES + 1))


# ---------------------------------------------------------------------------------------
# Writing YAML for people


def test_dumped_yaml_keeps_unicode_and_does_not_fold_long_text():
    text = "Crazyflie 2.x hover at 1 m: 500 Hz discrete LQR within its rotor limits (Förster 2015) " * 3
    dumped = yamlio.dump({"description": text, "mass": 0.027})
    assert dumped.splitlines()[0] == f"description: '{text}'"
    assert load(dumped) == {"description": text, "mass": 0.027}


@pytest.mark.parametrize("value", ["1e5", "010", "0x1F", "yes", "null", "1.5"])
def test_dumped_yaml_quotes_text_quadctl_would_read_as_another_type(value):
    assert load(yamlio.dump({"a": value})) == {"a": value}
    assert load(f"a: {yamlio.flow(value)}") == {"a": value}


def test_flow_yaml_is_one_line_that_reads_back():
    value = {"note": "Förster, identified from log.csv " * 4, "inertia": [6.9e-05, 7.75e-05, 1.5e-04]}
    line = yamlio.flow(value)
    assert "\n" not in line and "Förster" in line
    assert load(f"a: {line}") == {"a": value}


@pytest.mark.parametrize(("value", "written"), [
    (4.0, "4.0"), (111000000.0, "1.11e+08"), (1e-05, "1.0e-05"), (0.1 + 0.2, "0.30000000000000004"),
    (123456789.0, "123456789.0"), (-0.0, "-0.0"), (float("inf"), ".inf"), (-float("inf"), "-.inf"),
])
def test_a_number_is_written_as_short_as_it_reads_back(value, written):
    """Six significant digits where they hold the number exactly, a float to any YAML reader (PyYAML's
    ``safe_load`` reads ``1e-05`` as text); every digit where they do not."""
    import yaml

    assert yamlio.flow(value) == written
    for back in (load(f"a: {written}")["a"], load(yamlio.dump({"a": value}))["a"],
                 yaml.safe_load(yamlio.dump({"a": value}))["a"]):
        assert isinstance(back, float)
        assert (back, math.copysign(1.0, back)) == (value, math.copysign(1.0, value))  # -0.0 keeps its sign


def test_flow_yaml_keeps_the_keys_in_their_order():
    assert yamlio.flow({"pD": 0.5, "theta": 0.1, "phi": 0.1}) == "{pD: 0.5, theta: 0.1, phi: 0.1}"


# ---------------------------------------------------------------------------------------
# Reading files


def read(path):
    return yamlio.read_text(path, str(path), "config file")


def test_a_large_file_is_refused_from_its_size(tmp_path):
    path = tmp_path / "big.yaml"
    with open(path, "wb") as f:
        f.truncate(50_000_000)  # sparse: 50 MB that cost nothing to make
    with pytest.raises(ConfigError, match=r"big\.yaml: more than 1,000,000 bytes, the most quadctl reads for a "
                                          r"config file; a config file is a few kB: check the path$"):
        read(path)


@pytest.mark.skipif(not os.path.exists("/dev/zero"), reason="needs /dev/zero")
def test_an_endless_device_is_read_up_to_the_cap():
    with pytest.raises(ConfigError, match=r"^/dev/zero: more than 1,000,000 bytes"):
        read("/dev/zero")


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs named pipes")
def test_a_pipe_is_read(tmp_path):
    import threading

    fifo = tmp_path / "config.fifo"
    os.mkfifo(fifo)
    writer = threading.Thread(target=lambda: fifo.write_text("name: piped\n"))
    writer.start()
    assert read(fifo) == "name: piped\n"
    writer.join()


@pytest.mark.parametrize("make,message", [
    (lambda p: p.mkdir(), r"is a folder, not a config file; give a \.yaml file"),
    (lambda p: None, r"no such config file; check the path"),
    (lambda p: p.write_bytes(b"name: \xff\n"), r"cannot read the config file \(not UTF-8 text: invalid start byte at "
                                              r"byte 6\); save it as UTF-8"),
])
def test_unreadable_files(tmp_path, make, message):
    path = tmp_path / "c.yaml"
    make(path)
    with pytest.raises(ConfigError, match=message):
        read(path)


def test_the_pid_presets_read_by_libyaml_are_what_pythons_yaml_reader_reads():
    import yaml

    from quadctl.config import pid

    if not hasattr(yaml, "CSafeLoader"):
        pytest.skip("PyYAML without libyaml: the presets are read in Python")
    with open(pid.PRESETS_FILE, encoding="utf-8") as fh:
        expected = yaml.load(fh, Loader=yaml.SafeLoader)
    pid.presets.cache_clear()
    assert pid.presets() == expected
