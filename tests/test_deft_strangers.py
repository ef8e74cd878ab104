"""DeFT on a stack it was not tuned on: a warm-started controller, rebuilt from a description of it.

Its first cycles run before the first message of one input arrived (the
factory gets a frame without that input), it answers the newest trigger
when a solve ends, and each answer carries every earlier one (a warm
start): one wrong first frame would spoil every output. Extraction must
reproduce every output at θ = 0, its suite must pass on the run it came
from, a declared provenance is taken first, and --ground-truth works with
--module and is checked before the work.
"""

from __future__ import annotations

import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest

from astaa_deft.analysis.deft.extract import extract, ground_truth_rate
from astaa_deft.analysis.deft.fork_replay import can_fork
from astaa_deft.analysis.deft.planner_section import replay_module_of
from astaa_deft.analysis.deft.replay import make_planner
from astaa_deft.analysis.deft.workflow import ExtractOptions, extract_module_tests
from astaa_deft.engine.spec.loader import load_spec
from astaa_deft.io.log.reader import read_log

import astaa_deft
from proxy_helpers import SUT_DIR
from warm_mpc_log import write_mpc_log

# The subprocesses import this checkout of the tool (its pytest plugin included) and the factory beside the spec.
ENV = {**os.environ, "PYTHONPATH": os.pathsep.join([str(SUT_DIR), str(Path(astaa_deft.__file__).parent.parent)])}


@pytest.fixture(autouse=True)
def _factory_on_path(monkeypatch):
    monkeypatch.syspath_prepend(str(SUT_DIR))


def _extract(spec_path, log_path, jobs):
    spec = load_spec(spec_path)
    entry = replay_module_of(spec, "mpc")
    return spec, entry, extract(read_log(log_path), spec, make_planner(spec, {}, entry=entry), entry=entry, jobs=jobs)


@pytest.mark.parametrize("jobs", [None, pytest.param(2, marks=pytest.mark.skipif(not can_fork(), reason="POSIX"))])
def test_first_cycles_without_an_input_and_a_warm_start_reproduce_exactly(tmp_path, jobs):
    spec_path, log_path, outputs = write_mpc_log(tmp_path)
    spec, entry, ex = _extract(spec_path, log_path, jobs)
    assert ex.outputs == outputs and not ex.skipped
    first = ex.frames[0]
    assert set(first.inputs) == {"state"}  # the path had not arrived: the frame leaves it out
    assert ex.accepted_at(0.0) == outputs  # every output, though each depends on all before it
    assert ground_truth_rate(ex, spec, "used", entry) == (outputs, outputs)  # the frames the module used


def test_a_declared_provenance_is_taken_first_and_checked_by_replay(tmp_path):
    spec_path, log_path, outputs = write_mpc_log(tmp_path, provenance=True)
    spec, entry, ex = _extract(spec_path, log_path, None)
    assert entry.provenance == "used"
    assert ex.declared == outputs and ex.accepted_at(0.0) == outputs
    assert all(f.candidates_tried == 1 for f in ex.frames)  # the named frame, reproduced: nothing searched


def test_the_suite_carries_the_state_of_frames_it_does_not_test(tmp_path):
    # Output 5 is logged off: no frame reproduces it, but the state its step built carries every later one.
    spec_path, log_path, outputs = write_mpc_log(tmp_path, tampered=5)
    out = tmp_path / "suite"
    report = extract_module_tests(log_path, spec_path, out, ExtractOptions(module="mpc", jobs=1))
    assert report.accepted == outputs - 1 and report.suite_failures == []
    done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(out)],
                          capture_output=True, text=True, cwd=out, timeout=120, env=ENV)
    assert done.returncode == 0, done.stdout[-2000:]
    assert f"{outputs - 1} passed" in done.stdout


def test_ground_truth_works_with_module_and_is_checked_before_the_work(tmp_path):
    spec_path, log_path, outputs = write_mpc_log(tmp_path)
    command = [sys.executable, "-m", "astaa_deft.cli", "extract", str(log_path), "--spec", str(spec_path),
               "--module", "mpc", "-o", str(tmp_path / "suite")]
    env = ENV
    bad = subprocess.run([*command, "--ground-truth", "used[", "--jobs", "1"], capture_output=True, text=True,
                         env=env, timeout=60)
    assert bad.returncode == 2 and "--ground-truth" in bad.stderr and "outputs" not in bad.stdout
    typo = subprocess.run([*command, "--ground-truth", "usd", "--jobs", "1"], capture_output=True, text=True,
                          env=env, timeout=60)  # a field the output's declared type does not have: before the work
    assert typo.returncode == 2 and "'usd' names no field of 'command'" in typo.stderr, typo.stderr
    assert "outputs" not in typo.stdout
    good = subprocess.run([*command, "--ground-truth", "used", "--jobs", "1"], capture_output=True, text=True,
                          env=env, timeout=120)
    assert good.returncode == 0, good.stderr
    assert f"outputs of module 'mpc' found: {outputs}" in good.stdout and "planning" not in good.stdout
    assert f"ground truth (used): {outputs}/{outputs} frames used exactly module 'mpc''s inputs" in good.stdout


