"""What the campaign hands a pool for one case, and the messages on the channel to the case's process.

:class:`CasePayload` is the case's JSON form on the way to a worker (the
keys ``worker.execute`` reads) and back from it (``from_json``, in the
worker's process). A test case is an object everywhere in the campaign;
it becomes text only here and in the journal, through one pair of
functions (:func:`testcase_text`, :func:`read_testcase`). A payload read
back keeps its case's text until the worker checks it against its own spec
and dictionaries (:meth:`CasePayload.testcase`). :class:`CaseMessage` (the payload, to the case process)
and :class:`OutcomeMessage` (its outcome, back) are the two messages on
that channel, framed by :mod:`astaa_deft.io.pipe_messages`. :class:`CasePool`
is the interface the campaign drives (``executors.LocalPool`` and
``executors.DaskPool`` have it).
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import ClassVar, Protocol

from astaa_deft.engine.intercept.dictionary import Dictionary
from astaa_deft.engine.intercept.testcase import TestCase, parse_testcase
from astaa_deft.model.json import JsonObject, JsonValue
from astaa_deft.model.sut import Spec
from astaa_deft.orchestration.journal.model import CaseKind, CaseOutcome, PlannedCase, testcase_text


def read_testcase(text: str | None, name: str, spec: Spec | None = None,
                  dictionary: Dictionary | None = None) -> TestCase | None:
    """The test case :func:`testcase_text` wrote (None for a clean run), checked against ``spec`` and
    ``dictionary`` when given (InputError naming ``name`` when it does not fit them)."""
    return parse_testcase(text.encode(), name, spec, dictionary) if text else None


def case_json(case: PlannedCase, text: str | None = None) -> JsonObject:
    """A planned case's JSON form (its test case as text: ``text`` when it is at hand already)."""
    return {"case_id": case.case_id, "kind": case.kind.value, "number": case.number, "seed": case.seed,
            "params": dict(case.params), "testcase_xml": text if text is not None else testcase_text(case.testcase),
            "strategy": case.strategy, "parent": case.parent}


def _case_of(body: JsonObject) -> tuple[PlannedCase, str | None]:
    """The case :func:`case_json` wrote, without its test case, and that test case's text (KeyError, ValueError
    or TypeError for another shape: a bug, not input)."""
    params, text, parent = body["params"], body["testcase_xml"], body["parent"]
    if not isinstance(params, dict) or not isinstance(text, (str, type(None))):
        raise ValueError(f"a planned case, not {body!r}")
    case = PlannedCase(case_id=str(body["case_id"]), kind=CaseKind(body["kind"]), number=int(_number(body["number"])),
                       seed=int(_number(body["seed"])), params={str(k): str(v) for k, v in params.items()},
                       testcase=None, strategy=str(body["strategy"]), parent=None if parent is None else str(parent))
    return case, text


def _strings(value: JsonValue) -> tuple[str, ...]:
    if not isinstance(value, list):
        raise ValueError(f"a list of strings, not {value!r}")
    return tuple(str(item) for item in value)


def _number(value: JsonValue) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise ValueError(f"a number, not {value!r}")
    return float(value)


def _delays(value: JsonValue) -> dict[str, float]:
    if not isinstance(value, dict):
        raise ValueError(f"a module -> seconds object, not {value!r}")
    return {str(module): _number(seconds) for module, seconds in value.items()}


@dataclass(frozen=True, kw_only=True)
class CasePayload:
    """Everything a worker needs to run ``case``, nothing it must look up (paths absolute)."""

    spec: str  # the spec file
    case: PlannedCase
    run_dir: str  # the case's own folder (its log, its modules' output)
    horizon: float  # seconds the run may last at most
    dictionaries: tuple[str, ...]  # dictionary files beside the bundled one
    settle: float | None  # a mutated run ends this long after its last mutation could act (None: never)
    known: tuple[str, ...]  # known baseline findings: a mutated run does not end at these
    # An ending module -> the seconds its exit may come after its last message, learned from the baseline
    shutdown_delays: dict[str, float] = field(default_factory=dict)
    # Read back (from_json): the case's test case as text, checked by testcase() against the worker's spec.
    received_text: str | None = field(default=None, compare=False)

    def testcase(self, spec: Spec, dictionary: Dictionary) -> TestCase | None:
        """The case's test case, checked against ``spec`` and ``dictionary`` when the payload was read back
        (InputError when it does not fit them); None for a clean run."""
        if self.received_text is None:
            return self.case.testcase
        return read_testcase(self.received_text, self.case.case_id, spec, dictionary)

    def to_json(self) -> JsonObject:
        """The payload's JSON form (what the pools pass on to the workers)."""
        return {"spec": self.spec, "case": case_json(self.case, self.received_text), "run_dir": self.run_dir,
                "horizon": self.horizon, "dictionaries": [path for path in self.dictionaries],
                "settle": self.settle, "known": [name for name in self.known],
                "shutdown_delays": dict(self.shutdown_delays)}

    @classmethod
    def from_json(cls, data: JsonObject) -> CasePayload:
        """The payload :meth:`to_json` wrote; ``dictionaries``, ``settle``, ``known`` and ``shutdown_delays`` may
        be left out.

        Raises ``KeyError``, ``ValueError`` or ``TypeError`` for a form it did not write.
        """
        case, settle = data["case"], data.get("settle")
        if not isinstance(case, dict):
            raise ValueError(f"a case is an object, not {case!r}")
        planned, text = _case_of(case)
        return cls(spec=str(data["spec"]), case=planned, run_dir=str(data["run_dir"]),
                   horizon=_number(data["horizon"]), dictionaries=_strings(data.get("dictionaries", [])),
                   settle=None if settle is None else _number(settle), known=_strings(data.get("known", [])),
                   shutdown_delays=_delays(data.get("shutdown_delays", {})), received_text=text)


@dataclass(frozen=True)
class CaseMessage:
    """To a case process: the case to run."""

    TAG: ClassVar[str] = "case"
    payload: CasePayload

    def to_json(self) -> JsonObject:
        return self.payload.to_json()

    @classmethod
    def from_json(cls, data: JsonObject) -> CaseMessage:
        return cls(CasePayload.from_json(data))


@dataclass(frozen=True)
class OutcomeMessage:
    """From a case process: what its run gave."""

    TAG: ClassVar[str] = "outcome"
    outcome: CaseOutcome

    def to_json(self) -> JsonObject:
        # A finding's detail may quote a module's own values: text for anything JSON has no form of.
        plain: JsonObject = json.loads(json.dumps(self.outcome.to_json(), default=str))
        return plain

    @classmethod
    def from_json(cls, data: JsonObject) -> OutcomeMessage:
        return cls(CaseOutcome.from_json(data))


class CasePool(Protocol):
    """Where cases run: submitted cases run concurrently and their outcomes come back as they finish."""

    def submit(self, case_id: str, payload: JsonObject) -> None:
        """Start the case (``payload``: :meth:`CasePayload.to_json`)."""

    def pending(self) -> int:
        """Cases submitted whose outcome has not been taken yet."""

    def done(self, timeout: float | None = None) -> Iterator[tuple[str, CaseOutcome]]:
        """(case id, outcome) of the cases that finished, waiting up to ``timeout`` seconds for the first."""

    def close(self) -> None:
        """Stop the pool's workers (cases still running are abandoned)."""
