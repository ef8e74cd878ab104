"""A test case that makes exactly a chosen subset of a run's mutations happen again, live.

The logged test case cannot simply be re-run with some policies left out: a
policy selects by windows, counts and seeded chances, so dropping one policy
or narrowing another changes which messages the rest hit. Instead every kept
mutation becomes a policy of its own that pins the very message it hit:

* ``<window from="0"><after channel="C" message="N"/></window>`` opens the
  window at the arrival of the N-th real message on the channel (the engine
  counts that message inside its window, so N is the event's
  ``message_index`` itself) and ``<select limit="1"/>`` takes that one
  message and no other;
* the consumers are the ones that got the mutated delivery (see
  :mod:`.mutations`), so a mutation that reached only ``control`` stays that way;
* ``set`` fields are written as literals of the values that were actually
  sent (``json:`` form, which carries NaN, infinities, nulls, mistyped values
  and lone surrogates exactly; base64 for binary values), never as the
  dictionary rule that produced them (``time.jump_back`` recomputed on
  another run would give another value);
* a stacked mutation (``set+delay``) becomes one policy per step, in order,
  on the same message: the engine stacks them the same way;
* the kept copies of one message become one ``duplicate`` with that many
  copies, after the real message's own policies (separate policies would
  duplicate each other's copies; see ``_copy_key`` for copies that carry
  changes).

What cannot be pinned exactly, and is approximated: an ``interleave``
injection is made the first slot after its template message at the original
policy's rate; a ``corrupt`` flip damages the same number of bytes, drawn
afresh; a ``reorder`` keeps the original policy's ``max-hold-ms``; a copy
that carries changes (``set+duplicate``) kept without its real message
brings those changes onto the real message too. Their outcome is checked by the live
confirmation runs like any other.
"""

from __future__ import annotations

import base64
import json
from pathlib import Path
from typing import Any, Mapping, Sequence

from ..intercept.actions import ACTIONS
from ..intercept.actions.base import ActionConfig
from ..intercept.actions.corrupt import Corrupt
from ..intercept.actions.delay import Delay
from ..intercept.actions.drop import Drop
from ..intercept.actions.duplicate import Duplicate
from ..intercept.actions.interleave import Interleave
from ..intercept.actions.reorder import Reorder
from ..intercept.actions.set import Assignment, Set
from ..intercept.testcase import Policy, Selection, TestCase, Window
from .mutations import FieldSelection, Mutation

DEFAULT_INJECTION_RATE = 10.0  # Hz, for an injection whose policy is unknown
MAX_RATE = 1000.0  # the schema's bound


def value_text(value: Any) -> str:
    """A ``<field value=…>`` that sets exactly ``value`` whatever the field's declared type.

    ``json:`` with ASCII escapes: the text stays valid XML (control
    characters and lone surrogates are escaped) and reads back to the same
    Python value (NaN and infinities included). Bytes go as base64, which a
    ``bytes`` field reads as binary.
    """
    if isinstance(value, (bytes, bytearray)):
        return base64.b64encode(bytes(value)).decode("ascii")
    return "json:" + json.dumps(value, ensure_ascii=True, allow_nan=True, separators=(",", ":"))


def restricted_testcase(chosen: Sequence[tuple[Mutation, FieldSelection]], *, testcase_id: str,
                        description: str = "", seed: int = 0, original: TestCase | None = None) -> TestCase:
    """One pinned policy per kept mutation (per step of a stacked one), in the order given.

    ``original`` is the logged test case, if known: it supplies what events do
    not record (an injection's rate, a reorder's hold time, corrupt modes).
    """
    policies: list[Policy] = []
    originals = {p.id: p for p in original.policies} if original is not None else {}
    copies = _copies(chosen)
    for mutation, selection in chosen:
        if _copy_key(mutation, chosen) is not None:
            count = copies.pop(_copy_key(mutation, chosen), 0)
            if count:
                policies.append(_pinned(mutation, "", Duplicate(count)))
            continue
        fields = mutation.fields if selection is None else tuple(mutation.fields[i] for i in selection)
        assignments = tuple(Assignment(c.path, value_text(c.new)) for c in fields)
        steps = mutation.steps
        field_step = next((i for i, s in enumerate(steps) if s.action in ("set", "interleave")), None)
        for n, step in enumerate(steps):
            action = _action(step.action, step.detail, assignments if n == field_step else (),
                             originals.get(step.policy))
            if action is None:
                continue  # a set step whose fields all went to another step or were minimised away
            policies.append(_pinned(mutation, f"-{n + 1}" if len(steps) > 1 else "", action))
    return TestCase(id=testcase_id, seed=seed, description=description, policies=tuple(policies))


