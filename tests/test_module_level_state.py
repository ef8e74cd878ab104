"""DIR/module_level/state.json read back as input: each field typed and bounded, a damaged file one clear error
naming the file, the field and the fix (in `fuzz --status` too: exit 2, no traceback)."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from astaa_deft.analysis.deft.module_search import FindingKind, ModuleVerdict
from astaa_deft.analysis.deft.stream_faults import FaultKind, FieldReads, StreamFault
from astaa_deft.model.errors import InputError
from astaa_deft.orchestration.journal.journal import Journal
from astaa_deft.orchestration.campaign.module_level_state import (
    ModuleFinding, ModuleLevelState, read_state, state_path, write_state,
)


def _state() -> ModuleLevelState:
    fault = StreamFault(channel="state", kind=FaultKind.SET, index=7, path="v", value=math.nan, value_ref="@f.nan")
    verdict = ModuleVerdict(module="ctrl", fault=fault, kind=FindingKind.INVARIANT, invariant="finite_u",
                            detail="u = nan", frame=7, steps=9, seconds=0.01)
    reads = FieldReads(module="ctrl", read=(("state", "v"),), unread=(("state", "debug.note"),), probed_frames=4,
                       seconds=0.5, notes=("probed",))
    return ModuleLevelState(modules=("ctrl",), log="/x/clean.mcap", cases=3, core_seconds=1.5, wall_seconds=2.0,
                            failing=1, findings=(ModuleFinding(name="M001", verdict=verdict, count=1, found_after=0.4,
                                                               case_id="m-0001", tests="module_level/tests/M001",
                                                               tests_fail=True),),
                            reads=(reads,), unread=(("state", "debug.note"),), per_module={"ctrl": 3},
                            started_after=5.0, params={"seconds": "3"}, complete=True)


def test_what_the_search_wrote_reads_back_the_same(tmp_path: Path):
    state = _state()
    write_state(tmp_path, state)
    back = read_state(tmp_path)
    assert back is not None
    assert math.isnan(back.findings[0].verdict.fault.value)  # type: ignore[arg-type]
    same = lambda s: json.dumps(s.to_json(), sort_keys=True)  # noqa: E731 - NaN != NaN: compare the text
    assert same(back) == same(state)


def _tampered(tmp_path: Path, change) -> str:
    write_state(tmp_path, _state())
    data = json.loads(state_path(tmp_path).read_text())
    change(data)
    state_path(tmp_path).write_text(json.dumps(data))
    with pytest.raises(InputError) as caught:
        read_state(tmp_path)
    return str(caught.value)


@pytest.mark.parametrize("change, place, what", [
    (lambda d: d["findings"][0]["verdict"]["fault"].update(index=-3), "findings[0].verdict.fault.index", "outside"),
    (lambda d: d["findings"][0]["verdict"]["fault"].update(kind="explode"), "findings[0].verdict.fault.kind",
     "not one of"),
    (lambda d: d["findings"][0].pop("verdict"), "findings[0].verdict", "is missing"),
    (lambda d: d["findings"][0]["verdict"].update(kind=3), "findings[0].verdict.kind", "must be text"),
    (lambda d: d.update(unread=[["state"]]), "unread[0]", "pair"),
    (lambda d: d.update(cases="many"), "cases", "whole number"),
    (lambda d: d.update(core_seconds=float("inf")), "core_seconds", "not a finite number"),
    (lambda d: d["reads"][0].update(read={"state": "v"}), "reads[0].read", "must be a list"),
    (lambda d: d.update(version=9), "version", "outside"),
    (lambda d: d.update(complete="yes"), "complete", "true or false"),
])
def test_a_tampered_state_is_one_error_naming_the_file_the_field_and_the_fix(tmp_path: Path, change, place, what):
    message = _tampered(tmp_path, change)
    assert "state.json" in message and f"'{place}'" in message and what in message, message
    assert "move the module_level folder away" in message


def test_a_state_that_is_not_json_or_not_an_object_is_named(tmp_path: Path):
    path = state_path(tmp_path)
    path.parent.mkdir()
    for text, what in (("not json", "is not JSON"), ("[1, 2]", "must be an object")):
        path.write_text(text)
        with pytest.raises(InputError, match=what) as caught:
            read_state(tmp_path)
        assert "state.json" in str(caught.value)


def test_a_file_of_a_search_before_it_planned_in_steps_reads_as_complete(tmp_path: Path):
    write_state(tmp_path, _state())
    data = json.loads(state_path(tmp_path).read_text())
    del data["complete"], data["params"]
    state_path(tmp_path).write_text(json.dumps(data))
    back = read_state(tmp_path)
    assert back is not None and back.complete and back.params == {}


def test_fuzz_status_on_a_tampered_state_exits_2_without_a_traceback(tmp_path: Path):
    out = tmp_path / "campaign"
    out.mkdir()
    Journal(out).close()  # a real (empty) journal: --status reads it, then the state
    write_state(out, _state())
    data = json.loads(state_path(out).read_text())
    data["findings"][0]["verdict"]["fault"]["index"] = "seven"
    state_path(out).write_text(json.dumps(data))
    done = subprocess.run([sys.executable, "-m", "astaa_deft.cli", "fuzz", "-o", str(out), "--status"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2, done.stdout + done.stderr
    assert "Traceback" not in done.stderr
    assert "state.json" in done.stderr and "findings[0].verdict.fault.index" in done.stderr, done.stderr
