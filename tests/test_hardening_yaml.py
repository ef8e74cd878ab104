"""Hostile YAML as a spec or a dictionary: every case is one exit-2 message naming
file:line:col — no traceback, no hang, bounded memory (issue 10, items 2, 3, 10)."""

from __future__ import annotations

import re
import resource
import subprocess
import sys
from pathlib import Path

import pytest

from astaa_deft.cli import main
from astaa_deft.commands.demo import demo_spec_path

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


@pytest.mark.parametrize("old,new,expect", [
    ("obstacles: {channel: prediction, array: obstacles, id: id,",
     "obstacles: {channel: prediction, array: obstacles, id: {a: 1},", "'id' must be a field path"),
    ("obstacles: {channel: prediction, array: obstacles, id: id, length: length,",
     "obstacles: {channel: prediction, array: obstacles, id: id, length: [],", "'length' must be a field path"),
    ("astaa_deft.demo.planner_core:Planner", "astaa_deft.demo.no_such_module:Planner", "is neither on the Python path nor in the spec's directory"),
    ("astaa_deft.demo.planner_core:Planner", "astaa_deft.demo.planner_core:NoSuchPlanner", "no callable"),
])
def test_spec_check_rejects_what_extract_would_fail_on(old, new, expect, tmp_path, capsys):
    assert old in DEMO_SPEC
    path = tmp_path / "spec.yaml"
    path.write_text(DEMO_SPEC.replace(old, new, 1))
    code, text = run_in_process(capsys, "spec", "check", str(path))
    assert_clear_error(code, text, path.name)
    assert expect in text
