"""The SUT spec: valid specs load into typed objects; each malformed one gets
one precise message (file, line, column, fix) and no traceback."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from astaa_deft.model.errors import InputError
from astaa_deft.engine.spec.loader import load_spec

GOOD = textwrap.dedent("""\
    name: mini
    params: {rate: "10"}
    modules:
      - name: talker
        command: ["{python}", "-m", "talker", "--rate", "{rate}", "--cfg", "{zenoh_config}"]
        ready: {channel: data, timeout: 5}
      - name: listener
        command: listener --verbose
        env: {LEVEL: debug}
    channels:
      - name: data
        key: mini/data
        producer: talker
        consumers: [listener]
        type: Sample
    types:
      Header:
        seq: uint64
        stamp: time
      Point:
        x: float64
        y: {type: float32, min: -10, max: 10}
      Sample:
        header: Header
        points: {array: Point, max_length: 8}
        mode: {enum: [idle, run]}
        tags: string[]
    brittle: [Header.stamp, Header.seq]
    """)


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "sut.yaml"
    path.write_text(text)
    return path


def test_good_spec_loads_typed(tmp_path):
    spec = load_spec(write(tmp_path, GOOD))
    assert spec.name == "mini"
    assert [m.name for m in spec.modules] == ["talker", "listener"]
    assert spec.module("listener").command == ("listener", "--verbose")
    assert spec.module("talker").ready.channel == "data"
    sample = spec.types["Sample"].fields
    assert sample["points"].kind == "array" and sample["points"].items.ref == "Point"
    assert sample["points"].max_length == 8
    assert sample["mode"].values == ("idle", "run")
    assert sample["tags"].items.kind == "string"
    assert spec.types["Point"].fields["y"].maximum == 10
    assert spec.channel("data").consumers == ("listener",)
    assert spec.brittle == ("Header.stamp", "Header.seq")


# (description, replace this, with this, expected message part, expected line)
MALFORMED = [
    ("unknown top-level key", "brittle:", "britle:", "unknown key 'britle' in the spec — did you mean 'brittle'?", 28),
    ("missing name", "name: mini\n", "", "the spec lacks 'name'", 1),
    ("bad module name", "- name: talker\n", "- name: talk er\n", "module name 'talk er' has characters", 4),
    ("unknown module key", "ready: {channel", "readiness: {channel", "unknown key 'readiness' in a module — did you mean 'ready'?", 6),
    ("command of wrong type", "command: listener --verbose", "command: 42", "command of 'listener' must be a list or a string", 8),
    ("unknown placeholder", "{zenoh_config}", "{zenoh_cfg}", "unknown placeholder '{zenoh_cfg}' — did you mean 'zenoh_config'?", 5),
    ("ready needs one of", "ready: {channel: data, timeout: 5}", "ready: {timeout: 5}", "'ready' needs exactly one of", 6),
    ("negative ready delay", "ready: {channel: data, timeout: 5}", "ready: {delay: -1}", "'ready.delay' must be ≥ 0", 6),
    ("unknown consumer", "consumers: [listener]", "consumers: [listner]", "unknown module 'listner' — did you mean 'listener'?", 14),
    ("unknown producer", "producer: talker", "producer: speaker", "unknown module 'speaker'", 13),
    ("wildcard key", "key: mini/data", "key: mini/**", "key 'mini/**' is not a concrete Zenoh key", 12),
    ("unknown message type", "type: Sample", "type: Sampel", "unknown message type 'Sampel' — did you mean 'Sample'?", 15),
    ("unknown field type", "x: float64", "x: float46", "unknown type 'float46' — did you mean 'float64'?", 21),
    ("min above max", "min: -10, max: 10", "min: 10, max: -10", "min 10 > max -10", 22),
    ("empty enum", "{enum: [idle, run]}", "{enum: []}", "enum of 'Sample.mode' must be a non-empty list", 26),
    ("bad length bound", "max_length: 8", "max_length: -3", "length bound of 'Sample.points' must be a whole number", 25),
    ("brittle unknown field", "Header.seq]", "Header.sequence]", "Header has no field 'sequence' (it has: seq, stamp)", 28),
    ("bad encoding", "type: Sample\n", "type: Sample\n    encoding: jsn\n", "unknown encoding 'jsn' — did you mean 'json'?", 16),
    ("duplicate channel key", "producer: talker", "producer: talker\n    key: mini/other", "duplicate key 'key'", 14),
    ("readiness channel unknown", "{channel: data,", "{channel: dta,", "readiness channel 'dta' is not declared — did you mean 'data'?", 6),
    ("self-containing type", "x: float64", "x: Point", "type 'Point' contains itself", 20),
    ("tab / YAML syntax", "modules:\n", "modules:\n\t- oops\n", "not valid YAML", 4),
    ("endpoint not a locator", "name: mini\n", "name: mini\nzenoh: {endpoints: [\"127.0.0.1:7447\"]}\n", "is not a Zenoh locator", 2),
    ("consumer is producer", "consumers: [listener]", "consumers: [talker]", "module 'talker' consumes its own channel 'data'", 14),
]


@pytest.mark.parametrize("what,old,new,message,line", MALFORMED, ids=[m[0] for m in MALFORMED])
def test_malformed_spec_is_one_clear_error(tmp_path, what, old, new, message, line):
    assert old in GOOD, what
    path = write(tmp_path, GOOD.replace(old, new, 1))
    with pytest.raises(InputError) as err:
        load_spec(path)
    problems = err.value.problems
    matching = [p for p in problems if message in str(p)]
    assert matching, f"{what}: expected {message!r} in {[str(p) for p in problems]}"
    assert matching[0].file == str(path)
    assert matching[0].line == line
    assert matching[0].column is not None


def test_empty_and_missing_files(tmp_path):
    with pytest.raises(InputError, match="file not found"):
        load_spec(tmp_path / "nope.yaml")
    with pytest.raises(InputError, match="the file is empty"):
        load_spec(write(tmp_path, ""))
    with pytest.raises(InputError, match="must be a mapping"):
        load_spec(write(tmp_path, "- a\n- b\n"))


def test_cli_spec_check_exit_codes_and_no_traceback(tmp_path):
    good = write(tmp_path, GOOD)
    ok = subprocess.run([sys.executable, "-m", "astaa_deft.cli", "spec", "check", str(good)],
                        capture_output=True, text=True)
    assert ok.returncode == 0, ok.stderr
    assert "ok" in ok.stdout
    bad = tmp_path / "bad.yaml"
    bad.write_text(GOOD.replace("type: Sample", "type: Sampel"))
    res = subprocess.run([sys.executable, "-m", "astaa_deft.cli", "spec", "check", str(bad)],
                         capture_output=True, text=True)
    assert res.returncode == 2
    assert "Traceback" not in res.stderr
    assert f"{bad}:15:11: unknown message type 'Sampel'" in res.stderr


def test_entries_without_names_are_reported_not_a_traceback(tmp_path):
    """Found by the generated specs: two unnamed channels (or modules) crashed the duplicate-name check."""
    path = write(tmp_path, "name: x\nmodules: [{}, {}]\nchannels: [{}, {}]\n")
    with pytest.raises(InputError) as err:
        load_spec(path)
    text = str(err.value)
    assert "a channel lacks 'name'" in text and "a module lacks 'name'" in text
    assert "declared twice" not in text
