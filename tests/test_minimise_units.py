"""Minimisation building blocks without a live SUT: mutation logs, reverting, pinned test cases, testers.

The logs here are written the way the proxy and the recorder write them —
the real interception engine on a synthetic message stream, the recorder's
own record writer — so what a consumer actually received is known exactly
and the streams rebuilt from the log can be checked against it.
"""

from __future__ import annotations

import heapq
import json
import math
from dataclasses import replace
from pathlib import Path

import pytest

from astaa_deft.engine.bus.topology import intercept_record
from astaa_deft.cli.commands.demo import demo_spec_path
from astaa_deft.engine.intercept import Interceptor, load_dictionary, parse_testcase
from astaa_deft.engine.intercept.actions.base import FieldChange
from astaa_deft.io.codecs import get_codec
from astaa_deft.engine.intercept.actions.set import value_text
from astaa_deft.io.log import layout
from astaa_deft.io.log.reader import read_log
from astaa_deft.engine.session.recorder import InterceptedChannel, _write_intercepted
from astaa_deft.io.log.writer import LogWriter
from astaa_deft.analysis.minimise.ddmin import Outcome
from astaa_deft.analysis.minimise.live_tester import LiveRun, LiveTester
from astaa_deft.analysis.minimise.mutations import (
    Mutation,
    ReceivedStreams,
    Step,
    read_mutations,
    sent_stream,
)
from astaa_deft.analysis.minimise.output import Confirmation
from astaa_deft.analysis.minimise.restrict import restricted_testcase
from astaa_deft.analysis.minimise import workflow
from astaa_deft.analysis.minimise.stages import Failure, Minimisation
from astaa_deft.engine.spec.loader import load_spec

SPEC = load_spec(demo_spec_path())
START_NS = 1_000_000_000_000
LOC_KEY = SPEC.channel("localization").key


def localization(i: int) -> dict:
    return {"header": {"seq": i, "stamp": 0.02 * i}, "x": 1.0 * i, "y": 0.0, "heading": 0.0, "speed": 10.0,
            "acceleration": 0.5, "yaw_rate": 0.0}


def intercepted_log(path: Path, policies: str, count: int = 60) -> dict[str, list[bytes]]:
    """Run ``count`` localization messages through the engine, log them as the recorder does.

    Returns what each consumer (planning, control) received, in delivery order.
    """
    testcase = parse_testcase(f"""<?xml version="1.0" encoding="UTF-8"?>
<testcase id="synthetic" seed="5"><description/>{policies}</testcase>""".encode(), "synthetic.xml", SPEC)
    engine = Interceptor(testcase, SPEC, load_dictionary())
    writer = LogWriter(path, SPEC)
    cid = writer.bus_channel(SPEC.channel("localization"))
    original_cid = writer.bus_channel(SPEC.channel("localization"), topic=layout.ORIGINAL_PREFIX + LOC_KEY)
    mutations_cid = writer.tool_channel(layout.MUTATIONS_TOPIC)
    target = InterceptedChannel(name="localization", codec=get_codec(SPEC.channel("localization").encoding),
                                delivered=cid, original=original_cid, mutations=mutations_cid)
    writer.event("run_started", time_ns=START_NS)
    received: dict[str, list[bytes]] = {"planning": [], "control": []}
    held: list = []
    order = iter(range(10**9))

    def deliver(d, now: float) -> None:
        t = START_NS + round(now * 1e9) + next(order)  # distinct, increasing log times
        for consumer in d.consumers:
            received[consumer].append(d.payload)
        if d.event is None:
            writer.message(cid, t, d.payload)
        else:
            record = intercept_record(d.event.to_json(), d.original, delivered=bool(d.consumers))
            _write_intercepted(writer, target, record, d.payload, log_time=t, publish_time=t)

    def route(deliveries, now: float) -> None:
        for d in deliveries:
            if d.at > now:
                heapq.heappush(held, (d.at, next(order), d))
            else:
                deliver(d, now)

    for step in range(count * 2 + 20):  # 10 ms ticks, a message every 20 ms
        now = step * 0.01
        while held and held[0][0] <= now:
            deliver(heapq.heappop(held)[2], now)
        if step % 2 == 0 and step // 2 < count:
            i = step // 2 + 1
            route(engine.on_message("localization", ("planning", "control"),
                                    json.dumps(localization(i)).encode(), now), now)
        route(engine.on_tick(now), now)
    for d in engine.flush(count * 0.02 + 0.2):
        deliver(d, count * 0.02 + 0.2)
    writer.finish()
    return received


