"""Each action owns what it is: flags, typed detail, how it pins itself for minimisation.

(That the schema lists exactly the registered actions is checked in test_intercept_testcase.py.)
"""

from __future__ import annotations

import ast
from pathlib import Path

from astaa_deft.engine.intercept.actions import ACTIONS
from astaa_deft.engine.intercept.actions.base import ActionConfig, FieldChange, PinnedStep
from astaa_deft.engine.intercept.actions.corrupt import Corrupt, CorruptDetail
from astaa_deft.engine.intercept.actions.delay import Delay, DelayDetail
from astaa_deft.engine.intercept.actions.duplicate import DuplicateDetail
from astaa_deft.engine.intercept.actions.interleave import Interleave
from astaa_deft.engine.intercept.actions.reorder import Reorder
from astaa_deft.engine.intercept.actions.set import Assignment, Set
from astaa_deft.analysis.minimise import mutations, restrict

PACKAGE = Path(restrict.__file__).resolve().parent.parent


def test_the_minimiser_knows_no_action_by_name():
    """restrict.py and mutations.py read the actions' flags; neither names an action nor imports one."""
    for module in (restrict, mutations):
        tree = ast.parse(Path(module.__file__).read_text())
        imported = {node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom) and node.module}
        assert not any(m.startswith("intercept.actions.") and m != "intercept.actions.base"
                       for m in (i.lstrip(".") for i in imported)), module.__name__
        strings = {node.value for node in ast.walk(tree)
                   if isinstance(node, ast.Constant) and isinstance(node.value, str)}
        assert not strings & set(ACTIONS), module.__name__
        assert not strings & {"delay_ms", "truncated_to", "flipped_bytes", "copies"}, module.__name__


def test_flags_come_from_the_action_files():
    assert sorted(mutations.EXTRA_ACTIONS) == ["duplicate", "interleave"]
    assert sorted(mutations.DEFERRING_ACTIONS) == ["delay", "reorder"]
    assert sorted(mutations.FIELDS_INSEPARABLE) == ["corrupt", "drop"]
    assert {n for n, a in ACTIONS.items() if a.carries_fields} == {"set", "interleave", "swap", "hold"}
    assert {n for n, a in ACTIONS.items() if a.pins_copies} == {"duplicate"}


def test_typed_details_round_trip_through_their_json_form():
    for record in (DelayDetail(200.0), DuplicateDetail(copy=1, copies=2),
                   CorruptDetail(flipped_bytes=(3, 7)), CorruptDetail(truncated_to=4, length=9),
                   CorruptDetail(skipped="empty payload")):
        data = record.to_json()
        assert all(v is not None for v in data.values())
        assert type(record).from_json({**data, "steps": [], "unknown": 1}) == record
    assert CorruptDetail(flipped_bytes=(3, 7)).to_json() == {"flipped_bytes": [3, 7]}
    assert DuplicateDetail(copy=1, copies=2).describe() == ["copies=2"]


def test_each_action_pins_itself_from_its_logged_step():
    change = FieldChange("speed_limit", 13.0, float("nan"))
    assert ACTIONS["set"].pinned(PinnedStep({}, (change,), None)) == Set((Assignment("speed_limit", "json:NaN"),))
    assert ACTIONS["set"].pinned(PinnedStep({}, (), None)) is None
    assert ACTIONS["delay"].pinned(PinnedStep({"delay_ms": 150.0}, (), Delay(99.0))) == Delay(150.0)
    assert ACTIONS["delay"].pinned(PinnedStep({}, (), Delay(99.0))) == Delay(99.0)
    assert ACTIONS["reorder"].pinned(PinnedStep({"released": "end of run"}, (), Reorder(250.0))) == Reorder(250.0)
    assert ACTIONS["interleave"].pinned(PinnedStep({"injection": 2}, (), Interleave(5000.0))) == Interleave(1000.0)
    truncated = ACTIONS["corrupt"].pinned(PinnedStep({"truncated_to": 4, "length": 9}, (), None))
    assert isinstance(truncated, Corrupt) and truncated.mode == "truncate" and int(9 * truncated.keep) == 4
    assert ACTIONS["corrupt"].pinned(PinnedStep({"flipped_bytes": [1, 5, 6]}, (), None)) == Corrupt("flip", bytes=3)
    assert ACTIONS["duplicate"].pin_copies(3) == ACTIONS["duplicate"](3)


def test_every_action_declares_its_detail_record_and_pins_itself():
    for name, action in ACTIONS.items():
        assert issubclass(action, ActionConfig) and action.name == name
        assert action.detail_type.from_json({}) == action.detail_type()
        assert "pinned" in vars(action), f"{name} does not say how to pin itself"
