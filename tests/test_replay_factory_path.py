"""A replay factory named by a file path relative to the spec: ``factory: ../controller.py:MPC``.

A module beside the SUT's sources, not beside the spec, needs no shim on
sys.path; a spec not read from a file (one stored in a log) names no file
to run.
"""

from __future__ import annotations

import pickle
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from astaa_deft.analysis.deft.replay import load_factory, make_planner
from astaa_deft.engine.spec.loader import load_spec, load_spec_text
from astaa_deft.model.errors import InputError

CONTROLLER = textwrap.dedent("""\
    from gains import GAIN  # a module beside it


    class MPC:
        def __init__(self, gain: str = "1"):
            self.gain = float(gain) * GAIN

        def step(self, frame):
            return {"acceleration": -self.gain * frame["localization"]["x"]}
    """)
SPEC = textwrap.dedent("""\
    name: s
    modules:
      - {name: control, command: [x]}
      - {name: sim, command: [x]}
    channels:
      - {name: localization, key: t/loc, producer: sim, consumers: [control], type: Pose}
      - {name: command, key: t/cmd, producer: control, consumers: [sim], type: Command}
    types:
      Pose: {x: float64}
      Command: {acceleration: float64}
    replay:
      modules:
        - {module: control, inputs: [localization], trigger: localization, outputs: [command],
           factory: "FACTORY", args: {gain: "2"}}
    """)


@pytest.fixture
def stack(tmp_path: Path) -> Path:
    (tmp_path / "src").mkdir()
    (tmp_path / "src" / "verdicts_mpc_controller.py").write_text(CONTROLLER)
    (tmp_path / "src" / "gains.py").write_text("GAIN = 0.5\n")
    (tmp_path / "spec").mkdir()
    spec = tmp_path / "spec" / "sut.yaml"
    spec.write_text(SPEC.replace("FACTORY", "../src/verdicts_mpc_controller.py:MPC"))
    return spec


def test_a_factory_file_relative_to_the_spec_replays_and_its_state_pickles(stack: Path):
    spec = load_spec(stack)
    [entry] = spec.replay
    planner = make_planner(spec, {}, entry=entry)
    assert planner.step({"localization": {"x": 3.0}}) == {"acceleration": -3.0}
    assert pickle.loads(pickle.dumps(planner.snapshot())).gain == 1.0  # importable by its own name
    done = subprocess.run([sys.executable, "-m", "astaa_deft.cli", "spec", "check", str(stack)],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stdout + done.stderr


def test_a_missing_factory_file_is_a_located_spec_error(stack: Path):
    stack.write_text(SPEC.replace("FACTORY", "../src/nope.py:MPC"))
    with pytest.raises(InputError) as caught:
        load_spec(stack)
    [problem] = caught.value.problems
    assert "factory module '../src/nope.py'" in problem.message and problem.line == 14, problem


def test_a_spec_not_read_from_a_file_names_no_file_to_run(stack: Path):
    text = stack.read_text()
    spec = load_spec_text(text, name="stored in a log")  # as a log's stored spec is read: no file
    assert spec.path is None
    with pytest.raises(InputError, match="not read from one"):
        load_factory(spec.replay[0].factory or "", None, "replay.modules[0]")


def test_a_factory_that_is_not_callable_is_a_spec_error_not_a_traceback(stack: Path):
    (stack.parent.parent / "src" / "verdicts_mpc_constant.py").write_text("MPC = 42\n")
    stack.write_text(SPEC.replace("FACTORY", "../src/verdicts_mpc_constant.py:MPC"))
    spec = load_spec(stack)
    with pytest.raises(InputError, match=r"replay factory '\.\./src/verdicts_mpc_constant\.py:MPC' is not callable"):
        make_planner(spec, {}, entry=spec.replay[0])


def test_a_snapshot_goes_back_only_into_a_module_that_steps(stack: Path):
    (stack.parent.parent / "src" / "verdicts_mpc_snapshot.py").write_text(CONTROLLER)  # a module name of its own
    stack.write_text(SPEC.replace("FACTORY", "../src/verdicts_mpc_snapshot.py:MPC"))
    spec = load_spec(stack)
    planner = make_planner(spec, {}, entry=spec.replay[0])
    planner.restore(planner.snapshot())
    with pytest.raises(TypeError, match="not a snapshot"):
        planner.restore({"gain": 1.0})
    assert planner.step({"localization": {"x": 3.0}}) == {"acceleration": -3.0}  # the module it had
