"""The one adapter between a campaign and the rest of the tool: run one case, get a typed outcome.

Today it drives :class:`astaa_deft.bus.run.BusRun` directly: a fresh run
with its own router port (the spec's endpoints with port 0 → a free port),
its own run directory and its own log, ended by the first broken invariant,
every module gone, or the time horizon. When the session layer lands this
module becomes a call of ``run_session(spec, options, stop_when=…)``; nothing
else in the campaign package touches the bus.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import replace
from pathlib import Path

from .. import fields
from ..bus.run import BusRun, RunOptions
from ..codecs import get_codec
from ..errors import InputError
from ..intercept.dictionary import Dictionary, load_dictionary
from ..intercept.engine import Interceptor
from ..intercept.testcase import TestCase
from ..log import layout
from ..monitor.kinds.bound import BoundInvariant
from ..monitor.verdict import IMPLICIT
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
    started = time.monotonic()
    bus = BusRun(isolated(spec), options)
    watch = MarginWatch(spec)
    reason = "horizon"
    try:
        with bus:
            watch.attach(bus)
            t0 = time.monotonic()
            while time.monotonic() - t0 < horizon:
                if bus.stop_requested.is_set():
                    reason = "violation"
                    break
                if bus.crashed():
                    reason = "module crashed"
                    break
                if bus.launcher is not None and not bus.alive():
                    reason = "all modules exited"
                    break
                time.sleep(POLL_SECONDS)
    except InputError as exc:
        return CaseOutcome("error", "?", "the run did not start", seconds=time.monotonic() - started,
                           error="; ".join(str(p) for p in exc.problems))
    seconds = time.monotonic() - started
    verdict = bus.verdict
    if verdict is None:  # never observed to the end: no Pass
        return CaseOutcome("error", "?", "the run was not observed to its end", seconds=seconds,
                           log_path=str(log_path), reason=reason, error="no verdict")
    findings = [Finding(str(v.get("invariant")), str(v.get("crash", "Silent")), v.get("module"),
                        v.get("channel"), str(v.get("detail", ""))) for v in bus.violations]
    for exit_ in bus.crashed():
        if not any(f.module == exit_.module for f in findings):
            findings.append(Finding(IMPLICIT, "Abort", exit_.module, None, exit_.describe()))
    mutations = bus.interception.mutations if bus.interception is not None else 0
    return CaseOutcome("done", verdict.klass, verdict.summary, findings, seconds, str(log_path), reason,
                       mutations, margins=watch.margins(bus.violations))


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
            try:
                bus.subscribe(inv.channel, lambda sample, inv=inv, codec=codec: self._seen(inv, codec, sample))
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

    def margins(self, violations: list[dict]) -> dict[str, float]:
        with self._lock:
            out = dict(self.closest)
        for v in violations:
            out[str(v.get("invariant"))] = 0.0
        return out
