"""Malformed invariants are spec errors with file, line, column and a fix — never a crash mid-run."""

from __future__ import annotations

import pytest
from monitor_helpers import line_of, spec_problems, spec_text

from astaa_deft.model.errors import Problem


def only_problem(invariants: str) -> Problem:
    problems = spec_problems(invariants)
    assert len(problems) == 1, "\n".join(map(str, problems))
    problem = problems[0]
    assert problem.file == "sut.yaml"
    assert problem.fix, f"no fix in: {problem}"
    return problem


def column_of(invariants: str, needle: str) -> int:
    """1-based column of ``needle`` on its line of the full spec text."""
    text = spec_text(invariants)
    line = text.splitlines()[line_of(text, needle) - 1]
    return line.index(needle) + 1


def temporal(formula: str, signals: str = "{speed: {channel: localization, field: speed}}",
             period: str = "0.1") -> str:
    return f'- {{name: a, kind: temporal, period: {period}, signals: {signals}, formula: "{formula}"}}'


def collision(ego: str = "{channel: localization, length: 4, width: 1.9}",
              obstacles: str = "{channel: obstacles, array: obstacles}") -> str:
    return f"- {{name: a, kind: collision, ego: {ego}, obstacles: {obstacles}}}"


# (invariant YAML, words of the message, text on the offending line, text the column points at or None)
CASES = [
    # the common part
    ("- {name: a, kind: bounds, channel: command}", "'kind' must be one of", "kind: bounds", "bounds"),
    ("- {name: a, kind: bound, channel: command, field: acceleration, mni: 0}", "unknown key 'mni'", "mni", "mni"),
    ("- {kind: bound, channel: command, field: acceleration, min: 0}", "lacks 'name'", "kind: bound", None),
    ("- {name: 'bad name', kind: bound, channel: command, field: acceleration, min: 0}",
     "has characters other than", "bad name", None),
    ("- {name: a, kind: bound, severity: severe, channel: command, field: acceleration, min: 0}",
     "'severity' must be one of", "severe", "severe"),
    ("- {name: a, kind: bound, crash: crashy, channel: command, field: acceleration, min: 0}",
     "'crash' must be one of", "crashy", "crashy"),
    # bound
    ("- {name: a, kind: bound, channel: comand, field: acceleration, min: 0}", "unknown channel 'comand'",
     "comand", "comand"),
    ("- {name: a, kind: bound, channel: command, field: accel, min: 0}", "has no field 'accel'", "accel", "accel"),
    ("- {name: a, kind: bound, channel: trajectory, field: \"points[*].speed\", min: 0}", "has no field 'speed'",
     "points", "speed"),
    ("- {name: a, kind: bound, channel: command, field: header, min: 0}", "need a numeric field", "header", None),
    ("- {name: a, kind: bound, channel: command, field: acceleration, non_empty: true}",
     "'non_empty' needs an array or a string", "non_empty", None),
    ("- {name: a, kind: bound, channel: command, field: acceleration, in_enum: true}", "'in_enum' needs an enum",
     "in_enum", None),
    ("- {name: a, kind: bound, channel: command, field: acceleration, min: 4, max: -8}", "greater than 'max'",
     "min: 4", None),
    ("- {name: a, kind: bound, channel: command, field: acceleration}", "checks nothing", "field: acceleration",
     None),
    ("- {name: a, kind: bound, channel: command, field: acceleration, min: fast}", "must be a finite number",
     "fast", "fast"),
    # expression
    ("- {name: a, kind: expression, channel: status, expr: \"ego_speed <= spede\"}", "unknown field 'spede'",
     "spede", "spede"),
    ("- {name: a, kind: expression, channel: status, expr: \"mode > 3\"}", "cannot order", "mode > 3", "mode"),
    ("- {name: a, kind: expression, channel: status, expr: \"ego_speed == 'fast'\"}", "never equal",
     "ego_speed ==", "ego_speed"),
    ("- {name: a, kind: expression, channel: status, expr: \"__import__('os')\"}", "'__import__' is not allowed",
     "__import__", "__import__"),
    ("- {name: a, kind: expression, channel: status, expr: \"mode.__class__ == 1\"}", "'__class__' is not allowed",
     "__class__", "__class__"),
    ("- {name: a, kind: expression, channel: status, expr: \"ego_speed + 1\"}", "needed", "ego_speed + 1", None),
    ("- {name: a, kind: expression, channel: status, expr: \"ego_speed <\"}", "not a valid expression",
     "ego_speed <", None),
    ("- {name: a, kind: expression, channel: status, expr: 3}", "must be a non-empty string", "expr: 3", "3"),
    # deadline
    ("- {name: a, kind: deadline, channel: trajectory, module: planning, max_gap: 1}", "either a 'channel' or",
     "kind: deadline", None),
    ("- {name: a, kind: deadline, channel: trajectory, max_gap: -1}", "greater than 0", "max_gap", "-1"),
    ("- {name: a, kind: deadline, channel: trajectory, max_gap: 1, after: last}", "'after' must be one of",
     "after: last", "last"),
    ("- {name: a, kind: deadline, module: planing, max_gap: 1}", "unknown module 'planing'", "planing", "planing"),
    ("- {name: a, kind: deadline, channel: command, responds_to: command, max_gap: 1}", "cannot answer itself",
     "responds_to", None),
    # process
    ("- {name: a, kind: process, modules: [contrl]}", "unknown module 'contrl'", "contrl", "contrl"),
    ("- {name: a, kind: process, modules: [control], restart_counter: header.count}", "has a numeric field",
     "restart_counter", None),
    # temporal
    (temporal("always(speed >"), "not a valid formula", "always(speed", None),
    (temporal("always(sped < 3)"), "unknown signal 'sped'", "sped <", "sped"),
    (temporal("speed > 1 implies eventually(speed < 3)"), "unbounded 'eventually'", "implies", None),
    (temporal("eventually[0:0.25](speed < 3)"), "whole number of samples", "0.25", None),
    (temporal("speed / 2 < 3"), "'/' is not allowed", "speed / 2", None),
    (temporal("next(speed < 3)"), "'next' is not supported", "next(", "next"),
    (temporal("Speed < 3", signals="{Speed: {channel: localization, field: speed}}"),
     "must start with a lowercase letter", "Speed:", "Speed:"),
    (temporal("gear > 0", signals="{gear: {channel: trajectory, field: gear}}"),
     "needs a number or a boolean", "field: gear", "gear}"),
    (temporal("speed < 3", signals="{speed: {channel: localization, field: speed}, x: {channel: localization, "
                                   "field: x}}"), "not used in the formula", "signals", None),
    (temporal("speed < 3", period="0"), "greater than 0", "period: 0", None),
    # collision
    (collision(ego="{channel: localization, width: 1.9}"), "'ego' lacks 'length'", "ego:", None),
    (collision(obstacles="{channel: obstacles, array: header}"), "this needs an array", "array: header", "header"),
    (collision(obstacles="{channel: obstacles, array: obstacles, x: pos_x}"), "has no field 'pos_x'", "pos_x",
     "pos_x"),
    (collision(ego="{channel: status, length: 4, width: 1.9}"), "Status has no field 'x'", "channel: status", None),
]


@pytest.mark.parametrize("invariants, words, on_line, at", CASES, ids=[c[1] for c in CASES])
def test_each_malformed_invariant_is_one_located_spec_error(invariants, words, on_line, at):
    problem = only_problem(invariants)
    assert words in problem.message
    assert problem.line == line_of(spec_text(invariants), on_line)
    if at is not None:
        assert problem.column == column_of(invariants, at), str(problem)


def test_every_problem_is_reported_at_once_and_valid_invariants_survive():
    problems = spec_problems("""
        - {name: ok, kind: bound, channel: command, field: acceleration, finite: true}
        - {name: a, kind: bound, channel: command, field: accel, min: 0}
        - {name: b, kind: expression, channel: status, expr: "__import__('os')"}
        - {name: ok, kind: process}
        """)
    messages = [p.message for p in problems]
    assert len(problems) == 3, messages
    assert any("accel" in m for m in messages)
    assert any("__import__" in m for m in messages)
    assert any("declared twice" in m for m in messages)


def test_an_invariants_section_that_is_not_a_list_is_an_error():
    problems = spec_problems("name: x")
    assert "'invariants' must be a list" in problems[0].message
