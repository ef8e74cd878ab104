"""A test case that makes exactly a chosen subset of a run's mutations happen again, live.

The logged test case cannot simply be re-run with some policies left out: a
policy selects by windows, counts and seeded chances, so dropping one policy
or narrowing another changes which messages the rest hit. Instead every kept
mutation becomes a policy of its own that pins the very message it hit:

* ``<window from="0"><after channel="C" message="N"/></window>`` opens the
  window at the arrival of the N-th real message on the channel (the engine
  counts that message inside its window, so N is the event's
  ``message_index`` itself) and ``<select limit="1"/>`` takes that one
  message and no other; a mutation made once the stack was live is counted
  from the running stack instead (``Mutation.pin``, :mod:`.anchoring`):
  ``<window from="S"><after channel="ANCHOR" message="M"/></window>``, the
  first message of C from S seconds after the anchor's M-th message;
* the consumers are the ones that got the mutated delivery (see
  :mod:`.mutations`), so a mutation that reached only ``control`` stays that way;
* each action pins itself (``ActionConfig.pinned``, in its own module):
  ``set`` fields, for instance, are written as literals of the values that
  were actually sent (``json:`` form, which carries NaN, infinities, nulls,
  mistyped values and lone surrogates exactly; base64 for binary values),
  never as the dictionary rule that produced them (``time.jump_back``
  recomputed on another run would give another value);
* a stacked mutation (``set+delay``) becomes one policy per step, in order,
  on the same message: the engine stacks them the same way;
* the kept copies of one message become one ``duplicate`` (an action with
  ``pins_copies``) with that many copies, after the real message's own policies (separate policies would
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

from collections.abc import Sequence
from pathlib import Path

from astaa_deft.io.output_place import write_atomic
from astaa_deft.engine.intercept.actions import ACTIONS
from astaa_deft.engine.intercept.actions.base import ActionConfig, PinnedStep
from astaa_deft.engine.intercept.testcase import Policy, Selection, TestCase, Window
from astaa_deft.analysis.minimise.mutations import FieldSelection, Mutation


def restricted_testcase(chosen: Sequence[tuple[Mutation, FieldSelection]], *, testcase_id: str,
                        description: str = "", seed: int = 0, original: TestCase | None = None) -> TestCase:
    """One pinned policy per kept mutation (per step of a stacked one), in the order given.

    ``original`` is the logged test case, if known: it supplies what events do
    not record (an injection's rate, a reorder's hold time, corrupt modes).
    Each action pins itself (``ActionConfig.pinned``); this module knows no action by name.
    """
    policies: list[Policy] = []
    originals = {p.id: p for p in original.policies} if original is not None else {}
    copies = _copies(chosen)
    for mutation, selection in chosen:
        copy_key = _copy_key(mutation, chosen)
        if copy_key is not None:
            count = copies.pop(copy_key, 0)
            if count:
                policies.append(_pinned(mutation, "", _copying_action(mutation).pin_copies(count)))
            continue
        fields = mutation.fields if selection is None else tuple(mutation.fields[i] for i in selection)
        steps = mutation.steps
        field_step = next((i for i, s in enumerate(steps) if _kind(s.action, "carries_fields")), None)
        for n, step in enumerate(steps):
            action = _step_action(step.action, PinnedStep(step.detail, fields if n == field_step else (),
                                                          _original_action(originals.get(step.policy), step.action)))
            if action is None:
                continue  # a set step whose fields all went to another step or were minimised away
            policies.append(_pinned(mutation, f"-{n + 1}" if len(steps) > 1 else "", action))
    return TestCase(id=testcase_id, seed=seed, description=description, policies=tuple(policies))


def _kind(action: str, flag: str) -> bool:
    """Whether the action named ``action`` has ``flag`` (False for an action this version does not know)."""
    cls = ACTIONS.get(action)
    return bool(cls is not None and getattr(cls, flag))


def _step_action(name: str, step: PinnedStep) -> ActionConfig | None:
    cls = ACTIONS.get(name)
    return cls.pinned(step) if cls is not None else None


def _original_action(policy: Policy | None, name: str) -> ActionConfig | None:
    return policy.action if policy is not None and policy.action.name == name else None


def _copying_action(mutation: Mutation) -> type[ActionConfig]:
    return next(ACTIONS[a] for a in sorted(mutation.actions) if _kind(a, "pins_copies"))


def _pinned(mutation: Mutation, suffix: str, action: ActionConfig) -> Policy:
    """A policy doing ``action`` to the one message ``mutation`` hit, for its consumers only."""
    pin = mutation.pin
    window = Window(pin.after, None, pin.channel, pin.message) if pin is not None else \
        Window(0.0, None, mutation.channel, max(mutation.message_index, 1))
    return Policy(id=f"m{mutation.number:04d}{suffix}", action=action, channels=(mutation.channel,),
                  consumers=tuple(mutation.consumers), window=window, selection=Selection(limit=1))


def _copy_key(mutation: Mutation, chosen: Sequence[tuple[Mutation, FieldSelection]]) -> tuple | None:
    """(channel, message, consumers) if ``mutation`` can be pinned as a plain copy, else None.

    A copy is made from the real message as the steps before its duplication
    left it, and the steps after act on both; the real message's own event
    holds all of them but the duplication. So when the real delivery to the
    same consumers is kept too (or the copy has no other step), a plain
    copying action pinned after the real message's policies makes the very
    same copy. Otherwise the copy's steps are pinned as they are — and reach
    the real message as well (an approximation the engine cannot avoid).
    An extra delivery that is not a copy (an injection) is never one.
    """
    copying = {a for a in mutation.actions if _kind(a, "pins_copies")}
    injecting = {a for a in mutation.actions if _kind(a, "adds_delivery")} - copying
    if not copying or injecting:
        return None
    key = (mutation.channel, mutation.message_index, mutation.consumers)
    if mutation.actions == copying:
        return key
    real = {c for m, _ in chosen if not m.extra and (m.channel, m.message_index) == key[:2] for c in m.consumers}
    return key if set(mutation.consumers) <= real else None


def _copies(chosen: Sequence[tuple[Mutation, FieldSelection]]) -> dict[tuple, int]:
    """Plain copies per message: one policy copying k times (k policies would stack to 2^k - 1)."""
    out: dict[tuple, int] = {}
    for mutation, _ in chosen:
        key = _copy_key(mutation, chosen)
        if key is not None:
            out[key] = out.get(key, 0) + 1
    return out


def write_testcase(testcase: TestCase, path: Path) -> Path:
    write_atomic(path, testcase.to_xml())  # whole, never through a link
    return path
