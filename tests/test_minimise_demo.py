"""`astaa-deft minimise` on real intercepted runs of the demo stack (seeded defect 1).

One run of the demo (lane_follow, defects on) is recorded through the star
proxy with a test case of a dozen benign policies — sets on many fields of
every channel, a consumer-narrowed set, delays, duplicates, drops: over a
hundred mutations — and one policy that sets one routing's speed limit to
NaN, stacked on a benign set of the same message. The planner then plans
over 15 m/s: the `planned_speed` invariant breaks. Minimisation must find
that one mutation, and that one field of it, by planner replay, and the
minimal test case must make the failure happen again live.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

from astaa_deft.engine.session import RunOptions, run_session
from astaa_deft.analysis.minimise.workflow import MinimiseOptions
from astaa_deft.cli.commands import minimise as command
from astaa_deft.cli.commands.demo import demo_noise_policies, demo_spec_path
from astaa_deft.analysis.deft.suite import Suite
from astaa_deft.model.errors import InputError
from astaa_deft.engine.intercept import load_interceptor, load_testcase
from astaa_deft.io.log import layout
from astaa_deft.io.log.reader import read_log
from astaa_deft.analysis.deft.invariant_oracle import check_invariant_oracle
from astaa_deft.analysis.deft.oracle_entry import OracleEntry
from astaa_deft.analysis.minimise.replay_model import Job, ReplaySetup
from astaa_deft.analysis.minimise.replay_pool import ReplayPool
from astaa_deft.analysis.minimise.mutations import ReceivedStreams, read_mutations, sent_stream
from astaa_deft.engine.monitor import check_log
from astaa_deft.engine.spec.loader import load_spec

SPEC_PATH = demo_spec_path()
SPEC = load_spec(SPEC_PATH)

NOISE = demo_noise_policies()  # policies/examples/demo_noise.xml
CULPRIT = """
  <policy id="culprit"><channel>routing</channel><window from="4"/><select limit="1"/>
    <set><field path="speed_limit" value="dict:float.nan"/></set></policy>