@pytest.mark.skipif(not can_fork(), reason="the suite runs beside a forked search")
def test_the_suite_run_beside_the_search_reports_what_fails_from_a_fresh_module(tmp_path):
    from astaa_deft.analysis.deft.extract import SuiteRun
    from astaa_deft.io.codecs import get_codec

    spec_path, log_path, outputs = write_mpc_log(tmp_path)
    spec = load_spec(spec_path)
    entry = replay_module_of(spec, "mpc")
    decided = []
    clean = extract(read_log(log_path), spec, make_planner(spec, {}, entry=entry), entry=entry, jobs=1,
                    on_output=lambda done, total, outcome: decided.append(outcome))
    assert clean.suite_failures == [] and len(decided) == outputs
    # The same frames on a module that is not fresh (one step before): with a warm start every test fails.
    used = make_planner(spec, {}, entry=entry)
    used.step({"state": {"header": {"seq": 0, "stamp": 0.0}, "y": 5.0, "v": 1.0}})
    run = SuiteRun(used, entry, {name: get_codec(spec.channel(name).encoding) for name in ("state", "path", "command")})
    for outcome in decided:
        run.add(outcome)
    while run.step_one():
        pass
    assert [index for index, _ in run.failures] == list(range(outputs))


@pytest.mark.skipif(not can_fork(), reason="the suite's run done by the forked replay")
def test_the_replays_own_in_order_steps_of_a_fresh_module_are_the_suites_run(tmp_path):
    # Before: the calling process stepped a second fresh module on every frame beside the search (a second
    # replay competing for the cores). Now the replay makes its module itself and its in-order steps are the
    # suite's run; the caller steps nothing — unless a frame was not so checked.
    from astaa_deft.analysis.deft.extract import SuiteRun
    from astaa_deft.io.codecs import get_codec

    spec_path, log_path, outputs = write_mpc_log(tmp_path)
    spec = load_spec(spec_path)
    entry = replay_module_of(spec, "mpc")
    decided = []

    def fresh():  # called in the replay process
        return make_planner(spec, {}, entry=entry)

    caller = make_planner(spec, {}, entry=entry)
    ex = extract(read_log(log_path), spec, caller, entry=entry, jobs=1, fresh=fresh,
                 on_output=lambda done, total, outcome: decided.append(outcome))
    # Every frame is checked by one whole in-order run of a fresh module: the replay's own (the module it made,
    # while no fork took over), or — once one did — the caller's.
    assert ex.suite_failures == [] and len(ex.frames) > 0
    assert (ex.checked_in_replay, ex.checked_beside) in ((len(ex.frames), 0), (0, len(ex.frames)))
    assert ex.checked_beside or all(outcome.in_order is not None for outcome in decided)
    # A replay that says it will not check the frames (beside) leaves them all to the caller: a module that
    # is not fresh (one step before) then fails every test there.
    used = make_planner(spec, {}, entry=entry)
    used.step({"state": {"header": {"seq": 0, "stamp": 0.0}, "y": 5.0, "v": 1.0}})
    run = SuiteRun(used, entry, {name: get_codec(spec.channel(name).encoding) for name in ("state", "path", "command")})
    for outcome in decided:
        run.add(replace(outcome, in_order=None, beside=True))
    while run.step_one():
        pass
    assert [index for index, _ in run.failures] == list(range(outputs))


def test_a_written_suite_is_checked_on_its_own_run_and_failing_tests_are_unchecked(tmp_path):
    import json

    from astaa_deft.analysis.deft.workflow import check_suite, uncheck_frames

    spec_path, log_path, outputs = write_mpc_log(tmp_path)
    out = tmp_path / "suite"
    extract_module_tests(log_path, spec_path, out, ExtractOptions(module="mpc", jobs=1))
    assert check_suite(out) == ([], 0)
    manifest = json.loads((out / "deft.json").read_text())
    manifest["frames"][3]["output"] = manifest["frames"][4]["output"]  # frame 3 now expects another answer
    (out / "deft.json").write_text(json.dumps(manifest))
    assert [f.index for f in check_suite(out)[0]] == [3]
    uncheck_frames(out, {3})
    assert check_suite(out) == ([], 0)  # frame 3 is stepped for its state, not tested


@pytest.mark.skipif(not can_fork(), reason="forked search")
def test_a_module_not_bit_stable_across_a_fork_is_reproduced_by_the_suites_own_run(tmp_path):
    # Forked copies answer 1e-15 off; the suite's run (a fresh module, never forked) answers exactly: the
    # near misses the search kept are the right frames, and the suite says they pass.
    spec_path, log_path, outputs = write_mpc_log(tmp_path, factory="NoisyAfterForkMpc")
    spec, entry, ex = _extract(spec_path, log_path, 2)
    assert ex.accepted_at(0.0) == outputs and ex.suite_failures == []
    assert ex.confirmed_unforked == outputs  # the runner itself is a forked copy: every output was a near miss


def test_without_forks_the_written_suite_has_the_last_word_on_copied_states(tmp_path):
    # Candidates tried from deep copies: a module off by 1e-15 in a copied state misses θ = 0 there; the written
    # suite, run once from a fresh module, reproduces those frames exactly: they are tests, and they pass.
    from astaa_deft.analysis.deft.export import export_suite
    from astaa_deft.analysis.deft.workflow import check_suite

    spec_path, log_path, outputs = write_mpc_log(tmp_path, factory="NoisyAfterCopyMpc")
    spec, entry, ex = _extract(spec_path, log_path, None)
    assert ex.accepted_at(0.0) < outputs
    out = tmp_path / "suite"
    export_suite(ex.frames, spec, {}, out, entry=entry)
    failing, confirmed = check_suite(out, ex)
    assert failing == [] and confirmed == ex.confirmed_unforked > 0
    assert ex.accepted_at(0.0) == outputs


def test_a_provenance_that_is_no_field_path_is_one_located_spec_error(tmp_path):
    from astaa_deft.model.errors import InputError

    text = (SUT_DIR / "warm_mpc.yaml").read_text().replace("      frames: per_output\n",
                                                           "      frames: per_output\n      provenance: used[\n")
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(InputError) as caught:
        load_spec(path)
    problem = caught.value.problems[0]
    assert "provenance" in problem.message and problem.line == text.splitlines().index("      provenance: used[") + 1
