"""Pinned mutations hit the same message of the live run when the SUT starts later (minimise/anchoring.py).

Regression: pins counted from the run's start made a minimised test case hit
another message when the stack started a little later or earlier (one
acceptance run called the demo's localization reorder "not reproduced").
tests/sut/anchored.yaml: 'clock' ticks from its start, 'responder' joins after
``delay`` seconds; each tick says how many acknowledgements the clock had,
i.e. where in the live run it is.
"""

from __future__ import annotations

import json
from pathlib import Path

from astaa_deft.engine.intercept.dictionary import load_dictionary
from astaa_deft.engine.intercept.engine import Interceptor
from astaa_deft.engine.intercept.testcase import TestCase, parse_testcase
from astaa_deft.io.log.reader import read_log
from astaa_deft.analysis.minimise.anchoring import choose_anchor, pin_to_anchor
from astaa_deft.analysis.minimise.mutations import Mutation, read_mutations
from astaa_deft.analysis.minimise.restrict import restricted_testcase
from astaa_deft.engine.session import RunOptions, run_session
from astaa_deft.engine.spec.loader import load_spec

ANCHORED = Path(__file__).parent / "sut" / "anchored.yaml"
# One tick, 0.3 s into the live run (counted from the first acknowledgement), gets value 7.
POLICY = (b'<testcase id="t" seed="1"><description>x</description><policy id="p1"><channel>tick</channel>'
          b'<window from="0.3"><after channel="ack" message="1"/></window><select limit="1"/>'
          b'<set><field path="value" value="7.0"/></set></policy></testcase>')


def _run(spec, testcase: TestCase, delay: float, log: Path) -> list[Mutation]:
    options = RunOptions(mode="star", interceptor=Interceptor(testcase, spec, load_dictionary()), record=log,
                         params={"delay": str(delay)}, run_dir=log.parent / f"{log.stem}-modules",
                         time_limit=delay + 2.5)
    result = run_session(spec, options)
    assert result.complete and result.mutations == 1, result
    return read_mutations(read_log(log), spec).mutations


def _acks(mutation: Mutation) -> int:
    return json.loads(mutation.original)["acks"]


def _acks_routed_around(mutation: Mutation, log_path: Path, spec) -> tuple[int, int]:
    """Where the mutated tick is in the live run, as a pin to ``ack`` counts it: the acknowledgements the proxy
    routed before the tick before it, and before it (the log's times are the proxy's). A pin to ack M takes the
    first tick after ack M: M lies in between. Counting ticks instead would measure the responder's pace as well,
    which a loaded machine slows (the clock ticks on regardless, and a late responder acknowledges a burst)."""
    log = read_log(log_path)
    acks = [m.log_time for m in log.on(spec.channel("ack").key)]
    previous = max(m.log_time for m in log.on(spec.channel("tick").key) if m.log_time < mutation.original_time_ns)
    return sum(1 for t in acks if t < previous), sum(1 for t in acks if t < mutation.original_time_ns)


def test_a_pinned_mutation_hits_the_same_live_message_when_the_stack_starts_later(tmp_path: Path):
    spec = load_spec(ANCHORED)
    original = parse_testcase(POLICY, "t", spec, load_dictionary())
    first = _run(spec, original, 0.2, tmp_path / "original.mcap")
    log = read_log(tmp_path / "original.mcap")
    mlog = read_mutations(log, spec)
    assert choose_anchor(log, mlog, original) == "ack"  # the test case's own anchor
    assert choose_anchor(log, mlog, None) == "ack"  # else the channel that started last
    pinned = pin_to_anchor(mlog, log, "ack").mutations
    assert pinned[0].pin is not None and pinned[0].pin.channel == "ack"
    assert _acks(first[0]) >= 1  # hit inside the live run: the clock had heard the responder (0.3 s after its
    # first acknowledgement; how many more came by then is the responder's pace, which load slows)
    assert _acks_routed_around(first[0], tmp_path / "original.mcap", spec)[1] == pinned[0].pin.message

    # The stack now starts three seconds later: ~150 more ticks before the first acknowledgement (a loaded
    # machine's start-up of the responder varies by a second or so: far less than that).
    again = _run(spec, restricted_testcase([(pinned[0], None)], testcase_id="min"), 3.2, tmp_path / "later.mcap")
    # Counted from the running stack: the first tick after the same acknowledgement, give or take one of message
    # timing (the interceptor counts acknowledgements as it routes them, the log as the recorder got them) ...
    before_previous, before = _acks_routed_around(again[0], tmp_path / "later.mcap", spec)
    pin = pinned[0].pin
    if pin.after == 0:
        assert before_previous - 1 < pin.message <= before + 1, (before_previous, before, pin)
    else:  # the window opens a moment after ack M (ticks came faster than acks there): a tick after it
        assert pin.message <= before + 1, (before, pin)
    # ... which, counted from the run's start, is another message number.
    assert again[0].message_index > first[0].message_index + 20


def test_a_mutation_before_the_stack_is_live_keeps_its_count_from_the_start(tmp_path: Path):
    spec = load_spec(ANCHORED)
    early = POLICY.replace(b'<window from="0.3"><after channel="ack" message="1"/></window>',
                           b'<window from="0"><after channel="tick" message="3"/></window>')
    _run(spec, parse_testcase(early, "t", spec, load_dictionary()), 0.5, tmp_path / "early.mcap")
    log = read_log(tmp_path / "early.mcap")
    mlog = read_mutations(log, spec)
    pinned = pin_to_anchor(mlog, log, "ack").mutations
    assert pinned[0].pin is None and pinned[0].message_index == 3
    xml = restricted_testcase([(pinned[0], None)], testcase_id="min").to_xml().decode()
    assert '<after channel="tick" message="3"/>' in xml


# A delay alone (no mutation delivered at once to calibrate the interceptor's clock by): where did the
# delayed message really arrive? Regression: the run's start stood in for the interceptor's clock origin,
# late by the recorder's start-up, so the reverted message landed after its successor — a campaign's
# delayed-localization bucket then "failed without any mutation" and could not be minimised.
DELAY = (b'<testcase id="d" seed="1"><description>x</description><policy id="p1"><channel>tick</channel>'
         b'<window from="0.3"><after channel="ack" message="1"/></window><select limit="1"/>'
         b'<delay ms="60"/></policy></testcase>')


def test_a_reverted_delayed_message_arrives_between_its_neighbours(tmp_path: Path):
    spec = load_spec(ANCHORED)
    testcase = parse_testcase(DELAY, "d", spec, load_dictionary())
    mutation = _run(spec, testcase, 0.2, tmp_path / "delayed.mcap")[0]
    log = read_log(tmp_path / "delayed.mcap")
    seq = json.loads(mutation.original)["seq"]
    arrived = {json.loads(m.data)["seq"]: m.log_time for m in log.on("anchored/tick")
               if m.data != mutation.original}  # the untouched ticks (the delayed one is logged late)
    assert mutation.delivered_time_ns is not None and mutation.delivered_time_ns > arrived[seq + 1]
    assert arrived[seq - 1] < mutation.original_time_ns < arrived[seq + 1]
