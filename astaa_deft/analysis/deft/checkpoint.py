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
from dataclasses import asdict, dataclass
from pathlib import Path

from astaa_deft.io.inputfile import InputKind, read_input
from astaa_deft.io.output_place import write_atomic
from astaa_deft.io.statefile import MAX_INT, StateReader, load_json
from astaa_deft.model.errors import InputError, Problem
from astaa_deft.model.json import JsonObject, JsonValue
from astaa_deft.model.sut import Spec
from astaa_deft.engine.spec.replay_section import ReplayModule
from astaa_deft.analysis.deft.export import MANIFEST, export_suite
from astaa_deft.analysis.deft.extract import Decided, ExtractedFrame
from astaa_deft.analysis.deft.validator import Comparison

STATE = "extraction.json"
STATE_VERSION = 1
WRITE_EVERY_S = 2.0  # the partial suite is rewritten at most this often (and once more at the end)
_PARTIAL = ".partial"
STATE_FILE = InputKind("extraction state", 256 << 20, f"the {STATE} an interrupted extract left")


def identity(log_path: Path, spec: Spec, entry: ReplayModule) -> JsonObject:
    """What an extraction must share with the one it resumes: the same log, spec, module and threshold."""
    return {"log": str(log_path.resolve()), "log_bytes": log_path.stat().st_size, "spec": spec.name,
            "module": entry.module, "threshold": entry.threshold}


def _decided_json(outcome: Decided) -> JsonObject:
    frame = outcome.frame
    if frame is None or outcome.choice is None:
        return {"output": outcome.output_index, "skipped": outcome.skipped or "skipped"}
    return {"output": outcome.output_index, "choice": dict(outcome.choice), "trigger_time_ns": frame.trigger_time,
            "frame_time_ns": frame.frame_time, "comparison": _comparison_json(frame.comparison),
            "accepted": frame.accepted, "candidates_tried": frame.candidates_tried, "exact": frame.exact}


def _comparison_json(comparison: Comparison) -> JsonObject:
    """A frame's comparison as the state keeps it: its numbers (a resumed frame is judged again, so the fields
    that differed are not kept)."""
    return {key: value for key, value in asdict(comparison).items() if key not in ("fields", "fields_left_out")}


@dataclass(frozen=True)
class LogShape:
    """What a resumed state is checked against: the log's recorded outputs of the module and, per input
    channel, its messages (a choice indexes them)."""

    outputs: int
    inputs: Mapping[str, int]


MAX_SKIPPED_TEXT = 10_000  # characters of why an output was skipped
BYTES_PER_OUTPUT = 16_384  # far above what one decided output takes in the state (~300 bytes, ~1 kB skipped)


def _decided_of(item: StateReader, position: int, shape: LogShape | None) -> Decided:
    (output, skipped, choice, comparison, trigger, frame_time, accepted, tried, exact) = item.fields(
        "output", "skipped", "choice", "comparison", "trigger_time_ns", "frame_time_ns", "accepted",
        "candidates_tried", "exact")
    output.whole(position, position)  # in order from the first
    if skipped.present:
        return Decided(output_index=position, frame=None, choice=None, skipped=skipped.string(MAX_SKIPPED_TEXT))
    picks: dict[str, int] = {}
    for name, index in choice.entries(max_items=1000):
        if shape is not None and name not in shape.inputs:
            choice.fail(f"names '{name[:60]}', not an input of the module ({', '.join(sorted(shape.inputs))})")
        picks[name] = index.whole(0, (shape.inputs[name] - 1) if shape is not None else MAX_INT)
    lacking = sorted(set(shape.inputs) - set(picks)) if shape is not None else []
    if lacking or not picks:  # a decided frame holds a message of every input
        choice.fail(f"lacks the input{'s' if len(lacking) > 1 else ''} {', '.join(lacking)}" if lacking
                    else "is empty (a frame has a message of every input)")
    distance, max_error, points, how = comparison.fields("distance", "max_error", "points", "how")
    frame = ExtractedFrame(
        index=0, output=None, trigger_time=trigger.whole(), frame_time=frame_time.whole(), inputs={},
        comparison=Comparison(distance=distance.real(0.0, infinite=True), max_error=max_error.real(0.0, infinite=True),
                              points=points.whole(), how=how.string(100)),
        accepted=bool(accepted.flag()), candidates_tried=tried.whole(), exact=bool(exact.flag()))
    return Decided(output_index=position, frame=frame, choice=picks)


def read_state(out_dir: Path, expected: Mapping[str, JsonValue], shape: LogShape | None = None) -> list[Decided]:
    """The outputs an interrupted extraction into ``out_dir`` decided, in order (InputError if there is
    none, it was of another log, spec, module or threshold, or any field is not what this version writes:
    type, range, version, size — checked against the log's ``shape`` when given)."""
    path = out_dir / STATE
    fix = f"drop --resume to extract afresh into {out_dir}"
    if not path.is_file():
        raise InputError(Problem(str(path), None, None, "no interrupted extraction to resume here", fix))
    text = read_input(path, STATE_FILE)
    # What an extraction of this log can have written (a few hundred bytes an output): a larger file is
    # refused before it is parsed, in time and memory bounded by the log, not by the file.
    most_bytes = min(STATE_FILE.max_bytes or 0, (1 << 20) + BYTES_PER_OUTPUT * shape.outputs) if shape is not None \
        else STATE_FILE.max_bytes or 0
    if len(text) > most_bytes:
        raise InputError(Problem(str(path), None, None, f"is {len(text):,} bytes: an extraction of this log writes "
                                 f"at most {most_bytes:,}", fix))
    state = StateReader(str(path), load_json(text, str(path), "", fix, max_chars=most_bytes), fix)
    version, extraction, outputs, decided = state.fields("version", "extraction", "outputs", "decided")
    if version.value != STATE_VERSION:
        version.fail(f"is {str(version.value)[:40]}: this version of astaa-deft reads state version {STATE_VERSION}"
                     " only")
    for (key, value), was in zip(expected.items(), extraction.fields(*expected), strict=True):
        if was.value != value:
            raise InputError(Problem(str(path), None, None, f"it was an extraction with {key} "
                                     f"{str(was.value)[:200]!r}, not {value!r}",
                                     f"resume with the same log, spec, --module and --threshold, or {fix}"))
    most = shape.outputs if shape is not None else MAX_INT
    outputs.whole(0, MAX_INT)
    return [_decided_of(item, n, shape) for n, item in enumerate(decided.items(most))]


class Checkpoint:
    """Writes the partial suite and the state as outputs are decided (``add``); ``write`` forces it."""

    def __init__(self, out_dir: Path, spec: Spec, params: Mapping[str, str], *, entry: ReplayModule,
                 extraction: Mapping[str, JsonValue]) -> None:
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
        write_atomic(self.out_dir / STATE, json.dumps(state) + "\n")  # whole, and never through a link

    def finished(self) -> None:
        """The extraction is complete: nothing to resume."""
        (self.out_dir / STATE).unlink(missing_ok=True)