RICH = """
  <policy id="yaw"><channel>localization</channel><select every="3"/><set><field path="yaw_rate" value="0.5"/></set></policy>
  <policy id="acc"><channel>localization</channel><consumer>planning</consumer><select every="4"/>
    <set><field path="acceleration" value="9.5"/><field path="x" value="-1"/></set></policy>
  <policy id="lost"><channel>localization</channel><consumer>control</consumer><select every="7"/><drop/></policy>
  <policy id="late"><channel>localization</channel><consumer>planning</consumer><select every="5"/><delay ms="35"/></policy>
  <policy id="twice"><channel>localization</channel><select every="6"/><duplicate/></policy>
"""


@pytest.fixture(scope="module")
def rich(tmp_path_factory):
    path = tmp_path_factory.mktemp("mlog") / "rich.mcap"
    received = intercepted_log(path, RICH)
    log = read_log(path)
    return log, read_mutations(log, SPEC), received


def test_every_effective_event_is_a_mutation_with_original_and_delivery(rich):
    log, mlog, _ = rich
    events = [json.loads(m.data) for m in log.on(layout.MUTATIONS_TOPIC)]
    assert len(mlog.mutations) == len(events) > 40
    assert mlog.noop == 0
    drops = [m for m in mlog.mutations if "drop" in m.actions]
    assert drops and all(m.delivered is None for m in drops)
    delayed = [m for m in mlog.mutations if m.deferred]
    assert delayed and all(m.delivered_time_ns - m.original_time_ns > 25_000_000 for m in delayed)
    copies = [m for m in mlog.mutations if m.extra]
    assert copies and all(m.delivered == m.original or "set" in m.actions for m in copies)
    assert [m.number for m in mlog.mutations] == list(range(len(mlog.mutations)))
    nan_free = [m.fields for m in mlog.mutations if "set" in m.actions]
    assert all(isinstance(change, FieldChange) for fields in nan_free for change in fields)


def test_consumers_are_who_got_the_delivery_not_who_the_event_names(rich):
    """A set for everyone followed by a set for planning only: control's copy carries the first event,
    whose recorded consumers still name planning too."""
    _, mlog, _ = rich
    by_message: dict[int, list[Mutation]] = {}
    for m in mlog.mutations:
        if not m.extra:
            by_message.setdefault(m.message_index, []).append(m)
    split = [ms for ms in by_message.values() if {m.action for m in ms} >= {"set", "set+set"}]
    assert split, "the policies should stack on some message"
    for ms in split:
        owners = [c for m in ms for c in m.consumers]
        assert sorted(owners) == ["control", "planning"]  # a partition of the channel's consumers
        first = next(m for m in ms if m.action == "set")
        assert first.consumers == ("control",) and list(first.event["consumers"]) == ["planning", "control"]


@pytest.mark.parametrize("module", ["planning", "control"])
def test_streams_with_every_mutation_kept_are_what_the_module_received(rich, module):
    _, mlog, received = rich
    streams = ReceivedStreams(mlog, module, ["localization"])
    kept = streams.build({m.number: None for m in streams.relevant})["localization"]
    assert [d.data for d in kept] == received[module]


@pytest.mark.parametrize("module", ["planning", "control"])
def test_streams_with_every_mutation_reverted_are_the_real_messages_in_order(rich, module):
    _, mlog, _ = rich
    streams = ReceivedStreams(mlog, module, ["localization"])
    reverted = streams.build({})["localization"]
    assert [json.loads(d.data) for d in reverted] == [localization(i) for i in range(1, 61)]
    assert [m.data for m in sent_stream(mlog, read_log(mlog_path(rich)), "localization")] == [d.data for d in reverted]


def mlog_path(rich) -> Path:
    return rich[0].path


def test_reverting_one_mutation_changes_only_its_message(rich):
    _, mlog, received = rich
    streams = ReceivedStreams(mlog, "planning", ["localization"])
    everything = {m.number: None for m in streams.relevant}
    delay = next(m for m in streams.relevant if m.action == "delay")
    copy = next(m for m in streams.relevant if m.extra)
    for undone in (delay, copy):
        kept = {n: s for n, s in everything.items() if n != undone.number}
        stream = streams.build(kept)["localization"]
        if undone is copy:  # the extra copy is gone, nothing else changed
            assert len(stream) == len(received["planning"]) - 1
        else:  # the real message is back at its arrival time: before the ones that overtook it
            seqs = [json.loads(d.data)["header"]["seq"] for d in stream]
            assert seqs.index(undone.message_index) < seqs.index(undone.message_index + 1)


def test_a_field_subset_sets_only_those_fields(rich):
    _, mlog, _ = rich
    both = next(m for m in mlog.mutations if m.policy == "acc" and len(m.fields) == 2)
    only_x = json.loads(both.payload((1,), "json"))
    assert only_x["x"] == -1 and only_x["acceleration"] == 0.5
    assert both.payload(None, "json") == both.delivered == both.payload((0, 1), "json")


