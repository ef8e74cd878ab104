"""The faults a module-level search replays against one module: the live generator's values and message faults.

Every (input channel, field) the generator would mutate live — the
exceptional-value targets and the semantic value families' targets of
:class:`~astaa_deft.engine.intercept.generate.FaultTargets` — gets each of its
dictionary values with a value of its own (entries derived from the message
itself are left to the live search), on one message or held on several, at
a message inside the stack's live part; every input channel gets each message
fault (drop, delay by each of the live delays, duplicate, reorder) at a few
messages spread over the live part. The order is the live rounds' (values of
the first class everywhere first: non-finite, empty, extreme, …), channels
interleaved, so a time-boxed search covers every field early.

Pure and deterministic: the same targets, streams, window and seed give the same list.
"""

from __future__ import annotations

import random
from collections.abc import Mapping, Sequence

from astaa_deft.analysis.deft.stream_faults import FaultKind, StreamFault
from astaa_deft.engine.intercept.dictionary.model import DYNAMIC
from astaa_deft.engine.intercept.faults.base import Target
from astaa_deft.engine.intercept.faults.message import DELAYS_MS
from astaa_deft.engine.intercept.generate import VALUE_CLASSES, value_class

MESSAGE_FAULT_SPOTS = 4  # messages of each input channel that each message fault is tried on
HOLD_SHARE = 1 / 3  # value faults held on several messages instead of one
HOLD_MESSAGES = (5, 20)


def plan_faults(*, module: str, inputs: Sequence[str], times: Mapping[str, Sequence[int]],
                window: tuple[int, int], targets: Mapping[str, Sequence[Target]], seed: int) -> list[StreamFault]:
    """Every fault of the module's search, in the order it is tried (module doc).

    ``times``: each input channel's arrival times (ns) in the clean run;
    ``window``: the live part (ns, on the same clock) the faults' messages fall in;
    ``targets``: the generator's targets by channel (only the module's inputs are used).
    """
    lanes: dict[int, list[list[StreamFault]]] = {}
    for channel in inputs:
        spots = _in_window(times.get(channel, ()), window)
        if not spots:
            continue
        rng = random.Random(f"module-level/{seed}/{module}/{channel}")
        by_round: dict[int, list[StreamFault]] = {}
        for target in targets.get(channel, ()):
            for entry in target.values:
                if entry.problem(target.site) is not None:
                    continue
                value = entry.static_value(target.site)
                if value is DYNAMIC:
                    continue
                index = rng.choice(spots)
                held = rng.random() < HOLD_SHARE
                fault = StreamFault(channel=channel, kind=FaultKind.HOLD if held else FaultKind.SET, index=index,
                                    path=str(target.path), value=value, value_ref=entry.ref,
                                    count=rng.randint(*HOLD_MESSAGES) if held else 1)
                by_round.setdefault(_round_of(value_class(entry)), []).append(fault)
        message_faults = []
        picks = _spread(spots, MESSAGE_FAULT_SPOTS, rng)
        for index in picks:
            message_faults += [StreamFault(channel=channel, kind=FaultKind.DROP, index=index),
                               StreamFault(channel=channel, kind=FaultKind.DUPLICATE, index=index),
                               StreamFault(channel=channel, kind=FaultKind.REORDER, index=index)]
            message_faults += [StreamFault(channel=channel, kind=FaultKind.DELAY, index=index, delay_ms=float(ms))
                               for ms in DELAYS_MS]
        by_round.setdefault(0, [])[:0] = message_faults[:len(message_faults) // 2]
        by_round.setdefault(1, []).extend(message_faults[len(message_faults) // 2:])
        for number, faults in by_round.items():
            rng.shuffle(faults)
            lanes.setdefault(number, []).append(faults)
    ordered: list[StreamFault] = []
    for number in sorted(lanes):
        ordered += _interleaved(lanes[number])
    return _unique(ordered)


def _round_of(cls: str) -> int:
    return VALUE_CLASSES.index(cls) if cls in VALUE_CLASSES else len(VALUE_CLASSES)


def _in_window(times: Sequence[int], window: tuple[int, int]) -> list[int]:
    start, end = window
    return [i for i, t in enumerate(times) if start <= t <= end]


def _spread(spots: Sequence[int], count: int, rng: random.Random) -> list[int]:
    """``count`` message indices spread over ``spots`` (one drawn in each of ``count`` equal parts)."""
    if len(spots) <= count:
        return list(spots)
    size = len(spots) / count
    return [spots[int(part * size + rng.random() * size)] for part in range(count)]


def _interleaved(lanes: list[list[StreamFault]]) -> list[StreamFault]:
    out: list[StreamFault] = []
    for turn in range(max((len(lane) for lane in lanes), default=0)):
        out.extend(lane[turn] for lane in lanes if turn < len(lane))
    return out


def _unique(faults: list[StreamFault]) -> list[StreamFault]:
    seen: set[str] = set()
    out = []
    for fault in faults:
        key = repr(fault.to_json())
        if key not in seen:
            seen.add(key)
            out.append(fault)
    return out
