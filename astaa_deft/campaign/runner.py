"""The one adapter between a campaign and the rest of the tool: run one case, get a typed outcome.

One call of :func:`astaa_deft.session.run_session`: a fresh run with its
own router port (the spec's endpoints with port 0 → a free port), its own
run directory and its own log, ended by the spec's own ``run:`` section (a
module's exit, a channel's "done", its time limit — applied by the session
for every caller, no SUT-specific logic here), the first broken invariant,
a crashed module (as its on_crash says), every module gone, or the campaign's time horizon.
Nothing else in the campaign package touches the bus.
"""

from __future__ import annotations

import math
import threading
from dataclasses import replace
from pathlib import Path

import zenoh

from .. import fields
from ..codecs import get_codec
from ..codecs.base import Codec
from ..errors import InputError
from ..intercept.dictionary import Dictionary, load_dictionary
from ..intercept.engine import Interceptor
from ..intercept.testcase import TestCase
from ..log import layout
from ..log.records import ViolationRecord
from ..monitor.kinds.bound import BoundInvariant
from ..monitor.verdict import IMPLICIT
from ..session import BusRun, RunOptions, run_session
from ..spec.model import Spec
from .model import CaseOutcome, Finding

POLL_SECONDS = 0.05
LOG_NAME = "run.mcap"
POLICY_NAME = "policy.xml"


def isolated(spec: Spec) -> Spec:
    """The spec with every listening endpoint on a free port: concurrent runs never share a router."""
    endpoints = []
    for endpoint in spec.zenoh.endpoints:
        proto, _, addr = endpoint.partition("/")
        host, _, _port = addr.rpartition(":")
        endpoints.append(f"{proto}/{host}:0")
    return replace(spec, zenoh=replace(spec.zenoh, endpoints=tuple(endpoints)))


def run_case(spec: Spec, testcase: TestCase | None, params: dict[str, str], run_dir: Path, horizon: float,
             dictionary: Dictionary | None = None) -> CaseOutcome:
    """One fresh run of the SUT with ``testcase`` (None: clean) for at most ``horizon`` seconds."""
    run_dir.mkdir(parents=True, exist_ok=True)
    log_path = run_dir / LOG_NAME
    attachments = {}
    interceptor = None
    if testcase is not None and testcase.policies:
        policy_file = run_dir / POLICY_NAME
        policy_file.write_bytes(testcase.to_xml())
        attachments[layout.POLICY_ATTACHMENT] = policy_file
        interceptor = Interceptor(testcase, spec, dictionary or load_dictionary())
    options = RunOptions(mode="star", launch=True, record=log_path, params=dict(params),
                         command_line=["astaa-deft", "fuzz"], run_dir=run_dir / "modules",
                         interceptor=interceptor, stop_on_violation=True, attachments=attachments)
    options.time_limit = horizon
    watch = MarginWatch(spec)
    try:
        # A crash ends the run as the spec's on_crash says (run_session applies it), as for `proxy`.
        result = run_session(isolated(spec), options, on_start=watch.attach)
    except InputError as exc:
        return CaseOutcome("error", "?", "the run did not start", error="; ".join(str(p) for p in exc.problems))
    reason = {"time limit": "horizon", "violation (--stop-on-violation)": "violation"}.get(result.end_reason,
                                                                                            result.end_reason)
    if result.verdict is None or not result.observed or not result.complete:  # not fully observed: no Pass
        return CaseOutcome("error", "?", "the run was not observed to its end", seconds=result.seconds,
                           log_path=str(log_path), reason=reason,
                           error="no verdict" if result.verdict is None else "the log was not finished")
    findings = [Finding(v.invariant, v.crash, v.module, v.channel, v.detail) for v in result.violations]
    for exit_ in result.crashes:
        if not any(f.module == exit_.module for f in findings):
            findings.append(Finding(IMPLICIT, "Abort", exit_.module, None, exit_.describe()))
    return CaseOutcome("done", result.verdict.klass, result.verdict.summary, findings, result.seconds,
                       str(log_path), reason, result.mutations, margins=watch.margins(result.violations))


class MarginWatch:
    """How close each bound invariant came to breaking: the smallest distance of its field to min/max.

    Normalised by the bound's range when it has both ends (so invariants
    compare), 0 when a value is non-finite or out of bounds; every invariant
    that broke gets 0. The guided strategy steers by these numbers.
    """

    def __init__(self, spec: Spec):
        self.bounds = [inv for inv in getattr(spec, "invariants", ()) if isinstance(inv, BoundInvariant)
                       and (inv.minimum is not None or inv.maximum is not None)]
        self.spec = spec
        self.closest: dict[str, float] = {}
        self._lock = threading.Lock()

    def attach(self, bus: BusRun) -> None:
        for inv in self.bounds:
            codec = get_codec(self.spec.channel(inv.channel).encoding)
            def seen(sample: zenoh.Sample, inv: BoundInvariant = inv, codec: Codec = codec) -> None:
                self._seen(inv, codec, sample)

            try:
                bus.subscribe(inv.channel, seen)
            except KeyError:  # not observable in this mode
                continue

    def _seen(self, inv: BoundInvariant, codec, sample) -> None:
        try:
            values = [v for _, v in fields.get(codec.decode(sample.payload.to_bytes()), inv.field)]
        except Exception:  # noqa: BLE001 - a payload the monitors will report; not ours to judge
            return
        span = (inv.maximum - inv.minimum) if inv.minimum is not None and inv.maximum is not None else 1.0
        for value in values:
            if not isinstance(value, (int, float)) or isinstance(value, bool):
                continue
            if not math.isfinite(value):
                margin = 0.0
            else:
                ends = [value - inv.minimum if inv.minimum is not None else math.inf,
                        inv.maximum - value if inv.maximum is not None else math.inf]
                margin = max(0.0, min(ends)) / (span or 1.0)
            with self._lock:
                if margin < self.closest.get(inv.name, math.inf):
                    self.closest[inv.name] = margin

    def margins(self, violations: tuple[ViolationRecord, ...]) -> dict[str, float]:
        with self._lock:
            out = dict(self.closest)
        for v in violations:
            out[v.invariant] = 0.0
        return out
