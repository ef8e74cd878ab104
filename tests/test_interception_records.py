"""What the proxy sends the recorder about an intercepted delivery, and what the recorder makes of it.

The event travels as ``marshal`` data (cheap on the proxy's thread) and the
recorder writes its JSON form: that form must be exactly the one
``Mutation.to_json`` gives, whatever the values (exceptional floats,
bytes, lone surrogates, objects that look like tags, types marshal refuses).
"""

from __future__ import annotations

import json
from collections import OrderedDict

import pytest

from astaa_deft.engine.bus.topology import (
    EVENT_JSON, EVENT_MARSHAL, intercept_record, pack_deliveries, read_intercept_record, unpack_deliveries,
)
from astaa_deft.model.records import FieldChange, Mutation
from astaa_deft.engine.session.recorder import event_json


def _event(old, new, detail=None) -> Mutation:
    return Mutation(testcase="tc", policy="p1", action="set", channel="data", consumers=("sink", "other"),
                    message_index=7, time=1.25, fields=(FieldChange("a.b[2]", old, new),), detail=detail or {})


VALUES = [
    (0.5, float("nan")),
    (1, float("-inf")),
    ("text", b"\x00\xffbytes"),
    ("\ud800lone", "ok"),
    ({"float": 1}, [1, (2, 3), {"x": None}]),
    (True, 2**80),
]


@pytest.mark.parametrize("old,new", VALUES)
def test_marshalled_event_reads_back_as_its_json_form(old, new) -> None:
    event = _event(old, new, {"skipped_fields": ({"path": "x", "reason": "r"},)})
    wire, original, delivered = read_intercept_record(intercept_record(event, b"orig", delivered=True))
    assert wire.form == EVENT_MARSHAL
    assert (original, delivered) == (b"orig", True)
    assert json.dumps(event_json(wire), default=str) == json.dumps(event.to_json(), default=str)


def test_a_value_marshal_cannot_carry_falls_back_to_the_json_form() -> None:
    event = _event(OrderedDict(a=1), object())  # a dict subclass and an arbitrary object
    wire, original, delivered = read_intercept_record(intercept_record(event, None, delivered=False))
    assert wire.form == EVENT_JSON
    assert (original, delivered) == (None, False)
    assert json.dumps(event_json(wire), default=str) == json.dumps(event.to_json(), default=str)


def test_an_event_already_in_json_form_is_kept_as_is() -> None:
    body = _event(1, 2).to_json()
    wire, _, _ = read_intercept_record(intercept_record(body, None, delivered=True))
    assert event_json(wire) == body


def test_malformed_records_and_batches_raise_value_error() -> None:
    record = intercept_record(_event(1, 2), b"o", delivered=True)
    with pytest.raises(ValueError):
        read_intercept_record(record[:8])
    with pytest.raises(ValueError):
        read_intercept_record(b"\x09" + record[1:])  # unknown event form
    batch = pack_deliveries([(1, b"payload", b"o", True, _event(1, 2)), (2, b"p2", None, True, None)])
    assert [row[:4] for row in unpack_deliveries(batch)] == [(1, b"payload", b"o", True), (2, b"p2", None, True)]
    for damaged in (batch[:-1], b"", b"\x00garbage"):
        with pytest.raises(ValueError):
            unpack_deliveries(damaged)
    import marshal

    for rows in ([(1, b"p")], [(1, "text", None, True, None)], [(1, b"p", None, True, (1, 2))], {"not": "a list"},
                 [(1, b"p", None, True, b"{not json")]):
        with pytest.raises(ValueError):
            unpack_deliveries(marshal.dumps(rows))


def test_an_event_whose_json_is_not_an_object_is_malformed() -> None:
    """A JSON event is a mutation's JSON object: a list or a number there is a damaged record, not an event."""
    import marshal
    import struct

    for body in (b"[1, 2]", b"3", b'"text"'):
        record = struct.pack("<BI??", EVENT_JSON, len(body), True, False) + body
        with pytest.raises(ValueError, match="not a JSON object"):
            read_intercept_record(record)
        with pytest.raises(ValueError, match="not an object"):
            unpack_deliveries(marshal.dumps([(1, b"p", None, True, body)]))


@pytest.mark.parametrize("old,new", VALUES)
def test_a_batch_of_deliveries_carries_each_event_as_its_json_form(old, new) -> None:
    events = [_event(old, new, {"skipped_fields": ({"path": "x", "reason": "r"},)}),
              _event(OrderedDict(a=1), object()),  # marshal refuses these: that event alone goes as JSON
              None]
    rows = [(i, b"p%d" % i, None if e is None else b"orig", i != 1, e) for i, e in enumerate(events)]
    back = unpack_deliveries(pack_deliveries(rows))
    assert [r[:4] for r in back] == [r[:4] for r in rows]
    assert [None if r[4] is None else r[4].form for r in back] == [EVENT_MARSHAL, EVENT_JSON, None]
    for (_, _, _, _, wire), event in zip(back[:2], events[:2], strict=True):
        assert json.dumps(event_json(wire), default=str) == json.dumps(event.to_json(), default=str)


def test_built_instances_are_the_dataclasses_own() -> None:
    """``built`` (the engine's per-message constructor) gives what ``__init__`` gives, every field included."""
    from dataclasses import FrozenInstanceError, fields

    from astaa_deft.engine.intercept.actions.base import Delivery, built

    for cls, values in ((Mutation, _event(1, 2).__dict__),
                        (FieldChange, {"path": "a", "old": 1, "new": float("inf")}),
                        (Delivery, {"consumers": ("s",), "payload": b"p", "at": 1.0, "original": b"o", "event": None})):
        assert set(values) == {f.name for f in fields(cls)}, f"{cls.__name__} gained a field: pass it to built()"
        fast, slow = built(cls, **values), cls(**values)
        assert fast == slow and repr(fast) == repr(slow)
        with pytest.raises(FrozenInstanceError):
            fast.__setattr__(fields(cls)[0].name, None)


def test_the_recorders_event_text_reads_back_as_the_stdlibs():
    # The recorder writes an event's JSON with orjson where it can (a fifth of the cost): the same
    # object back, dates and dataclasses as the stdlib's default=str writes them, big integers exact.
    import dataclasses
    import datetime
    import enum
    import json

    from astaa_deft.engine.session.recorder import _EVENT_ENCODER, _event_text

    class Gear(enum.IntEnum):
        DRIVE = 3

    @dataclasses.dataclass
    class Point:
        x: int

    for body in ({"fields": [{"path": "v", "old": 1.5, "new": {"float": "nan"}}], "consumers": ["é"]},
                 {"stamp": datetime.datetime(2020, 1, 1)}, {"point": Point(1)}, {"gear": Gear.DRIVE},
                 {"seq": 2**70}, {"small": 1e-05}, {"sequence": None, "flag": True}):
        assert json.loads(_event_text(body)) == json.loads(_EVENT_ENCODER.encode(body)), body
