"""An extraction's partial results on disk: the suite of the outputs decided so far, and how to go on.

While an extraction runs, ``DIR`` holds the module tests of the outputs
decided so far (rewritten every few seconds, each file replaced whole: a
kill leaves a suite that runs) and ``DIR/extraction.json``, every decided
output's frame (its inputs by index in the log) and outcome, with what
names the extraction (log, spec, module, threshold). ``extract --resume``
reads it back (:func:`read_state`) and steps those frames once each instead
of searching them again. A finished extraction removes it.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from collections.abc import Mapping
from dataclasses import asdict
from pathlib import Path
from typing import Any

from astaa_deft.model.errors import InputError, Problem
from astaa_deft.model.sut import Spec
from astaa_deft.engine.spec.replay_section import ReplayModule
from astaa_deft.analysis.deft.export import MANIFEST, export_suite
from astaa_deft.analysis.deft.extract import Decided, ExtractedFrame
from astaa_deft.analysis.deft.validator import Comparison

STATE = "extraction.json"
STATE_VERSION = 1
WRITE_EVERY_S = 2.0  # the partial suite is rewritten at most this often (and once more at the end)
_PARTIAL = ".partial"


def identity(log_path: Path, spec: Spec, entry: ReplayModule) -> dict[str, Any]:
    """What an extraction must share with the one it resumes: the same log, spec, module and threshold."""
    return {"log": str(log_path.resolve()), "log_bytes": log_path.stat().st_size, "spec": spec.name,
            "module": entry.module, "threshold": entry.threshold}


def _decided_json(outcome: Decided) -> dict[str, Any]:
    frame = outcome.frame
    if frame is None or outcome.choice is None:
        return {"output": outcome.output_index, "skipped": outcome.skipped or "skipped"}
    return {"output": outcome.output_index, "choice": dict(outcome.choice), "trigger_time_ns": frame.trigger_time,
            "frame_time_ns": frame.frame_time, "comparison": asdict(frame.comparison), "accepted": frame.accepted,
            "candidates_tried": frame.candidates_tried, "exact": frame.exact}


def _decided_of(item: Mapping[str, Any]) -> Decided:
    if "skipped" in item:
        return Decided(int(item["output"]), None, None, str(item["skipped"]))
    frame = ExtractedFrame(index=0, output=None, trigger_time=int(item["trigger_time_ns"]),
                           frame_time=int(item["frame_time_ns"]), inputs={},
                           comparison=Comparison(**item["comparison"]), accepted=bool(item["accepted"]),
                           candidates_tried=int(item["candidates_tried"]), exact=bool(item["exact"]))
    return Decided(int(item["output"]), frame, {str(k): int(v) for k, v in item["choice"].items()})


def read_state(out_dir: Path, expected: Mapping[str, Any]) -> list[Decided]:
    """The outputs an interrupted extraction into ``out_dir`` decided, in order (InputError if there is
    none, or it was of another log, spec, module or threshold)."""
    path = out_dir / STATE
    fix = f"drop --resume to extract afresh into {out_dir}"
    if not path.is_file():
        raise InputError(Problem(str(path), None, None, "no interrupted extraction to resume here", fix))
    try:
        state = json.loads(path.read_text())
        decided = [_decided_of(item) for item in state["decided"]]
        was = state["extraction"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise InputError(Problem(str(path), None, None, f"unreadable ({exc})", fix)) from None
    for key, value in expected.items():
        if was.get(key) != value:
            raise InputError(Problem(str(path), None, None, f"it was an extraction with {key} {was.get(key)!r}, "
                                     f"not {value!r}", f"resume with the same log, spec, --module and "
                                     f"--threshold, or {fix}"))
    if [d.output_index for d in decided] != list(range(len(decided))):
        raise InputError(Problem(str(path), None, None, "its outputs are not in order from the first", fix))
    return decided


class Checkpoint:
    """Writes the partial suite and the state as outputs are decided (``add``); ``write`` forces it."""

    def __init__(self, out_dir: Path, spec: Spec, params: Mapping[str, str], entry: ReplayModule,
                 extraction: Mapping[str, Any]) -> None:
        self.out_dir = out_dir
        self.spec = spec
        self.params = params
        self.entry = entry
        self.extraction = dict(extraction)
        self.decided: list[Decided] = []
        self.total = 0
        self._written_at = time.monotonic()

    def add(self, outcome: Decided, total: int) -> None:
        self.decided.append(outcome)
        self.total = total
        if time.monotonic() - self._written_at >= WRITE_EVERY_S:
            self.write()

    def accepted(self) -> list[ExtractedFrame]:
        return [d.frame for d in self.decided if d.frame is not None and d.frame.accepted]

    def kept(self) -> list[ExtractedFrame]:
        """Every frame stepped so far, accepted or not (the suite steps them all for their state)."""
        return [f for d in self.decided if d.frame is not None for f in (*d.before, d.frame)]

    def write(self) -> None:
        """The suite of the frames so far (tests of the accepted ones) and the state, each file replaced whole."""
        self._written_at = time.monotonic()
        self.out_dir.mkdir(parents=True, exist_ok=True)
        staging = self.out_dir / _PARTIAL
        shutil.rmtree(staging, ignore_errors=True)
        manifest = export_suite(self.kept(), self.spec, self.params, staging, entry=self.entry)
        for path in sorted(staging.iterdir(), key=lambda p: p.name == MANIFEST):  # the manifest last
            os.replace(path, self.out_dir / path.name)
        manifest.parent.rmdir()
        state = {"version": STATE_VERSION, "extraction": self.extraction, "outputs": self.total,
                 "decided": [_decided_json(d) for d in self.decided]}
        temporary = self.out_dir / (STATE + ".tmp")
        temporary.write_text(json.dumps(state) + "\n")
        os.replace(temporary, self.out_dir / STATE)

    def finished(self) -> None:
        """The extraction is complete: nothing to resume."""
        (self.out_dir / STATE).unlink(missing_ok=True)
