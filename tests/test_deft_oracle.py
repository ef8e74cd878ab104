"""The DeFT collision oracle and module-test export on a crafted log.

A toy planner (tests/sut/toy_planner.py) drives at an obstacle predicted in
its path; the log records a collision. Extraction must turn the faulty
frames into oracle tests that fail with that planner and pass once it is
"fixed" (plans to stop) — and frame tests that fail, with a readable diff,
when the planner's output changes.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from astaa_deft.analysis.deft.export import MANIFEST
from astaa_deft.io.log.writer import LogWriter
from astaa_deft.engine.spec.loader import load_spec

SUT = Path(__file__).parent / "sut"

SPEC = textwrap.dedent("""\
    name: toy
    params: {stop: "off", shift: "0"}
    modules: [{name: sim, command: "true"}, {name: planner, command: "true"}]
    channels:
      - {name: pose, key: toy/pose, producer: sim, consumers: [planner], type: Pose}
      - {name: tick, key: toy/tick, producer: sim, consumers: [planner], type: Tick}
      - {name: plan, key: toy/plan, producer: planner, consumers: [], type: Plan}
    types:
      Header: {seq: uint64, stamp: time}
      Pose: {header: Header, x: float64, y: float64, speed: float64}
      Box: {t: time, x: float64, y: float64, heading: float64}
      Obstacle: {id: uint32, length: float64, width: float64, trajectory: {array: Box}}
      Tick: {header: Header, obstacles: {array: Obstacle}}
      Point: {t: time, x: float64, y: float64, heading: float64}
      Plan: {header: Header, points: {array: Point}}
    planner:
      module: planner
      inputs: [pose, tick]
      trigger: tick
      output: plan
      trajectory: {points: points, x: x, y: y, t: t}
      replay: {factory: "toy_planner:ToyPlanner", args: {stop: "{stop}", shift: "{shift}"}}
      oracle:
        collision:
          ego: {length: 4.0, width: 2.0}
          obstacles: {channel: tick, array: obstacles, trajectory: trajectory}
    """)


def crafted_log(tmp_path: Path) -> tuple[Path, Path]:
    """10 planning cycles at 10 Hz; an obstacle stands at x = 15; the ego drives at 10 m/s from x = 0."""
    spec_path = tmp_path / "toy.yaml"
    spec_path.write_text(SPEC)
    sys.path.insert(0, str(SUT))  # the spec's replay factory must be importable for the spec to load
    try:
        spec = load_spec(spec_path)
        from toy_planner import ToyPlanner
    finally:
        sys.path.remove(str(SUT))
    log_path = tmp_path / "toy.mcap"
    w = LogWriter(log_path, spec)
    ids = {name: w.bus_channel(spec.channel(name)) for name in ("pose", "tick", "plan")}

    planner = ToyPlanner()
    t0 = 1_000_000_000
    obstacle = {"id": 7, "length": 4.0, "width": 2.0,
                "trajectory": [{"t": 0.1 * i, "x": 15.0, "y": 0.0, "heading": 0.0} for i in range(40)]}
    for k in range(10):
        now = 0.1 * k
        pose = {"header": {"seq": k + 1, "stamp": now}, "x": 10.0 * now, "y": 0.0, "speed": 10.0}
        tick = {"header": {"seq": k + 1, "stamp": now}, "obstacles": [obstacle]}
        base = t0 + k * 100_000_000
        w.message(ids["pose"], base, json.dumps(pose).encode())
        w.message(ids["tick"], base + 1_000_000, json.dumps(tick).encode())
        plan = planner.step({"pose": pose, "tick": tick})
        w.message(ids["plan"], base + 5_000_000, json.dumps(plan).encode())
    w.event("run_started", time_ns=t0)
    w.event("violation", time_ns=t0 + 2_000_000_000, invariant="no_collision", invariant_kind="collision")
    w.metadata("astaa-deft.run", {"spec": "toy", "params": json.dumps({"stop": "off", "shift": "0"})})
    w.finish()
    return spec_path, log_path


def cli(*args: str, cwd: Path | None = None, extra_path: Path | None = None) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(SUT), env.get("PYTHONPATH", "")]))
    return subprocess.run([sys.executable, *args], capture_output=True, text=True, env=env, cwd=cwd)


def set_params(suite: Path, **params: str) -> None:
    manifest = json.loads((suite / MANIFEST).read_text())
    manifest["params"].update(params)
    (suite / MANIFEST).write_text(json.dumps(manifest))


def test_collision_oracle_fails_then_passes_with_the_fixed_planner(tmp_path):
    spec_path, log_path = crafted_log(tmp_path)
    suite = tmp_path / "suite"
    res = cli("-m", "astaa_deft.cli", "extract", str(log_path), "--spec", str(spec_path), "-o", str(suite))
    assert res.returncode == 0, res.stderr
    assert "10 module tests" in res.stdout
    manifest = json.loads((suite / MANIFEST).read_text())
    # Frame k plans from x = k to x = k + 9 m; boxes 4 m long overlap once a planned centre passes
    # x = 11, i.e. from frame 3 on (frame 2 only touches it): frames 3…9 are faulty plans.
    assert [o["frame"] for o in manifest["oracles"]] == list(range(3, 10))
    assert all(o["recorded"]["obstacle"] == 7 for o in manifest["oracles"])
    log_path.unlink()  # the suite must not need the log

    run = cli("-m", "pytest", "-q", "-p", "no:cacheprovider", str(suite), cwd=tmp_path)
    assert run.returncode == 1
    assert "7 failed, 10 passed" in run.stdout
    assert "reaches obstacle 7" in run.stdout

    set_params(suite, stop="on")  # the fixed planner stops: no plan reaches the obstacle
    run = cli("-m", "pytest", "-q", "-p", "no:cacheprovider", "-k", "oracle", str(suite), cwd=tmp_path)
    assert run.returncode == 0, run.stdout
    assert "7 passed" in run.stdout


def test_frame_tests_fail_with_a_readable_diff_when_the_output_changes(tmp_path):
    spec_path, log_path = crafted_log(tmp_path)
    suite = tmp_path / "suite"
    assert cli("-m", "astaa_deft.cli", "extract", str(log_path), "--spec", str(spec_path),
               "-o", str(suite)).returncode == 0
    set_params(suite, shift="0.25")
    run = cli("-m", "pytest", "-q", "-p", "no:cacheprovider", "-k", "frame_00003", str(suite), cwd=tmp_path)
    assert run.returncode == 1
    assert "frame 3: the planner's output changed" in run.stdout
    assert "largest point error 0.25 m" in run.stdout
    assert "recorded x,y" in run.stdout and "replayed x,y" in run.stdout


def test_oracle_tests_run_first_from_a_snapshot_before_their_frame(tmp_path):
    """TTRF: a suite that reproduces a collision fails at its first test, one planner step from a snapshot."""
    from astaa_deft.analysis.deft.oracle_entry import OracleEntry
    from astaa_deft.analysis.deft.snapshots import usable_snapshot
    from astaa_deft.analysis.deft.suite import Suite

    spec_path, log_path = crafted_log(tmp_path)
    suite_dir = tmp_path / "suite"
    res = cli("-m", "astaa_deft.cli", "extract", str(log_path), "--spec", str(spec_path), "-o", str(suite_dir))
    assert res.returncode == 0, res.stderr
    oracles = json.loads((suite_dir / MANIFEST).read_text())["oracles"]
    assert oracles and all(o.get("snapshot") for o in oracles)
    run = cli("-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", str(suite_dir), cwd=tmp_path)
    assert run.returncode == 1 and "1 failed" in run.stdout and "passed" not in run.stdout, run.stdout
    assert "oracle_collision_000" in run.stdout  # the first test run is the oracle, not frame 0
    sys.path.insert(0, str(SUT))
    try:
        suite = Suite(suite_dir)
        for oracle in oracles:  # one step from the snapshot answers as the whole replay in order does
            fast = suite.result_from_snapshot(oracle["frame"], usable_snapshot(suite, OracleEntry.from_json(oracle)))
            slow = next(r for r in suite.results() if r.index == oracle["frame"])
            assert fast.message == slow.message and fast.error is None
        set_params(suite_dir, stop="on")  # another planner than the snapshot's: replayed from the start
        assert all(usable_snapshot(Suite(suite_dir), OracleEntry.from_json(oracle)) is None for oracle in oracles)
    finally:
        sys.path.remove(str(SUT))


def test_an_oracle_entry_reads_its_optional_fields_as_absent():
    from astaa_deft.analysis.deft.oracle_entry import OracleEntry

    bare = OracleEntry.from_json({"kind": "collision", "frame": 4})
    assert (bare.kind, bare.frame, bare.snapshot, bare.snapshot_params, bare.snapshot_code) == (
        "collision", 4, None, None, None)
    assert bare.start_ns == 0 and bare.invariant is None
    full = OracleEntry.from_json({"kind": "invariant", "invariant": "planned_speed", "frame": 7, "start_ns": 12,
                                  "snapshot": "snapshots/frame_00007.pickle",
                                  "snapshot_of": {"params": {"a": "1"}, "code": "abc"}})
    assert (full.invariant, full.start_ns, full.snapshot, full.snapshot_params, full.snapshot_code) == (
        "planned_speed", 12, "snapshots/frame_00007.pickle", {"a": "1"}, "abc")


@pytest.mark.parametrize(("entry", "names"), [
    ({"kind": 3, "frame": 4}, "'kind' is '3', not a string"),
    ({"kind": "collision", "frame": "4"}, "'frame' is '4', not an integer or null"),
    ({"kind": "invariant", "frame": 1, "start_ns": [1]}, "'start_ns' is '[1]', not a number"),
    ({"kind": "collision", "frame": 1, "snapshot_of": ["x"]}, "'snapshot_of' is \"['x']\", not an object or null"),
])
def test_an_oracle_entry_of_the_wrong_type_names_its_field(entry, names):
    from astaa_deft.analysis.deft.oracle_entry import OracleEntry

    with pytest.raises(ValueError) as caught:
        OracleEntry.from_json(entry)
    assert names in str(caught.value)
