"""Logs are data: nothing a log's own spec names runs unless the user names a spec or says --trust-log-spec.

A crafted log carries a spec whose module command and whose replay factory
would each create a marker file (the factory's module is importable: its
directory is on PYTHONPATH). Every command that reads a log runs without
creating either marker; `minimise` refuses with one message that lists what
the log would run and names both ways on. With --trust-log-spec, a real
recorded run's module command does run.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from astaa_deft.model.errors import InputError
from astaa_deft.io.log.reader import read_log
from astaa_deft.io.log.writer import LogWriter
from astaa_deft.analysis.minimise.replay_model import load_spec_for
from astaa_deft.engine.spec.executes import what_spec_runs
from astaa_deft.engine.spec.loader import load_spec_text

SUT_DIR = Path(__file__).parent / "sut"

FACTORY_MODULE = textwrap.dedent("""\
    import os
    from pathlib import Path
    Path(os.environ["FACTORY_MARKER"]).touch()  # importing this module is running the log's code


    class Planner:
        def step(self, frame):
            return {}
    """)


def crafted_spec(command_marker: Path) -> str:
    return textwrap.dedent(f"""\
        name: crafted
        modules:
          - name: talker
            command: ["{{python}}", "-c", "import pathlib, sys; pathlib.Path(sys.argv[1]).touch()",
                      "{command_marker}"]
            cwd: /
            env: {{GREETING: hello}}
          - name: planning
            command: ["{{python}}", "-c", "import time; time.sleep(60)"]
        channels:
          - {{name: data, key: t/data, producer: talker, consumers: [planning], type: Sample}}
          - {{name: plan, key: t/plan, producer: planning, type: Sample}}
        types:
          Sample: {{seq: uint64, value: float64}}
        replay:
          modules:
            - {{module: planning, inputs: [data], trigger: data, outputs: [plan], factory: "marker_factory:Planner"}}
        invariants:
          - {{name: value_small, kind: bound, channel: data, field: value, max: 10}}
        """)


@pytest.fixture()
def crafted(tmp_path):
    """(log, env, markers): a log whose stored spec would touch the markers if anything it names ran."""
    markers = tmp_path / "command.marker", tmp_path / "factory.marker"
    code_dir = tmp_path / "elsewhere"
    code_dir.mkdir()
    (code_dir / "marker_factory.py").write_text(FACTORY_MODULE)
    text = crafted_spec(markers[0])
    spec = load_spec_text(text, name="crafted.yaml")
    log = tmp_path / "mailed.mcap"
    writer = LogWriter(log, spec)
    writer.attachment("spec.yaml", text.encode())
    data = writer.bus_channel(spec.channel("data"))
    for i in range(50):
        writer.message(data, 1_000_000_000 + i * 10_000_000, json.dumps({"seq": i, "value": 0.5}).encode())
    writer.finish()
    env = {**os.environ, "FACTORY_MARKER": str(markers[1]),
           "PYTHONPATH": os.pathsep.join(filter(None, [str(code_dir), os.environ.get("PYTHONPATH", "")]))}
    return log, env, markers


def cli(*args: str, env: dict, cwd: Path, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "astaa_deft.cli", *args], capture_output=True, text=True,
                          env=env, cwd=cwd, timeout=timeout)


def test_the_crafted_factory_would_run_if_imported(crafted, tmp_path):
    """The markers mean something: the factory's module is importable where the commands below run."""
    log, env, (_, factory_marker) = crafted
    probe = subprocess.run([sys.executable, "-c", "import marker_factory"], env=env, cwd=tmp_path)
    assert probe.returncode == 0 and factory_marker.exists()


@pytest.mark.parametrize("extra", [[], ["--live-only"]], ids=["minimise", "minimise-live-only"])
def test_minimise_refuses_to_run_what_a_log_names(crafted, tmp_path, extra):
    log, env, markers = crafted
    res = cli("minimise", str(log), "-o", str(tmp_path / "out"), *extra, env=env, cwd=tmp_path)
    assert res.returncode == 2, res.stdout + res.stderr
    assert "Traceback" not in res.stderr
    assert not any(m.exists() for m in markers)  # nothing ran: no command, no factory import
    lines = [line for line in res.stderr.splitlines() if line.startswith("astaa-deft: error:")]
    head, listed = lines[0], "\n".join(lines[1:])
    assert "--trust-log-spec" in head and "--spec FILE" in head and "a log is data" in head
    assert str(log) in head
    # What it would run, exactly as the log names it: the command with its cwd and env, and the factory.
    assert str(markers[0]) in listed and "(in /)" in listed and "GREETING=hello" in listed
    assert "replay module 'planning' factory (imported and called in the tool): marker_factory:Planner" in listed