# ---------------------------------------------------------------- pinned test cases


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf, None, 0, 1.0, -0.0, 2**70, "fast", "\x00\x1b[31m",
                                   "\udc80", "", [1, {"a": None}], {"float": 1}, True])
def test_value_text_reads_back_as_the_same_value(value):
    from astaa_deft.engine.intercept.actions.set import parse_literal
    from astaa_deft.model.sut import FieldType

    text = value_text(value)
    back = parse_literal(text, FieldType(kind="float64"))
    if isinstance(value, float) and math.isnan(value):
        assert math.isnan(back)
    else:
        assert back == value and type(back) is type(value)
        if isinstance(value, float):
            assert math.copysign(1, back) == math.copysign(1, value)


def mutation(number: int, steps: tuple[Step, ...], fields=(), channel="localization", index=7,
             consumers=("control",), **kw) -> Mutation:
    defaults = dict(time=1.0, at=1.0, original=b"{}", original_time_ns=0, delivered=b"{}", delivered_time_ns=0)
    return Mutation(number=number, channel=channel, steps=steps, consumers=consumers, message_index=index,
                    fields=tuple(fields), **{**defaults, **kw})


def test_restricted_test_case_pins_each_mutation_and_round_trips():
    nan = mutation(3, (Step("p", "set", {}),), [FieldChange("heading", 0.1, math.nan),
                                                  FieldChange("header.stamp", 5.0, 4.0)])
    stacked = mutation(4, (Step("a", "set", {}), Step("b", "delay", {"delay_ms": 250.0})),
                       [FieldChange("speed", 1.0, -1.0)], index=9, consumers=("planning", "control"))
    copies = [mutation(n, (Step("d", "duplicate", {"copy": n - 4, "copies": 2}),), index=11) for n in (5, 6)]
    dropped = mutation(7, (Step("x", "drop", {}),), channel="trajectory", index=2)
    cut = mutation(8, (Step("c", "corrupt", {"truncated_to": 40, "length": 100}),), index=12)
    testcase = restricted_testcase([(nan, (0,)), (stacked, None), *[(c, None) for c in copies], (dropped, None),
                                    (cut, None)], testcase_id="minimal-x", description="d")
    back = parse_testcase(testcase.to_xml(), "minimal.xml", SPEC)
    assert back == testcase
    by_id = {p.id: p for p in back.policies}
    assert sorted(by_id) == ["m0003", "m0004-1", "m0004-2", "m0005", "m0007", "m0008"]
    pinned = by_id["m0003"]
    assert (pinned.window.anchor_channel, pinned.window.anchor_message, pinned.window.start) == ("localization", 7, 0)
    assert pinned.selection.limit == 1 and pinned.consumers == ("control",)
    assert [f.path for f in pinned.action.fields] == ["heading"]  # the field selection holds
    assert by_id["m0004-2"].action.ms == 250.0 and by_id["m0004-1"].consumers == ("planning", "control")
    assert by_id["m0005"].action.copies == 2  # two kept copies of one message: one policy
    assert by_id["m0007"].action.name == "drop"
    assert int(100 * by_id["m0008"].action.keep) == 40


def test_a_pinned_policy_hits_exactly_the_logged_message():
    """The engine counts the anchor message inside its window: message=N selects the N-th message."""
    target = mutation(0, (Step("p", "set", {}),), [FieldChange("yaw_rate", 0.0, 7.0)], index=5,
                      consumers=("control",))
    testcase = restricted_testcase([(target, None)], testcase_id="pin")
    engine = Interceptor(testcase, SPEC, load_dictionary())
    hits = []
    for i in range(1, 11):
        for d in engine.on_message("localization", ("planning", "control"), json.dumps(localization(i)).encode(),
                                   0.02 * i):
            if d.event is not None:
                hits.append((d.event.message_index, d.consumers, json.loads(d.payload)["yaw_rate"]))
    assert hits == [(5, ("control",), 7.0)]


def test_the_rich_log_pinned_and_replayed_gives_the_same_deliveries(rich, tmp_path):
    """All mutations of a log, pinned, through the engine again: each consumer receives what it did."""
    _, mlog, received = rich
    testcase = restricted_testcase([(m, None) for m in mlog.mutations], testcase_id="again")
    policies = testcase.to_xml().decode().split("<description></description>", 1)[1].rsplit("</testcase>", 1)[0]
    again = intercepted_log(tmp_path / "again.mcap", policies)
    assert again == received


# ---------------------------------------------------------------- the live tester's bookkeeping


