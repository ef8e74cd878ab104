"""Hostile YAML as a spec or a dictionary: every case is one exit-2 message naming
file:line:col — no traceback, no hang, bounded memory."""

from __future__ import annotations

import re
import resource
import subprocess
import sys
from pathlib import Path

import pytest

from astaa_deft.cli import main
from astaa_deft.cli.commands.demo import demo_spec_path

BAD = Path(__file__).parent / "data" / "bad_inputs"
DEMO_SPEC = demo_spec_path().read_text()


def _limited() -> None:
    """Runs in the child: 1 GB of address space, 30 s of CPU — a bomb dies instead of swapping."""
    resource.setrlimit(resource.RLIMIT_AS, (1 << 30, 1 << 30))
    resource.setrlimit(resource.RLIMIT_CPU, (30, 30))


def cli(*args: str, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "astaa_deft.cli", *args], capture_output=True, text=True,
                          timeout=timeout, preexec_fn=_limited)


def run_in_process(capsys, *args: str) -> tuple[int, str]:
    code = main(list(args))
    out = capsys.readouterr()
    return code, out.out + out.err


def assert_clear_error(code: int, text: str, name: str) -> None:
    assert "Traceback" not in text, text
    assert code == 2, text
    assert re.search(re.escape(name) + r":\d+(:\d+)?: ", text), text
    assert len(text) < 2000, text  # one message, not a dump of internal nodes


def test_anchor_bomb_refused_fast_with_bounded_memory(tmp_path):
    bomb = BAD / "anchor_bomb.yaml"
    assert bomb.stat().st_size < 600
    for args in (["spec", "check", str(bomb)],
                 ["generate", "--spec", str(demo_spec_path()), "--dictionary", str(bomb), "--count", "1",
                  "--seed", "1", "-o", str(tmp_path / "out")],
                 ["policy", "check", str(BAD.parent / "policies_bad"), "--dictionary", str(bomb)]):
        res = cli(*args)
        assert_clear_error(res.returncode, res.stderr, "anchor_bomb.yaml")
        assert "alias" in res.stderr


