"""What a live run's own timing made possible: deadline misses the stack's modules really made.

On a loaded machine a module can really go silent past its deadline: the
monitor is right to say so, and a test of a clean run must not call that a
false finding. What a test can hold the tool to is the publishers' own
clocks: each message carries the time its publisher stamped it with
(``publish_time``, the publishing session's own timestamp), so a deadline
miss the stack made shows as a gap between two of its own stamps, while one
the proxy made (by delivering or recording late) does not.
"""

from __future__ import annotations

from astaa_deft.engine.monitor.kinds.deadline import DeadlineInvariant
from astaa_deft.io.log.reader import LogContents
from astaa_deft.model.records import Violation
from astaa_deft.model.sut import Spec


def made_by_the_stack(violation: Violation, log: LogContents, spec: Spec) -> bool:
    """Whether ``violation`` is a channel deadline the publisher's own stamps show it missed: the message
    before the silence and the next one (or the run's end) further apart than the deadline allows."""
    if violation.invariant_kind != "deadline" or violation.channel is None:
        return False
    deadline = next(inv for inv in spec.invariants if inv.name == violation.invariant)
    assert isinstance(deadline, DeadlineInvariant), deadline
    max_gap_ns = deadline.max_gap_ns
    topic = next(t for t, info in log.channels.items() if info.metadata.get("channel") == violation.channel)
    stamps = [m.publish_time for m in log.on(topic)]
    before = [t for t in stamps if t <= violation.time_ns - max_gap_ns]
    if not before:
        return False
    after = [t for t in stamps if t > before[-1]]
    end = after[0] if after else max(m.log_time for m in log.messages)
    return end - before[-1] > max_gap_ns


def unexplained(violations: list[Violation] | tuple[Violation, ...], log: LogContents, spec: Spec) -> list[str]:
    """The violations of a clean run the stack's own timing does not account for (each as 'invariant: detail')."""
    return [f"{v.invariant}: {v.detail}" for v in violations if not made_by_the_stack(v, log, spec)]


def overtaken_before_read(log: LogContents, spec: Spec, *, read_on: str, answered_on: str) -> bool:
    """Whether no mutated message of the run can have been read: after each, the next one on its channel came
    before the consumer answered (on ``answered_on``, by its own stamps) a message of ``read_on``. A consumer
    that uses only the newest message it has whenever ``read_on`` speaks (demo control reads the newest
    trajectory at each localization) then never saw a mutated one; a loaded machine's bursts, or a consumer it
    stalls, do that. False for a run without mutations."""
    from astaa_deft.analysis.minimise.mutations import read_mutations  # the tool's own reading of the records

    mutations = read_mutations(log, spec).mutations
    if not mutations:
        return False
    reads = sorted((m.log_time, m.publish_time) for m in log.on(spec.channel(read_on).key))
    answers = sorted(m.publish_time for m in log.on(spec.channel(answered_on).key))
    for mutation in mutations:
        delivered = mutation.delivered_time_ns
        if delivered is None:
            continue
        upto = min((m.log_time for m in log.on(spec.channel(mutation.channel).key) if m.log_time > delivered),
                   default=None)
        window = [published for logged, published in reads if delivered < logged and (upto is None or logged <= upto)]
        if window and any(window[0] < a and (upto is None or a <= upto) for a in answers):
            return False
    return True