"""


def record(directory: Path, name: str, policies: str, seconds: float) -> Path:
    policy = directory / f"{name}.xml"
    policy.write_text(f'<?xml version="1.0" encoding="UTF-8"?>\n<testcase id="{name}" seed="1">'
                      f"<description>test</description>{policies}</testcase>\n")
    log = directory / f"{name}.mcap"
    options = RunOptions(mode="star", interceptor=load_interceptor(policy, SPEC), record=log,
                         params={"scenario": "lane_follow", "defects": "on"}, run_dir=directory / f"run-{name}",
                         attachments={layout.POLICY_ATTACHMENT: policy}, time_limit=seconds)
    run_session(SPEC, options)
    return log


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    directory = tmp_path_factory.mktemp("runs")
    return {"failing": record(directory, "noisy-nan", NOISE + CULPRIT, 6.5), "directory": directory}


@pytest.fixture(scope="module")
def minimised(runs):
    out = runs["directory"] / "minimal"
    code = command.minimise(runs["failing"], out, MinimiseOptions(spec_path=SPEC_PATH, confirm=1))
    return code, out, json.loads((out / "summary.json").read_text())


def test_the_log_holds_over_a_hundred_mutations_and_the_culprit(runs):
    log = read_log(runs["failing"])
    mlog = read_mutations(log, SPEC)
    assert len(mlog.mutations) >= 100
    [culprit] = [m for m in mlog.mutations if "culprit" in m.policy]
    assert culprit.channel == "routing" and [c.path for c in culprit.fields] == ["header.seq", "speed_limit"]
    narrowed = [m for m in mlog.mutations if m.policy.endswith("noise-acc")]
    assert narrowed and all(m.consumers == ("planning",) for m in narrowed)
    streams = ReceivedStreams(mlog, "planning", SPEC.planner.inputs)
    reverted = streams.build({})
    for name in SPEC.planner.inputs:  # with every mutation reverted: what the producer sent
        assert [d.data for d in reverted[name]] == [m.data for m in sent_stream(mlog, log, name)]


def test_replay_minimises_to_the_one_culprit_field_and_it_reproduces_live(minimised):
    code, out, body = minimised
    assert code == 0, body["verdict"]
    assert body["tester"] == "replay"
    assert body["mutations"]["before"] >= 100 and body["mutations"]["after"] == 1
    assert body["fields"]["after"] == 1 and body["frames"]["after"] >= 1
    [event] = body["culprit_events"]
    assert (event["channel"], [f["path"] for f in event["fields"]]) == ("routing", ["speed_limit"])
    assert event["fields"][0]["new"] == {"float": "nan"}
    assert body["tests_run"] <= 100
    # The minimal test case, run live through the proxy, failed the same way.
    assert body["confirmation"]["runs"] == body["confirmation"]["failures"] == 1
    [stage1, stage2, stage3] = body["stages"]
    assert (stage1["name"], stage2["name"], stage3["name"]) == ("mutations", "scaffolding", "fields")


def test_minimal_files_are_valid_and_show_the_failure(minimised):
    _, out, _ = minimised
    testcase = load_testcase(out / "minimal.xml", SPEC)  # what `policy check --spec` accepts
    [policy] = testcase.policies
    assert policy.channels == ("routing",) and policy.selection.limit == 1
    assert policy.window.anchor_channel == "routing"
    log = read_log(out / "minimal.mcap")
    result = check_log(log, SPEC)
    assert [v.invariant for v in result.violations] == ["planned_speed"]
    assert len(log.on(layout.MUTATIONS_TOPIC)) == 1
    assert log.attachments[layout.POLICY_ATTACHMENT] == (out / "minimal.xml").read_bytes()


def test_module_tests_fail_on_the_culprit_and_pass_once_the_planner_is_fixed(minimised, tmp_path):
    _, out, _ = minimised
    suite = Suite(out / "tests")
    [oracle] = suite.manifest["oracles"]
    assert oracle["kind"] == "invariant" and oracle["invariant"] == "planned_speed"
    assert all(r.error is None for r in suite.results())
    assert "planned_speed" in (check_invariant_oracle(suite, OracleEntry.from_json(oracle)) or "")
    # The same suite against the planner with the defect guarded: the oracle holds.
    fixed = tmp_path / "fixed"
    fixed.mkdir()
    manifest = json.loads((out / "tests" / "deft.json").read_text())
    manifest["params"]["defects"] = "off"
    (fixed / "deft.json").write_text(json.dumps(manifest))
    (fixed / "frames.mcap").write_bytes((out / "tests" / "frames.mcap").read_bytes())
    assert check_invariant_oracle(Suite(fixed), OracleEntry.from_json(oracle)) is None


def test_pytest_runs_the_module_tests(minimised):
    _, out, _ = minimised
    res = subprocess.run([sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-q", str(out / "tests")],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 1 and "1 failed" in res.stdout and "planned_speed" in res.stdout, res.stdout


# ---------------------------------------------------------------- errors


def copy_log(source: Path, target: Path, keep=lambda channel, message: True,
             change=lambda channel, message: message.data) -> Path:
    """Rewrite an MCAP log record by record, dropping and changing messages."""
    with open(source, "rb") as src, open(target, "wb") as dst:
        reader = make_reader(src)
        writer = Writer(dst)
        writer.start(profile=layout.PROFILE, library="test")
        schemas, channels = {}, {}
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            if not keep(channel, message):
                continue
            if schema is not None and schema.id not in schemas:
                schemas[schema.id] = writer.register_schema(schema.name, schema.encoding, schema.data)
            if channel.id not in channels:
                channels[channel.id] = writer.register_channel(channel.topic, channel.message_encoding,
                                                               schemas.get(channel.schema_id, 0), channel.metadata)
            writer.add_message(channels[channel.id], message.log_time, change(channel, message),
                               message.publish_time, message.sequence)
        for attachment in reader.iter_attachments():
            writer.add_attachment(attachment.create_time, attachment.log_time, attachment.name,
                                  attachment.media_type, attachment.data)
        for metadata in reader.iter_metadata():
            writer.add_metadata(metadata.name, metadata.metadata)
        writer.finish()
    return target


def test_an_invariant_that_never_broke_is_an_input_error(runs, tmp_path):
    with pytest.raises(InputError, match="never broke in this run"):
        command.minimise(runs["failing"], tmp_path / "out",
                         MinimiseOptions(spec_path=SPEC_PATH, invariant="no_collision", confirm=0))


def test_a_log_without_mutations_is_an_input_error(runs, tmp_path):
    plain = copy_log(runs["failing"], tmp_path / "plain.mcap",
                     keep=lambda channel, message: channel.topic != layout.MUTATIONS_TOPIC)
    with pytest.raises(InputError, match="holds no mutations"):
        command.minimise(plain, tmp_path / "out", MinimiseOptions(spec_path=SPEC_PATH, confirm=0))


def test_a_run_that_did_not_fail_is_an_input_error(runs, tmp_path):
    benign = record(runs["directory"], "benign", NOISE, 4.0)
    assert read_mutations(read_log(benign), SPEC).mutations
    with pytest.raises(InputError, match="did not fail"):
        command.minimise(benign, tmp_path / "out", MinimiseOptions(spec_path=SPEC_PATH, confirm=0))


def test_a_failure_the_mutations_do_not_cause_is_reported_not_minimised(runs, tmp_path, capsys):
    """The culprit's event removed and its message put back: the log still says planned_speed broke."""
    log = read_log(runs["failing"])
    events = [json.loads(m.data) for m in log.on(layout.MUTATIONS_TOPIC)]
    [culprit] = [e for e in events if "culprit" in e["policy"]]
    routing = SPEC.channel("routing").key
    original = log.on(layout.ORIGINAL_PREFIX + routing)[culprit["original_sequence"] - 1].data

    def keep(channel, message):
        return not (channel.topic == layout.MUTATIONS_TOPIC and json.loads(message.data) == culprit)

    def change(channel, message):
        hit = channel.topic == routing and message.sequence == culprit["delivered_sequence"]
        return original if hit else message.data

    undone = copy_log(runs["failing"], tmp_path / "undone.mcap", keep, change)
    code = command.minimise(undone, tmp_path / "out",
                            MinimiseOptions(spec_path=SPEC_PATH, confirm=0, live_fallback=False))
    assert code == 1
    out = capsys.readouterr().out
    assert "does not reproduce in the planner replay" in out and "Traceback" not in out
    assert "does not reproduce" in json.loads((tmp_path / "out" / "summary.json").read_text())["verdict"]


