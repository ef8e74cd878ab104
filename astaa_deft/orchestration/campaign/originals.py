"""A failing case's invariants judged again on what the producers sent, not on what the case rewrote.

The monitors judge what the consumers received. When a case rewrites a
channel an invariant reads, a violation may exist only in the rewritten
messages (a collision with an obstacle whose length the case blew up) or
in the world as the producers published it (the planner, misled, drove into
a real obstacle). The log holds both sides — each mutated delivery's
original under ``/astaa/original/<key>`` — so the question is answered by
judging the invariant again with those channels carrying their producers'
messages (``minimise.mutations.sent_stream``: originals in place of
mutations, dropped messages back, injected ones gone, deferred ones at their
arrival time) and everything else as recorded.
"""

from __future__ import annotations

import copy
from collections.abc import Collection
from dataclasses import replace
from pathlib import Path

from astaa_deft.model.errors import InputError
from astaa_deft.io.log.reader import read_log
from astaa_deft.analysis.minimise.mutations import read_mutations, sent_stream
from astaa_deft.engine.monitor.offline import check_log
from astaa_deft.model.sut import Spec


def broken_on_originals(log_path: Path, spec: Spec, invariants: Collection[str],
                        channels: Collection[str]) -> set[str] | None:
    """The names among ``invariants`` that still break when ``channels`` carry their producers' messages.

    ``spec``'s invariants must be typed (a loaded spec). Returns None when
    the log cannot tell (missing, unreadable, mutation records that do not
    fit together): the caller decides what an unjudged finding means.
    """
    try:
        log = read_log(log_path)
        mutations = read_mutations(log, spec)
    except InputError:
        return None
    keys = {spec.channel(name).key for name in channels}
    view = copy.copy(log)  # the same log, with the producers' side of ``channels``
    view.messages = [m for m in log.messages if m.topic not in keys]
    for name in channels:
        view.messages.extend(sent_stream(mutations, log, name))
    judged = replace(spec, invariants=tuple(i for i in spec.invariants if i.name in invariants))
    return {v.invariant for v in check_log(view, judged).violations} & set(invariants)
