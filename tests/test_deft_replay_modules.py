"""Any deterministic module, not only the planner, runs alone: the spec's `replay:` section.

The demo names control there (`astaa_deft.demo.control:ReplayControl`, one
frame per localization). Its spec errors are one clear message each; DeFT
extracts control's frames from a real run and the exported suite passes
under pytest; and a control crash hidden among 100+ benign mutations
minimises on the module replay, not by whole-system re-runs.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest
from test_minimise_demo import NOISE, SPEC_PATH, record
from zoo.floor import output_key, plain_floor

from astaa_deft.analysis.minimise.workflow import MinimiseOptions
from astaa_deft.cli.commands import minimise as command
from astaa_deft.analysis.deft.extract import extract
from astaa_deft.analysis.deft.export import export_suite
from astaa_deft.analysis.deft.planner_section import replay_module_of, replay_modules
from astaa_deft.analysis.deft.replay import StepHang, make_planner, within_limit
from astaa_deft.analysis.deft.workflow import run_params
from astaa_deft.demo.control import ReplayControl
from astaa_deft.model.errors import InputError
from astaa_deft.io.log.reader import read_log
from astaa_deft.engine.monitor import check_log
from astaa_deft.engine.spec.loader import load_spec

SPEC_TEXT = SPEC_PATH.read_text()
ENTRY = SPEC_TEXT[SPEC_TEXT.index("replay:\n  modules:"):SPEC_TEXT.index("\n# Decictor")]
# Seeded defect 3: an empty trajectory crashes control (anchored to control's first command, so the
# stack is driving when it hits, however late it started). Five in a row: control steps on the newest
# trajectory when a localization comes, and on a loaded machine one empty plan can be overtaken by the
# next before control reads it (the run then did not fail). The first one control reads crashes it, so the
# failure still minimises to one mutation.
CRASH = """<policy id="culprit"><channel>trajectory</channel>
  <window from="1"><after channel="command" message="1"/></window><select limit="5"/>
  <set><field path="points" value="dict:array.empty"/></set></policy>"""


def spec_with(tmp_path: Path, old: str, new: str) -> Path:
    assert old in ENTRY, old
    path = tmp_path / "sut.yaml"
    path.write_text(SPEC_TEXT.replace(ENTRY, ENTRY.replace(old, new, 1)))
    return path


def test_the_demo_spec_names_control_and_keeps_the_planner_first():
    spec = load_spec(SPEC_PATH)
    entries = replay_modules(spec)
    assert [(e.module, e.output, e.frames) for e in entries] == [
        ("planning", "trajectory", "per_output"), ("control", "command", "per_trigger")]
    control = replay_module_of(spec, "control")
    assert control.inputs == ("trajectory", "localization") and control.trigger == "localization"
    assert control.exceptions == "crash" and control.hang_after == 0.5 and control.trajectory is None
    assert replay_module_of(spec).module == "planning"  # the default stays the planner


BAD_ENTRIES = [  # (what, old, new, message, fix)
    ("unknown key", "hang_after: 0.5", "hang_afte: 0.5", "unknown key 'hang_afte'", "did you mean 'hang_after'"),
    ("two outputs", "outputs: [command]", "outputs: [command, trajectory]", "must list exactly one channel",
     "one output per entry"),
    ("unknown channel", "trigger: localization", "trigger: localisation", "replay trigger 'localisation'",
     "did you mean 'localization'"),
    ("trigger not an input", "trigger: localization", "trigger: routing", "not among the inputs", "add it"),
    ("unknown module", "module: control", "module: contrl", "replay module 'contrl' is not declared",
     "did you mean 'control'"),
    ("not a consumer", "inputs: [trajectory, localization]", "inputs: [trajectory, localization, routing]",
     "does not list 'control' among its consumers", "drop the input"),
    ("output of another module", "outputs: [command]", "outputs: [trajectory]", "produced by 'planning'",
     "name a channel the module produces"),
    ("bad frames", "exceptions: crash", "frames: every_trigger", "must be one of per_trigger, per_output",
     "per_trigger"),
    ("bad exceptions", "exceptions: crash", "exceptions: fatal", "must be one of unresolved, crash", ""),
    ("zero hang", "hang_after: 0.5", "hang_after: 0", "must be a finite number > 0", ""),
    ("bad factory", "factory: astaa_deft.demo.control:ReplayControl", "factory: not a factory",
     "is not 'package.module:Name'", ""),
    ("bad ignore path", "hang_after: 0.5 ", "ignore: [header..stamp]\n      hang_after: 0.5 ",
     "'replay.modules[0].ignore' entry 'header..stamp' is no output field path", "a whole struct (header)"),
    ("missing factory", "factory: astaa_deft.demo.control:ReplayControl", "factory: nowhere_at_all.mod:Thing",
     "neither on the Python path nor in the spec's directory", ""),
]


@pytest.mark.parametrize("what,old,new,message,fix", BAD_ENTRIES, ids=[b[0] for b in BAD_ENTRIES])
def test_a_bad_replay_entry_is_one_clear_error(tmp_path, what, old, new, message, fix):
    path = spec_with(tmp_path, old, new)
    with pytest.raises(InputError) as err:
        load_spec(path)
    matching = [p for p in err.value.problems if message in str(p)]
    assert matching, f"{what}: {[str(p) for p in err.value.problems]}"
    problem = matching[0]
    assert problem.file == str(path) and problem.line is not None and problem.column is not None
    assert SPEC_TEXT.count("\n", 0, SPEC_TEXT.index(ENTRY)) < problem.line  # inside the section
    assert fix in str(problem)


def test_spec_check_exits_2_naming_the_place(tmp_path):
    path = spec_with(tmp_path, "outputs: [command]", "outputs: command")
    res = subprocess.run([sys.executable, "-m", "astaa_deft.cli", "spec", "check", str(path)],
                         capture_output=True, text=True, timeout=60)
    assert res.returncode == 2
    assert f"{path}:" in res.stderr and "must list exactly one channel" in res.stderr
    assert "Traceback" not in res.stderr


def test_a_module_without_a_replay_is_named_with_the_fix():
    with pytest.raises(InputError, match="module 'simulator' cannot run alone.*replay: modules:"):
        replay_module_of(load_spec(SPEC_PATH), "simulator")


def test_control_replay_answers_as_the_process_does():
    ctl = ReplayControl(defects=True)
    loc = {"header": {"seq": 1, "stamp": 1.0}, "x": 0.0, "y": 0.0, "heading": 0.0, "speed": 5.0,
           "acceleration": 0.0, "yaw_rate": 0.0}
    assert ctl.step({"localization": loc}) is None  # no plan yet: nothing published
    plan = {"header": {"seq": 7, "stamp": 1.0}, "points": [
        {"t": 1.0 + 0.1 * i, "x": 0.5 * i, "y": 0.0, "heading": 0.0, "v": 5.0, "a": 0.0} for i in range(50)]}
    command_ = ctl.step({"localization": {**loc, "header": {"seq": 2, "stamp": 1.02}}, "trajectory": plan})
    assert command_["header"] == {"seq": 1, "stamp": 1.02} and command_["trajectory_seq"] == 7
    assert ctl.step({"localization": {"header": {"seq": 3}}, "trajectory": plan}) is None  # malformed: dropped
    with pytest.raises(ValueError):  # seeded defect 3: what the process dies of
        ctl.step({"localization": {**loc, "header": {"seq": 4, "stamp": 1.04}},
                  "trajectory": {**plan, "points": []}})


def test_a_step_that_never_returns_is_stopped_as_a_hang():
    def forever() -> None:
        while True:
            pass

    started = time.monotonic()
    with pytest.raises(StepHang):  # of CPU time; or, when the load leaves it under a tenth of a core, blocked
        within_limit(forever, 0.2)
    assert within_limit(lambda: 3, 0.2) == 3
    assert time.monotonic() - started < 5


def test_a_step_that_waits_is_no_hang_until_it_has_waited_ten_times_its_limit():
    # A step that waits (for a core on a loaded machine, here in a sleep) uses no CPU: no hang at hang_after,
    # whatever the load; one that waits for good is stopped all the same, at ten times it.
    assert within_limit(lambda: (time.sleep(0.3), "answered")[1], 0.1) == "answered"
    started = time.monotonic()
    with pytest.raises(StepHang, match="blocked"):
        within_limit(lambda: time.sleep(30), 0.1)
    assert time.monotonic() - started < 10


@pytest.fixture(scope="module")
def crashed(tmp_path_factory):
    directory = tmp_path_factory.mktemp("crash")
    return directory, record(directory, "noisy-crash", NOISE + CRASH, 7.0)


@pytest.fixture(scope="module")
def clean_run(tmp_path_factory):
    """A run without mutations: its deliveries are what control received (DeFT reads passive records)."""
    directory = tmp_path_factory.mktemp("clean")
    never = """<policy id="never"><channel>routing</channel><window from="1000"/>
      <set><field path="speed_limit" value="json:1.0"/></set></policy>"""  # opens after the run: no mutation
    return directory, record(directory, "clean", never, 6.0)


def test_control_frames_are_extracted_and_replay_exactly(clean_run, tmp_path):
    _, log_path = clean_run
    spec = load_spec(SPEC_PATH)
    entry = replay_module_of(spec, "control")
    log = read_log(log_path)
    params = run_params(log, spec)
    ex = extract(log, spec, make_planner(spec, params, entry=entry), entry=entry)
    answered = [f for f in ex.frames if f.output is not None]
    assert len(answered) >= 100 and ex.recorded_outputs is not None and ex.recorded_outputs >= len(answered)
    # Frames before control's first plan are answered with nothing, as the process published nothing.
    assert ex.frames[0].output is None and ex.frames[0].accepted
    # Control is deterministic: its frames replay exactly. How many pair up is the recording's doing (on a
    # loaded machine control may have read a trajectory in another order than the recorder, beyond the
    # candidates, and its warm integrator carries that on); what the extraction must never do is lose an
    # output a plain replay of the same log reproduces (the floor of this very recording, as in the zoo).
    assert all(f.comparison.distance == 0.0 for f in ex.frames if f.accepted)
    floor = plain_floor(SPEC_PATH, "control", log_path, params=params)
    kept = {output_key(f.output) for f in ex.frames if f.accepted and f.output is not None}
    outputs = sorted(log.on(spec.channel(entry.output).key), key=lambda m: m.log_time)
    lost = [n for n, (m, plain) in enumerate(zip(outputs, floor.reproduced, strict=True))
            if plain and output_key(m) not in kept]
    print(f"control: {sum(f.accepted for f in ex.frames)} of {len(ex.frames)} frames replay exactly; "
          f"a plain replay: {floor.count} of {floor.outputs} outputs")
    assert lost == [] and sum(f.accepted for f in ex.frames) >= floor.count
    # Exported as `extract` exports: every frame in order, those not accepted stepped for their state only
    # (exporting the accepted ones alone would skip the state the others build: a loaded machine's few
    # unpaired frames then fail the frames after them, as 26 of 285 did once under pytest-xdist).
    export_suite(ex.frames, spec, params, tmp_path / "suite", entry=entry)
    manifest = json.loads((tmp_path / "suite" / "deft.json").read_text())
    assert manifest["module"] == "control" and any(e["output"] is None for e in manifest["frames"])
    checked = sum(e.get("check", True) for e in manifest["frames"])
    assert checked == sum(f.accepted for f in ex.frames)
    res = subprocess.run([sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-q", str(tmp_path / "suite")],
                         capture_output=True, text=True, timeout=180)
    assert res.returncode == 0 and f"{checked} passed" in res.stdout, res.stdout[-2000:]


def test_a_control_crash_minimises_on_the_module_replay(crashed):
    directory, log_path = crashed
    out = directory / "minimal"
    code = command.minimise(log_path, out, MinimiseOptions(spec_path=SPEC_PATH, confirm=0), verbose=False)
    body = json.loads((out / "summary.json").read_text())
    assert code == 0, body["verdict"]
    assert body["tester"] == "replay" and "module 'control' crashed" in body["why"]
    assert body["failure"]["invariant"] == "modules_alive" and body["failure"]["module"] == "control"
    # A haystack of noise: how many noise mutations fired before the crash depends on how soon control
    # started (49 in one CI run, 50 or more in others); the behaviour under test is that the culprit alone is left.
    assert body["mutations"]["before"] >= 20 and body["mutations"]["after"] == 1
    [event] = body["culprit_events"]
    assert (event["channel"], [f["path"] for f in event["fields"]]) == ("trajectory", ["points"])
    # The minimal log shows the crash as `astaa-deft check` reads it: control's abnormal exit.
    result = check_log(read_log(out / "minimal.mcap"), load_spec(SPEC_PATH))
    assert result.verdict.first is not None and result.verdict.first.invariant == "modules_alive"
    # The module tests fail while control still crashes on the kept frames …
    res = subprocess.run([sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-q", str(out / "tests")],
                         capture_output=True, text=True, timeout=180)
    assert res.returncode == 1 and "module 'control' crashes" in res.stdout, res.stdout[-2000:]
    # … and pass against control with the defect guarded.
    fixed = directory / "fixed"
    fixed.mkdir()
    manifest = json.loads((out / "tests" / "deft.json").read_text())
    manifest["params"]["defects"] = "off"
    (fixed / "deft.json").write_text(json.dumps(manifest))
    (fixed / "frames.mcap").write_bytes((out / "tests" / "frames.mcap").read_bytes())
    res = subprocess.run([sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-q", str(fixed)],
                         capture_output=True, text=True, timeout=180)
    assert res.returncode == 0, res.stdout[-2000:]