def test_minimisation_is_a_library_call_reporting_through_its_callback(runs, tmp_path, capsys):
    """The same undone culprit through minimise_log: progress goes to the callback, nothing is printed."""
    from astaa_deft.analysis.minimise.workflow import MinimiseOptions, minimise_log

    log = read_log(runs["failing"])
    [culprit] = [e for e in (json.loads(m.data) for m in log.on(layout.MUTATIONS_TOPIC)) if "culprit" in e["policy"]]
    routing = SPEC.channel("routing").key
    original = log.on(layout.ORIGINAL_PREFIX + routing)[culprit["original_sequence"] - 1].data
    undone = copy_log(runs["failing"], tmp_path / "undone.mcap",
                      lambda channel, message: not (channel.topic == layout.MUTATIONS_TOPIC
                                                    and json.loads(message.data) == culprit),
                      lambda channel, message: original if (channel.topic == routing and message.sequence
                                                            == culprit["delivered_sequence"]) else message.data)
    lines: list[str] = []
    report = minimise_log(undone, tmp_path / "out", MinimiseOptions(spec_path=SPEC_PATH, confirm=0,
                                                                    live_fallback=False), progress=lines.append)
    assert capsys.readouterr().out == ""
    assert any(line.startswith("tester: replay") for line in lines)
    assert not report.reproduced and not report.complete
    assert "does not reproduce in the planner replay" in report.verdict
    assert report.summary == json.loads((tmp_path / "out" / "summary.json").read_text())


def test_the_cli_reports_bad_input_without_a_traceback(runs, tmp_path, capsys):
    from astaa_deft import cli

    code = cli.main(["minimise", str(runs["failing"]), "--spec", str(SPEC_PATH), "--invariant", "no_such",
                     "-o", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and "never broke" in err and "Traceback" not in err


# ---------------------------------------------------------------- a hanging planner


HANGING = '''
import math
from astaa_deft.demo.planner_core import Planner as Real


class Planner(Real):
    """The demo planner, but a NaN speed limit makes it spin forever."""

    def step(self, frame):
        if not math.isfinite(frame["routing"]["speed_limit"]):
            while True:
                pass
        return super().step(frame)
'''


def test_a_hanging_planner_is_stopped_and_the_test_is_unresolved(runs, tmp_path, monkeypatch):
    (tmp_path / "hanging_planner.py").write_text(HANGING)
    spec_text = SPEC_PATH.read_text().replace("astaa_deft.demo.planner_core:Planner", "hanging_planner:Planner")
    spec_file = tmp_path / "demo_hanging.yaml"
    spec_file.write_text(spec_text)
    monkeypatch.setenv("PYTHONPATH", f"{tmp_path}:{Path(__file__).resolve().parents[1]}")
    culprit = next(m for m in read_mutations(read_log(runs["failing"]), SPEC).mutations if "culprit" in m.policy)
    with ReplayPool(ReplaySetup(log_path=str(runs["failing"]), spec_path=str(spec_file), invariant="planned_speed"),
                    workers=1, timeout=3.0) as pool:
        started = time.monotonic()
        answer = pool.run(Job.of({culprit.number: None}))
        assert answer.result.outcome.value == "unresolved" and "over 3 s" in answer.result.detail
        assert time.monotonic() - started < 60 and pool.timeouts == 1
        assert pool.run(Job.of({})).result.outcome.value == "pass"  # a fresh worker took over