def _pinned(mutation: Mutation, suffix: str, action: ActionConfig) -> Policy:
    """A policy doing ``action`` to the one message ``mutation`` hit, for its consumers only."""
    return Policy(id=f"m{mutation.number:04d}{suffix}", action=action, channels=(mutation.channel,),
                  consumers=tuple(mutation.consumers),
                  window=Window(0.0, None, mutation.channel, max(mutation.message_index, 1)),
                  selection=Selection(limit=1))


def _copy_key(mutation: Mutation, chosen: Sequence[tuple[Mutation, FieldSelection]]) -> tuple | None:
    """(channel, message, consumers) if ``mutation`` can be pinned as a plain copy, else None.

    A copy is made from the real message as the steps before its duplication
    left it, and the steps after act on both; the real message's own event
    holds all of them but the duplication. So when the real delivery to the
    same consumers is kept too (or the copy has no other step), a plain
    ``duplicate`` pinned after the real message's policies makes the very
    same copy. Otherwise the copy's steps are pinned as they are — and reach
    the real message as well (an approximation the engine cannot avoid).
    """
    if "duplicate" not in mutation.actions or mutation.actions & {"interleave"}:
        return None
    key = (mutation.channel, mutation.message_index, mutation.consumers)
    if mutation.actions == {"duplicate"}:
        return key
    real = {c for m, _ in chosen if not m.extra and (m.channel, m.message_index) == key[:2] for c in m.consumers}
    return key if set(mutation.consumers) <= real else None


def _copies(chosen: Sequence[tuple[Mutation, FieldSelection]]) -> dict[tuple, int]:
    """Plain copies per message: one policy duplicating k times (k policies would stack to 2^k - 1)."""
    out: dict[tuple, int] = {}
    for mutation, _ in chosen:
        key = _copy_key(mutation, chosen)
        if key is not None:
            out[key] = out.get(key, 0) + 1
    return out


def _action(name: str, detail: Mapping[str, Any], assignments: tuple[Assignment, ...],
            original: Policy | None) -> ActionConfig | None:
    before = original.action if original is not None and original.action.name == name else None
    if name == "set":
        return Set(assignments) if assignments else None
    if name == "drop":
        return Drop()
    if name == "delay":
        ms = detail.get("delay_ms", getattr(before, "ms", None))
        return Delay(float(ms)) if ms else None
    if name == "duplicate":
        return Duplicate(1)  # each extra copy is a mutation of its own
    if name == "reorder":
        return Reorder(before.max_hold_ms) if isinstance(before, Reorder) else Reorder()
    if name == "interleave":
        rate = before.rate if isinstance(before, Interleave) else DEFAULT_INJECTION_RATE
        return Interleave(min(rate, MAX_RATE), assignments)
    if name == "corrupt":
        if "truncated_to" in detail and detail.get("length"):
            keep = (int(detail["truncated_to"]) + 0.5) / int(detail["length"])
            return Corrupt("truncate", keep=min(keep, 0.999999))
        if "flipped_bytes" in detail:
            return Corrupt("flip", bytes=max(len(detail["flipped_bytes"]), 1))
        return before if isinstance(before, Corrupt) else None
    if name in ACTIONS and before is not None:  # an action added later: its original form
        return before
    return None


def write_testcase(testcase: TestCase, path: Path) -> Path:
    path.write_bytes(testcase.to_xml())
    return path
