"""Smaller hardening checks: a participant's infinite time, fuzz on SIGTERM, a bad replay
factory's message. Real parsing, a real campaign process, a real spec on disk."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from astaa_deft.engine.intercept import parse_testcase
from astaa_deft.engine.spec.loader import load_spec
from astaa_deft.model.errors import InputError

ROOT = Path(__file__).resolve().parent.parent
SPEC = load_spec(ROOT / "specs" / "demo_av.yaml")
BIG = "1" * 400  # a decimal the XSD takes, a float infinity


def policy(participant: str) -> bytes:
    return (f'<testcase id="tc" seed="1"><description/><policy id="p"><channel>prediction</channel>{participant}'
            "</policy></testcase>").encode()


@pytest.mark.parametrize("participant, attribute", [
    (f'<participant id="9" kind="vehicle" x="30" y="3.5" t="{BIG}"/>', "t"),
    (f'<participant id="9" kind="vehicle" x="30" y="3.5" t="1"><at t="{BIG}" x="50" y="3.5"/></participant>', "t"),
])
def test_a_participant_time_beyond_float_range_is_refused(participant, attribute):
    """Times have no bound in the XSD (a stack may stamp epoch seconds); x, y, length… have theirs there."""
    with pytest.raises(InputError) as caught:
        parse_testcase(policy(participant), "tc.xml", SPEC)
    text = str(caught.value)
    assert f"{attribute}=" in text and "is not a finite number" in text and "tc.xml" in text


def test_a_participant_with_finite_numbers_still_parses():
    finite = "9" * 300  # 1e300: a float
    case = parse_testcase(policy(f'<participant id="9" kind="vehicle" x="30" y="3.5" t="{finite}"/>'), "tc.xml", SPEC)
    assert case.policies[0].action.t == float(finite)


FUZZ_SPEC = textwrap.dedent("""\
    name: tiny
    modules:
      - {name: a, command: ["%s", "-c", "import time; time.sleep(30)"]}
      - {name: b, command: ["%s", "-c", "import time; time.sleep(30)"]}
    channels: [{name: data, key: t/data, producer: a, consumers: [b], type: Sample}]
    types:
      Sample: {seq: uint64, value: float64}
    invariants:
      - {name: value_small, kind: expression, channel: data, expr: "value < 10"}
    """)


def test_fuzz_on_sigterm_prints_the_summary_and_the_resume_line(tmp_path):
    spec = tmp_path / "spec.yaml"
    spec.write_text(FUZZ_SPEC % (sys.executable, sys.executable))
    out = tmp_path / "campaign"
    proc = subprocess.Popen([sys.executable, "-m", "astaa_deft.cli", "fuzz", "--spec", str(spec), "-o", str(out),
                             "--cases", "50", "--baseline", "1", "--no-minimise", "--horizon", "2", "--workers", "1"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while not (out / "journal.sqlite").exists() and time.monotonic() < deadline:
            time.sleep(0.2)
        time.sleep(3.0)  # the baseline run under way
        proc.send_signal(signal.SIGTERM)
        stdout, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == 143, stdout + stderr  # 128 + SIGTERM, as a shell reports it
    assert "campaign interrupted:" in stdout and f"-o {out} --resume" in stdout, stdout
    assert "Traceback" not in stderr


def test_a_bad_replay_factory_names_the_spec_file(tmp_path):
    """Found with minimise --trust-log-spec: 'error: : replay factory …' named no file."""
    from test_deft_oracle import SPEC as TOY_SPEC

    from astaa_deft.analysis.deft.replay import make_planner

    (tmp_path / "stepless.py").write_text("class Planner:\n    def __init__(self, **args):\n        pass\n")
    for name, factory, says in (("sut.yaml", "stepless:Planner", "returned an object without a step(frame) method"),
                                ("sut2.yaml", "gainful:Planner", "does not take these args")):
        spec_path = tmp_path / name
        text = TOY_SPEC.replace("toy_planner:ToyPlanner", factory)
        if name == "sut2.yaml":  # a factory whose parameters are not the args given
            (tmp_path / "gainful.py").write_text("class Planner:\n    def __init__(self, gain):\n        pass\n")
        spec_path.write_text(text)
        with pytest.raises(InputError) as caught:
            make_planner(load_spec(spec_path), {"stop": "off", "shift": "0"})
        [problem] = caught.value.problems
        assert problem.file == str(spec_path) and says in problem.message, problem
        assert f"planner.replay: replay factory '{factory}'" in problem.message