def test_reading_a_log_runs_nothing_it_names(crafted, tmp_path):
    """check and log info read the log's spec as data: they judge and summarise, and run none of it."""
    log, env, markers = crafted
    check = cli("check", str(log), env=env, cwd=tmp_path)
    assert check.returncode == 0 and "Pass" in check.stdout, check.stdout + check.stderr
    info = cli("log", "info", str(log), env=env, cwd=tmp_path)
    assert info.returncode == 0, info.stderr
    extract = cli("extract", str(log), "-o", str(tmp_path / "tests"), env=env, cwd=tmp_path)
    assert extract.returncode == 2 and "--spec" in extract.stderr  # extract runs only the spec the user names
    assert not any(m.exists() for m in markers)


def test_the_workflow_takes_the_decision_as_an_option(crafted):
    log, env, markers = crafted
    contents = read_log(log)
    with pytest.raises(InputError) as refused:
        load_spec_for(contents, None, trust_log_spec=False)
    assert "--trust-log-spec" in str(refused.value)
    spec = load_spec_for(contents, None, trust_log_spec=True)
    assert [str(item) for item in what_spec_runs(spec)][-1] == \
        "replay module 'planning' factory (imported and called in the tool): marker_factory:Planner"
    assert not any(m.exists() for m in markers)  # loading a spec runs nothing, trusted or not


RECORDED_SPEC = """\
name: trusted
modules:
  - name: listener
    command: ["{{python}}", "{sut}/listener.py", "--key", "test/data", "--out", "{{run_dir}}/listener.out"]
    ready: {{log: "listener: subscribed"}}
  - name: talker
    command: ["{{python}}", "{sut}/talker.py", "--key", "test/data", "--rate", "50", "--count", "150"]
  - name: witness
    command: ["{{python}}", "-c", "import pathlib, sys, time; pathlib.Path(sys.argv[1]).touch(); time.sleep(600)",
              "{marker}"]
channels:
  - {{name: data, key: test/data, producer: talker, consumers: [listener], type: Sample}}
types:
  Header: {{seq: uint64, stamp: time}}
  Sample: {{header: Header, value: float64}}
brittle: [Header.stamp, Header.seq]
invariants:
  - {{name: value_small, kind: bound, channel: data, field: value, max: 1000}}
"""

POLICY = """<?xml version="1.0" encoding="UTF-8"?>
<testcase id="big-value" seed="1">
  <description>two huge values after 1 s</description>
  <policy id="big"><channel>data</channel><window from="1"/><select limit="2"/>
    <set><field path="value" value="1e9"/></set></policy>
</testcase>
"""


def test_with_trust_log_spec_the_logs_own_commands_run(tmp_path):
    """A real intercepted run that failed, minimised live from its own spec once the user opts in."""
    marker = tmp_path / "witness.marker"
    spec = tmp_path / "trusted.yaml"
    spec.write_text(RECORDED_SPEC.format(sut=SUT_DIR, marker=marker))
    policy = tmp_path / "big.xml"
    policy.write_text(POLICY)
    log = tmp_path / "run.mcap"
    env = dict(os.environ)
    rec = cli("proxy", "--spec", str(spec), "--policy", str(policy), "--record", str(log), "--duration", "3",
              env=env, cwd=tmp_path)
    assert log.exists() and "value_small" in rec.stdout + rec.stderr, rec.stdout + rec.stderr
    assert marker.exists()
    marker.unlink()  # from here on, only the minimisation's own runs can create it
    spec.unlink()  # the log is all there is

    refused = cli("minimise", str(log), "--live-only", "-o", str(tmp_path / "out"), env=env, cwd=tmp_path)
    assert refused.returncode == 2 and "--trust-log-spec" in refused.stderr and not marker.exists()

    done = cli("minimise", str(log), "--live-only", "--trust-log-spec", "--confirm", "0", "--max-tests", "1",
               "-o", str(tmp_path / "out"), env=env, cwd=tmp_path, timeout=300)
    assert done.returncode in (0, 1), done.stdout + done.stderr
    assert "running what the spec stored in the log names (--trust-log-spec):" in done.stdout
    assert "module 'witness': " in done.stdout
    assert marker.exists()  # the log's module command ran, as the user allowed
