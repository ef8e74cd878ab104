"""The module-level search's state, ``DIR/module_level/state.json``: its records, and reading them back.

The tool writes the file, but it sits on a disk anyone may edit: it is read
back as input, through :class:`~astaa_deft.io.statefile.StateReader` (each
field's type and range checked), so a damaged file is one ``InputError``
naming the file, the field (``findings[2].verdict.fault.index``) and the fix
— never a traceback, never a silently wrong value.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from astaa_deft.analysis.deft.module_search import ModuleVerdict
from astaa_deft.analysis.deft.stream_faults import FieldReads, field_pairs
from astaa_deft.io.output_place import write_atomic
from astaa_deft.io.statefile import MAX_NAME, StateReader, load_json
from astaa_deft.model.errors import InputError, Problem
from astaa_deft.model.json import JsonObject
from astaa_deft.orchestration.campaign.level_split import LevelMeasure, Split

DIR_NAME = "module_level"
STATE_FILE = "state.json"
MAX_STATE_BYTES = 64 << 20
MAX_LIST = 1_000_000  # findings, reads, fields of one state: far more than a search writes
FIX = ("move the module_level folder away (the campaign then searches at module level again), or give another"
       " campaign directory (-o)")


@dataclass(frozen=True, kw_only=True)
class ModuleFinding:
    """One bucket of the module-level search: its first fault's verdict, how many faults failed its way."""

    name: str  # "M001"
    verdict: ModuleVerdict
    count: int
    found_after: float  # s from the search's start
    case_id: str | None = None  # its live case (None: not planned, the confirmations' cap reached)
    tests: str | None = None  # its DeFT module test's folder, relative to the campaign directory
    tests_fail: bool | None = None  # the test fails on the defect, as it should (None: not checked)

    def to_json(self) -> JsonObject:
        return {"name": self.name, "verdict": self.verdict.to_json(), "count": self.count,
                "found_after": round(self.found_after, 3), "case_id": self.case_id, "tests": self.tests,
                "tests_fail": self.tests_fail}


@dataclass(frozen=True, kw_only=True)
class ModuleLevelState:
    """What the module-level search did (``state.json``)."""

    modules: tuple[str, ...] = ()  # the modules replayed
    skipped: tuple[str, ...] = ()  # why a module of the spec was not (no factory, its setup failed)
    log: str | None = None  # the clean baseline log the frames came from
    cases: int = 0  # faults replayed
    core_seconds: float = 0.0  # CPU of the workers
    wall_seconds: float = 0.0
    findings: tuple[ModuleFinding, ...] = ()
    failing: int = 0  # faults whose replay failed (all buckets)
    reads: tuple[FieldReads, ...] = ()
    unread: tuple[tuple[str, str], ...] = ()  # fields live generation leaves out
    per_module: Mapping[str, int] = field(default_factory=dict)  # faults replayed per module
    started_after: float = 0.0  # s from the campaign's first planned case to the search's start
    params: Mapping[str, str] = field(default_factory=dict)  # the clean run's params (its findings' live cases')
    complete: bool = False  # its live cases planned and module tests written (else a resume finishes them)
    split: Split | None = None  # the budget's split the first round's measurements decided (None: no --budget)

    def to_json(self) -> JsonObject:
        return {"version": 1, "modules": list(self.modules), "skipped": list(self.skipped), "log": self.log,
                "cases": self.cases, "core_seconds": round(self.core_seconds, 3),
                "wall_seconds": round(self.wall_seconds, 3), "failing": self.failing,
                "findings": [f.to_json() for f in self.findings], "reads": [r.to_json() for r in self.reads],
                "unread": [list(p) for p in self.unread], "per_module": dict(self.per_module),
                "started_after": round(self.started_after, 3), "params": dict(self.params),
                "complete": self.complete, "split": None if self.split is None else self.split.to_json()}


def state_path(out: Path) -> Path:
    return out / DIR_NAME / STATE_FILE


def write_state(out: Path, state: ModuleLevelState) -> None:
    state_path(out).parent.mkdir(parents=True, exist_ok=True)
    write_atomic(state_path(out), json.dumps(state.to_json(), indent=1) + "\n")


def read_state(out: Path) -> ModuleLevelState | None:
    """The module-level search's state in campaign directory ``out`` (None: it did not run there); InputError
    naming the file, the field and the fix when it is damaged."""
    path = state_path(out)
    if not path.is_file():
        return None
    if path.is_symlink() or path.stat().st_size > MAX_STATE_BYTES:
        raise InputError(Problem(str(path), None, None, "is a link or larger than the tool writes", FIX))
    data = load_json(path.read_bytes(), str(path), "", FIX, max_chars=MAX_STATE_BYTES)
    return read_state_value(StateReader(str(path), data, FIX))


def read_state_value(r: StateReader) -> ModuleLevelState:
    (version, modules, skipped, log, cases, core, wall, failing, findings, reads, unread, per_module, started,
     params, complete, split) = r.fields("version", "modules", "skipped", "log", "cases", "core_seconds",
                                         "wall_seconds", "failing", "findings", "reads", "unread", "per_module",
                                         "started_after", "params", "complete", "split")
    version.whole(1, 1)
    return ModuleLevelState(
        modules=tuple(_names(modules)), skipped=tuple(_texts(skipped)), log=log.text(optional=True),
        cases=cases.whole(), core_seconds=core.real(0), wall_seconds=wall.real(0), failing=failing.whole(),
        findings=tuple(findings.each(read_finding, MAX_LIST)), reads=tuple(reads.each(FieldReads.from_json, MAX_LIST)),
        unread=field_pairs(unread), per_module=per_module.map(lambda v: v.whole(), MAX_LIST),
        started_after=started.real(0),
        # written by every search since it plans its live cases in steps; a file without them was written whole
        params=params.map(lambda v: v.string()) if params.present else {},
        complete=bool(complete.flag()) if complete.present else True,
        split=None if split.value is None else read_split(split))


def read_split(r: StateReader) -> Split:
    share, seconds, module, live = r.fields("share", "seconds", "module", "live")
    return Split(share=share.real(0, 1), seconds=seconds.real(0), module=read_measure(module),
                 live=read_measure(live))


def read_measure(r: StateReader) -> LevelMeasure:
    cases, cost, findings = r.fields("cases", "cost", "findings")
    return LevelMeasure(cases=cases.whole(), cost=cost.real(0), findings=findings.whole())


def read_finding(r: StateReader) -> ModuleFinding:
    name, verdict, count, after, case_id, tests, fails = r.fields(
        "name", "verdict", "count", "found_after", "case_id", "tests", "tests_fail")
    return ModuleFinding(name=name.string(MAX_NAME), verdict=ModuleVerdict.from_json(verdict), count=count.whole(1),
                         found_after=after.real(0), case_id=case_id.text(MAX_NAME, optional=True),
                         tests=tests.text(optional=True), tests_fail=fails.flag(optional=True))


def _names(r: StateReader) -> list[str]:
    return r.each(lambda v: v.string(MAX_NAME), MAX_LIST)


def _texts(r: StateReader) -> list[str]:
    return r.each(lambda v: v.string(), MAX_LIST)


__all__ = ["DIR_NAME", "ModuleFinding", "ModuleLevelState", "read_state", "state_path", "write_state"]