CASES = {
    "deep": "name: x\nmodules: " + "[" * 500 + "]" * 500 + "\n",
    "merge": "base: &b {x: 1}\nname: x\nmore:\n  <<: *b\n",
    "tag": "name: !foo bar\n",
    "bigint_value": "name: x\nn: " + "9" * 5000 + "\n",
    "mapping_key": "? {a: 1}\n: 2\n",
    "type_body_list": DEMO_SPEC.replace("  PerceivedObstacle:\n", "  PerceivedObstacle: [1]\n  Unused:\n", 1),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_hostile_spec_is_one_clear_error(case, tmp_path, capsys):
    path = tmp_path / f"{case}.yaml"
    path.write_text(CASES[case])
    code, text = run_in_process(capsys, "spec", "check", str(path))
    assert_clear_error(code, text, path.name)


@pytest.mark.parametrize("case", ["deep", "merge", "tag", "bigint_value"])
def test_hostile_dictionary_is_one_clear_error(case, tmp_path, capsys):
    path = tmp_path / f"{case}.yaml"
    path.write_text(CASES[case])
    code, text = run_in_process(capsys, "generate", "--spec", str(demo_spec_path()), "--dictionary", str(path),
                                "--count", "1", "--seed", "1", "-o", str(tmp_path / "out"))
    assert_clear_error(code, text, path.name)


def test_big_integer_in_a_dictionary_value(tmp_path, capsys):
    path = tmp_path / "dict.yaml"
    path.write_text("float64:\n  - " + "1" * 5000 + "\n")
    code, text = run_in_process(capsys, "generate", "--spec", str(demo_spec_path()), "--dictionary", str(path),
                                "--count", "1", "--seed", "1", "-o", str(tmp_path / "out"))
    assert_clear_error(code, text, path.name)


def test_type_body_not_a_mapping_through_generate(tmp_path, capsys):
    path = tmp_path / "spec.yaml"
    path.write_text(CASES["type_body_list"])
    code, text = run_in_process(capsys, "generate", "--spec", str(path), "--count", "1", "--seed", "1",
                                "-o", str(tmp_path / "out"))
    assert_clear_error(code, text, path.name)
    assert "PerceivedObstacle' must map field names" in text


# (name, replace this in the demo spec, with this, what the message says)
SPEC_CHECK_GAPS = [
    ("empty key before more channels", "key: demo/sim/obstacles", "key: ''", "channel 'obstacles' has an empty key"),
    ("huge max_gap", "max_gap: 1.0,", "max_gap: 1.0e+308,", "'max_gap' must be at most 86400, got 1e+308"),
    ("key ending in a newline", "key: demo/sim/obstacles", 'key: "demo/sim/obstacles\\n"',
     "key 'demo/sim/obstacles\\n' is not a concrete Zenoh key"),
    ("factory as a list", "factory: astaa_deft.demo.planner_core:Planner", "factory: [a, b]",
     "'factory' must be text 'package.module:Name', not a list"),
    ("planner threshold nan", "planner:\n", "planner:\n  threshold: .nan\n", "'planner.threshold' must be a finite number"),
    ("lookback beyond an int64 of ns", "planner:\n", "planner:\n  lookback_ms: 1.0e+308\n",
     "'planner.lookback_ms' must be a finite number ≥ 0 and at most 1e+09"),
    ("control character deep in the file", "  - {name: planning_deadline,", "  - {name: \x00planning_deadline,",
     "not valid YAML: the control character #x0000"),
]


@pytest.mark.parametrize("old,new,expect", [
    ("obstacles: {channel: prediction, array: obstacles, id: id,",
     "obstacles: {channel: prediction, array: obstacles, id: {a: 1},", "'id' must be a field path"),
    ("obstacles: {channel: prediction, array: obstacles, id: id, length: length,",
     "obstacles: {channel: prediction, array: obstacles, id: id, length: [],", "'length' must be a field path"),
    ("astaa_deft.demo.planner_core:Planner", "astaa_deft.demo.no_such_module:Planner", "is neither on the Python path nor in the spec's directory"),
    ("astaa_deft.demo.planner_core:Planner", "astaa_deft.demo.planner_core:NoSuchPlanner", "no callable"),
    *[gap[1:] for gap in SPEC_CHECK_GAPS],
])
def test_spec_check_rejects_what_extract_would_fail_on(old, new, expect, tmp_path, capsys):
    assert old in DEMO_SPEC
    path = tmp_path / "spec.yaml"
    path.write_text(DEMO_SPEC.replace(old, new, 1))
    code, text = run_in_process(capsys, "spec", "check", str(path))
    assert_clear_error(code, text, path.name)
    assert expect in text, text
    assert "Node(" not in text and "KeyError" not in text


def test_yaml_syntax_errors_are_placed_by_line_and_column(tmp_path, capsys):
    """PyYAML's reader places a bad character by offset ("position 9948"); the message gives line:column."""
    lines = DEMO_SPEC.splitlines(keepends=True)
    lines[150] = lines[150].replace(":", ": \x07", 1)
    path = tmp_path / "spec.yaml"
    path.write_text("".join(lines))
    code, text = run_in_process(capsys, "spec", "check", str(path))
    assert_clear_error(code, text, path.name)
    assert f"{path}:151:" in text and "position" not in text, text


def test_a_long_spec_is_read_in_one_pass(tmp_path, capsys):
    """20,000 channels: read without PyYAML's composer (quadratic in a sequence's length)."""
    channels = "".join(f"  - {{name: c{i}, key: big/c{i}, producer: a, consumers: [b], type: S}}\n"
                       for i in range(20_000))
    path = tmp_path / "big.yaml"
    path.write_text("name: big\nmodules: [{name: a, command: 'true'}, {name: b, command: 'true'}]\n"
                    f"channels:\n{channels}types:\n  S: {{seq: uint64, value: float64}}\n")
    code, text = run_in_process(capsys, "spec", "check", str(path))
    assert code == 0, text
    assert "20000 channels" in text
