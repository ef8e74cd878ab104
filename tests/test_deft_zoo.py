"""DeFT on the zoo of module behaviours (tests/zoo): the generator, its floor, extraction held to both.

The generator's own checks run on their own (no bus). A short form of the
zoo (``zoo.SHORT``: three members, 2 s of bus time each) runs in the
default run, the whole zoo behind ``-m slow``; for each member, one real run
on the bus, then: the plain-replay floor is computed; extraction at θ = 0
reproduces at least what the floor does; the extracted suite passes every
test on the very run it came from. Every member is held to both: none is
expected to fail.
"""

from __future__ import annotations

import copy
import json
import math
import os
import pickle
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from zoo import AXES, MEMBERS, MPC, NODE_FRAME_ID, SHORT, SLOW_PLANNER, Floor, Member, record, short, write_member
from zoo.judge import Extracted, SuiteRun, extract, lost, plain_replay, run_suite
from zoo.runtime.zoo_module import Step
from astaa_deft.analysis.deft.planner_section import replay_module_of
from astaa_deft.analysis.deft.replay import make_planner
from astaa_deft.engine.spec.loader import load_spec


# -- the generator ----------------------------------------------------------------------------------


def test_the_catalogue_covers_every_value_of_every_axis_with_both_stacks():
    assert len(MEMBERS) >= 24 and len({m.name for m in MEMBERS}) == len(MEMBERS)
    for axis, values in AXES.items():
        assert {getattr(m, axis) for m in MEMBERS} == set(values), axis
    assert {m.frames_mode for m in MEMBERS} == {"per_trigger", "per_output"}
    assert min(m.cost_ms[0] for m in MEMBERS) <= 1.0 and max(m.cost_ms[1] for m in MEMBERS) >= 1000.0
    assert (MPC.trigger, MPC.readiness, MPC.reading, MPC.state, MPC.rate_hz, MPC.c_rate) == (
        "newest_idle", "absent_first", "latched", "warm", 15.0, 1.0)
    assert (SLOW_PLANNER.reading, SLOW_PLANNER.state, SLOW_PLANNER.numerics, SLOW_PLANNER.cost_ms) == (
        "cycle_start", "warm", "noisy_fork", (500.0, 1200.0))
    assert {m.name for m in SHORT} <= {m.name for m in MEMBERS} and all(m.seconds <= 2.0 for m in SHORT)


def test_a_member_off_its_axes_is_refused():
    with pytest.raises(ValueError, match="trigger 'sometimes' is not one of each, timer"):
        Member("odd", trigger="sometimes")
    with pytest.raises(ValueError, match="cost_ms"):
        Member("odd", cost_ms=(5.0, 1.0))


def test_every_member_is_a_stack_the_tool_accepts(tmp_path):
    for member in MEMBERS:
        stack = write_member(member, tmp_path / member.name)
        spec = load_spec(stack.spec_path)
        entry = replay_module_of(spec, "module")
        assert (entry.inputs, entry.trigger, entry.output, entry.frames) == (("a", "b", "c"), "a", "out",
                                                                              member.frames_mode)
        assert entry.ignore == ("debug",) and entry.hang_after >= 2.0
        assert {m.name for m in spec.modules} == {"module", "producer"}
    # The factory beside the spec builds the member's step with the spec's args.
    planner = make_planner(load_spec(tmp_path / "mpc" / "spec.yaml"), {}, entry=replay_module_of(
        load_spec(tmp_path / "mpc" / "spec.yaml"), "module"))
    assert (planner.obj.state, planner.obj.cost) == ("warm", (0.010, 0.045))