class ScriptedTester(LiveTester):
    """A live tester whose runs are scripted (no SUT): fail/pass per call, in order."""

    def __init__(self, script: list[bool | None], repeats: int = 1):
        failure = Failure(invariant="control_alive", kind="expression", module="control", channel=None, at=3.0,
                          detail="silent", crash="Silent")
        super().__init__(SPEC, {}, failure, repeats=repeats)
        self.script = list(script)

    def run(self, testcase, horizon, record=None, policy_file=None) -> LiveRun:
        self.runs += 1
        failed = self.script.pop(0)
        return LiveRun(failed, "control_alive: silent" if failed else "Pass", 0.1)


def test_a_live_test_fails_if_any_of_its_runs_fails_and_reports_the_rate():
    tester = ScriptedTester([False, True, False], repeats=3)
    result = tester([])
    assert result.outcome is Outcome.FAIL and result.failure_rate == pytest.approx(1 / 3)
    tester = ScriptedTester([None, False], repeats=2)
    assert tester([]).outcome is Outcome.PASS
    assert ScriptedTester([None]).__call__([]).outcome is Outcome.UNRESOLVED


def test_reproduction_check_tells_flaky_from_not_reproducible():
    m = mutation(0, (Step("p", "set", {}),), [FieldChange("heading", 0.0, 1e16)])
    failure = Failure(invariant="control_alive", kind="deadline", module="control", channel="command", at=3.0,
                      detail="silent", crash="Restart")
    flaky = ScriptedTester([False, True, False])
    result, per_test = workflow.reproduce(flaky, [m], failure, 1, say=lambda line: None)
    assert result.outcome is Outcome.FAIL and result.failure_rate == pytest.approx(0.5) and per_test == 3
    assert flaky.runs == 2  # it stopped at the first failure once it knew the full set fails
    never = ScriptedTester([False, False, False])
    assert workflow.reproduce(never, [m], failure, 1, say=lambda line: None) == (None, 1)
    assert never.runs == 3
    steady = ScriptedTester([True])
    result, per_test = workflow.reproduce(steady, [m], failure, 1, say=lambda line: None)
    assert result.failure_rate == 1.0 and per_test == 1


def test_verdicts_and_exit_codes():
    failure = Failure(invariant="x", kind="bound", module=None, channel="c", at=1.0, detail="", crash="Silent")
    live = Minimisation(tester="live", failure=failure, mutations=[], kept={})
    replay = replace(live, tester="replay")
    assert workflow.verdict(live, Confirmation(runs=3, failures=3, rate=1.0))[1] is True
    text, reproduced = workflow.verdict(live, Confirmation(runs=3, failures=2, rate=2 / 3))
    assert reproduced is False and text.startswith("flaky") and "67%" in text
    assert workflow.verdict(live, Confirmation(runs=3, failures=0, rate=0.0))[1] is False
    assert workflow.verdict(replay, Confirmation(runs=0, failures=0, rate=None))[1] is True
    assert "open-loop" in workflow.verdict(replay, Confirmation(runs=1, failures=0, rate=0.0))[0]
    text, reproduced = workflow.verdict(replay, Confirmation(requested=2, runs=0, failures=0, rate=None,
                                                             details=("the run did not start: port in use",)))
    assert reproduced is False and "port in use" in text
    # The command's exit code is the report's: 0 only when the minimal test case stands.
    report = workflow.MinimiseReport(reproduced=False, verdict=text, summary={"verdict": text}, complete=False)
    assert report.text() == f"minimise: {text}"



def test_jobs_below_one_is_an_input_error_naming_the_option():
    from astaa_deft.model.errors import InputError
    from astaa_deft.analysis.minimise.workflow import MinimiseOptions

    with pytest.raises(InputError, match="--jobs"):
        MinimiseOptions(jobs=0).check()


def test_the_confirmation_in_summary_json_has_its_counts_only_when_no_run_was_asked_for():
    assert Confirmation(runs=0, failures=0, rate=None).to_json() == {
        "requested": 0, "runs": 0, "failures": 0, "rate": None}
    ran = Confirmation(runs=2, failures=1, rate=0.5, requested=3, seconds=1.23456,
                       details=("could not tell", "fail"))
    assert ran.to_json() == {"requested": 3, "runs": 2, "failures": 1, "rate": 0.5, "seconds": 1.235,
                             "details": ["could not tell", "fail"]}
    assert list(ran.to_json()) == ["requested", "runs", "failures", "rate", "seconds", "details"]


def test_live_only_chooses_the_live_tester_whatever_the_failure():
    from astaa_deft.analysis.minimise.stages import TesterKind, choose_tester

    failure = Failure(invariant="planned_speed", kind="bound", module=None, channel="trajectory", at=1.0, detail="",
                      crash="Silent")
    choice = choose_tester(SPEC, failure, live_only=True)
    assert choice.tester is TesterKind.LIVE and choice.why == "--live-only" and choice.entry is None
    assert json.dumps({"tester": choice.tester.value}) == '{"tester": "live"}'