def frame(seq: int, *, c: bool = True) -> dict:
    out = {"a": {"header": {"seq": seq, "stamp": 0.05 * seq}, "v": [0.3 + 0.01 * seq, -0.2]},
           "b": {"header": {"seq": seq // 2, "stamp": 0.1 * (seq // 2)}, "v": [0.1, 0.7]}}
    if c:
        out["c"] = {"header": {"seq": 0, "stamp": 0.0}, "v": [0.9, 0.4]}
    return out


def test_the_step_keeps_the_factory_contract():
    fast = {"cost_ms": "0.01-0.01"}
    # An absent input (no key) is a frame of its own, recorded as absent in the evaluation record.
    with_c, without_c = Step(**fast).step(frame(1)), Step(**fast).step(frame(1, c=False))
    assert with_c["x"] != without_c["x"] and (with_c["absent"], without_c["absent"]) == (0, 1)
    assert without_c["debug"]["inputs"] == {"a": 1, "b": 0, "c": None}
    # Several messages a cycle: one per step call, the later calls ignoring their frame.
    several = Step(outputs="several", **fast)
    parts = [several.step(frame(5)), several.step(frame(6)), several.step(frame(7)), several.step(frame(8))]
    assert [(m["part"], m["header"]["seq"]) for m in parts] == [(0, 15), (1, 16), (2, 17), (0, 24)]
    # None for some cycles; the warm state moved all the same.
    quiet = Step(outputs="none_some", state="warm", **fast)
    assert quiet.step(frame(3)) is None and quiet.x != [0.0, 0.0]
    # A warm start: the same frame after another history answers otherwise.
    warm_a, warm_b = Step(state="warm", **fast), Step(state="warm", **fast)
    warm_a.step(frame(1))
    assert warm_a.step(frame(2))["x"] != warm_b.step(frame(2))["x"]


def test_a_seeded_defect_kills_the_step_on_a_nan_and_the_spec_says_so(tmp_path):
    fast = {"cost_ms": "0.01-0.01"}
    poisoned = frame(2)
    poisoned["c"] = {**poisoned["c"], "v": [float("nan"), 0.4]}
    assert math.isnan(Step(**fast).step(poisoned)["x"][0])  # no defect: a NaN goes through
    with pytest.raises(ValueError, match="seeded defect: NaN in input c"):
        Step(defect="crash_on_nan", **fast).step(poisoned)
    with pytest.raises(ValueError, match="defect 'sometimes'"):
        Member("odd", defect="sometimes")
    stack = write_member(Member("defective", defect="crash_on_nan"), tmp_path / "defective")
    entry = replay_module_of(load_spec(stack.spec_path), "module")
    assert entry.exceptions == "crash" and entry.factory_args["defect"] == "crash_on_nan"
    assert replay_module_of(load_spec(write_member(MPC, tmp_path / "mpc").spec_path), "module").exceptions \
        == "unresolved"


def test_noisy_numerics_differ_by_an_ulp_in_a_copy_or_a_fork_and_stable_ones_not_at_all():
    fast = {"cost_ms": "0.01-0.01", "state": "warm"}
    for numerics, differs in (("stable", False), ("noisy_fork", True)):
        def built(numerics: str = numerics) -> Step:
            step = Step(numerics=numerics, **fast)
            for seq in range(3):
                step.step(frame(seq))
            return step

        reference = built().step(frame(3))["x"]
        for copied in (copy.deepcopy(built()), pickle.loads(pickle.dumps(built()))):
            errors = [abs(p - q) for p, q in zip(reference, copied.step(frame(3))["x"], strict=True)]
            assert (max(errors) > 0) == differs and max(errors) < 1e-15, (numerics, errors)
    read, write = os.pipe()
    noisy = Step(numerics="noisy_fork", **fast)
    here = noisy.step(frame(0))["x"]
    noisy = Step(numerics="noisy_fork", **fast)
    pid = os.fork()
    if pid == 0:  # the instance built before the fork, stepped in the child
        os.write(write, repr(noisy.step(frame(0))["x"]).encode())
        os._exit(0)
    os.waitpid(pid, 0)
    there = eval(os.read(read, 1000).decode())  # noqa: S307 — our own repr of two floats
    os.close(read)
    os.close(write)
    assert here != there and max(abs(p - q) for p, q in zip(here, there, strict=True)) < 1e-15
    assert all(math.isfinite(v) for v in here + there)


# -- members on the bus ---------------------------------------------------------------------------


@dataclass(frozen=True)
class ZooRun:
    member: Member
    floor: Floor
    extracted: Extracted
    suite: SuiteRun
    lost: int


def zoo_run(member: Member, directory: Path) -> ZooRun:
    stack = write_member(member, directory / member.name)
    log = record(stack)
    extracted = extract(stack, log, stack.directory / "suite")
    floor = plain_replay(stack, log)
    return ZooRun(member, floor, extracted, run_suite(stack.directory / "suite"), lost(floor, extracted, stack, log))


def check_floor(run: ZooRun) -> None:
    floor = run.floor
    assert floor.outputs > 0 and len(floor.reproduced) == floor.outputs and floor.steps > 0
    assert floor.way in floor.ways and floor.count == max(floor.ways.values()) and floor.seconds > 0
    assert run.extracted.outputs == floor.outputs  # extraction and floor count the same recorded outputs


def check_theta0(run: ZooRun) -> None:
    """Every output the floor reproduces, extraction reproduces too (so θ = 0 ≥ the floor): a cut that loses
    one the plain replay gets is a bug."""
    assert run.extracted.exact >= run.floor.count and run.lost == 0, (
        f"{run.member.name}: θ = 0 {run.extracted.exact}, floor {run.floor.count} ({run.floor.way}), "
        f"lost {run.lost} of {run.floor.outputs}")


def check_suite(run: ZooRun) -> None:
    assert run.suite.tests == run.extracted.tests
    assert run.suite.all_pass, f"{run.member.name}: {run.suite.output}"


@pytest.fixture(scope="module", params=SHORT, ids=[m.name for m in SHORT])
def short_run(request, tmp_path_factory) -> ZooRun:
    return zoo_run(request.param, tmp_path_factory.mktemp("zoo"))


def test_the_plain_replay_floor_is_computed(short_run):
    check_floor(short_run)


def test_extraction_at_theta_0_reproduces_at_least_the_floor(short_run):
    check_theta0(short_run)


def test_the_extracted_suite_passes_on_the_run_it_came_from(short_run):
    check_suite(short_run)


def test_a_field_the_node_adds_is_named_with_the_ignore_line_that_makes_the_run_reproduce(tmp_path):
    """A node that adds header.frame_id to every output, a field its step does not return: at θ = 0 nothing
    reproduces, whatever the frames (a plain replay neither). `astaa-deft extract` names the field, how it
    differs and the ignore: line to add, also in the suite's manifest; with that line in the spec, the same
    log reproduces at least what a plain replay then does."""
    member = short(NODE_FRAME_ID, 1.0)
    stack = write_member(member, tmp_path / member.name)
    log = record(stack)
    assert plain_replay(stack, log).count == 0
    res = subprocess.run([sys.executable, "-m", "astaa_deft.cli", "extract", str(log), "--spec", str(stack.spec_path),
                          "--module", "module", "--threshold", "0", "-o", str(tmp_path / "first")],
                         capture_output=True, text=True, timeout=300)
    assert res.returncode in (0, 1), res.stderr[-2000:]
    assert re.search(r"reproduce: (\d+) of \1 output\(s\) not within θ = 0", res.stdout), res.stdout
    assert re.search(r"header\.frame_id +only in the recorded output .* in every output .*'base_link'", res.stdout), \
        res.stdout
    assert f"in replay.modules[0] of {stack.spec_path}, replace its ignore: with (then extract again):  " \
        "ignore: [debug, header.frame_id]" in res.stdout, res.stdout
    stored = json.loads((tmp_path / "first" / "deft.json").read_text())["diagnosis"]
    assert stored["ignore"] == ["debug", "header.frame_id"] and stored["fields"][0]["how"] == "recorded only"
    assert stored["reproduced_with_line"] > 0
    fixed = write_member(member, stack.directory, replay_extra={"ignore": stored["ignore"]})
    floor = plain_replay(fixed, log)
    extracted = extract(fixed, log, tmp_path / "second")
    assert floor.count > 0 and extracted.exact >= floor.count and lost(floor, extracted, fixed, log) == 0
    assert extracted.report.diagnosis is None or extracted.report.diagnosis.ignore == ()


# -- the whole zoo (-m slow) ------------------------------------------------------------------------


@pytest.fixture(scope="module", params=MEMBERS, ids=[m.name for m in MEMBERS])
def zoo_member_run(request, tmp_path_factory) -> ZooRun:
    return zoo_run(request.param, tmp_path_factory.mktemp("zoo-all"))


@pytest.mark.slow
def test_whole_zoo_floor_is_computed(zoo_member_run):
    check_floor(zoo_member_run)


@pytest.mark.slow
def test_whole_zoo_extraction_at_theta_0_reproduces_at_least_the_floor(zoo_member_run):
    check_theta0(zoo_member_run)


@pytest.mark.slow
def test_whole_zoo_suite_passes_on_the_run_it_came_from(zoo_member_run):
    check_suite(zoo_member_run)
