"""A run's verdict on the CRASH scale (Kropp, Koopman & Siewiorek, FTCS 1998; the Ballista project).

From worst to best, as this tool assigns them:

* **Catastrophic** — the SUT as a whole is down: every module exited during
  the run, or the bus was lost (a ``bus_lost`` event);
* **Restart** — a module hung or restarted: it stopped talking (a deadline
  broke while its process was still alive) or its counter started over;
* **Abort** — a module exited abnormally: a non-zero code or a signal;
* **Silent** — an invariant broke while every module kept running: nothing
  in the system noticed (bound, expression, temporal, collision);
* **Hindering** — a module reported an error that misstates what happened:
  it exited with code 0 mid-run (success, for a failure), or an invariant
  marked ``crash: hindering`` broke (e.g. a status channel saying "OK"
  while its output is empty);
* **Pass** — none of the above.

The verdict is the worst class found; its summary names that class's most
severe finding (a critical collision before the clearance warning that came
first), and ``first`` is the earliest finding.
Crashes are always monitored: an abnormal exit counts even when no
``process`` invariant names the module.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any
from collections.abc import Mapping, Sequence

from astaa_deft.engine.monitor.violation import SEVERITIES, Violation

ORDER = ("Catastrophic", "Restart", "Abort", "Silent", "Hindering", "Pass")
IMPLICIT = "(module exit)"  # the name of the finding made from an exit no invariant reported


@dataclass(frozen=True)
class Verdict:
    klass: str
    first: Violation | None
    summary: str
    reasons: tuple[str, ...] = ()  # one line per finding that shaped the class

    def to_json(self) -> dict:
        return {"class": self.klass, "first": self.first.to_json() if self.first else None,
                "summary": self.summary, "reasons": list(self.reasons)}

    @classmethod
    def from_json(cls, body: Mapping[str, Any]) -> Verdict:
        first = body.get("first")
        return cls(str(body.get("class", "?")), Violation.from_json(first) if first else None,
                   str(body.get("summary", "")), tuple(body.get("reasons") or ()))


def run_verdict(violations: Sequence[Violation], exits: Sequence[Mapping], modules: Sequence[str]) -> Verdict:
    """The CRASH class of a run from its violations, its process-exit events and its module names.

    ``exits`` are ``process_exit`` event bodies (module, returncode, signal,
    time_ns, during_shutdown); a ``{"kind": "bus_lost", ...}`` event among
    them makes the run Catastrophic.
    """
    mid_run = [e for e in exits if e.get("kind", "process_exit") == "process_exit" and not e.get("during_shutdown")]
    bus_lost = [e for e in exits if e.get("kind") == "bus_lost"]
    first_exit_ns: dict[str | None, int] = {}
    for e in sorted(mid_run, key=lambda e: e.get("time_ns", 0)):
        first_exit_ns.setdefault(e.get("module"), e.get("time_ns", 0))
    findings = list(violations) + _unreported_exits(mid_run, violations)
    findings.sort(key=lambda v: v.time_ns)

    classes: dict[str, list[str]] = {c: [] for c in ORDER}
    if bus_lost:
        classes["Catastrophic"].append("the bus was lost")
    if modules and set(modules) <= set(first_exit_ns):
        classes["Catastrophic"].append("every module exited during the run")
    for v in sorted(findings, key=_most_severe_first):  # stable: in time order within a severity
        klass = v.crash
        if klass == "Restart" and v.kind == "deadline" and _exited_before(v, first_exit_ns):
            continue  # silence after a crash is the crash's consequence, not a hang
        if klass not in classes:
            klass = "Silent"
        classes[klass].append(f"{v.invariant}: {v.detail}")
    klass = next(c for c in ORDER if classes[c] or c == "Pass")
    first = findings[0] if findings else None
    return Verdict(klass, first, _summary(klass, first, findings, classes[klass]), tuple(classes[klass]))


def _most_severe_first(v: Violation) -> int:
    return -SEVERITIES.index(v.severity) if v.severity in SEVERITIES else 0


def _unreported_exits(mid_run: Sequence[Mapping], violations: Sequence[Violation]) -> list[Violation]:
    """Findings for mid-run exits that no process invariant reported."""
    reported = {(v.module, v.time_ns) for v in violations if v.kind == "process"}
    out = []
    for e in mid_run:
        module, time_ns = e.get("module"), int(e.get("time_ns", 0))
        if (module, time_ns) in reported:
            continue
        clean = e.get("returncode") == 0 and not e.get("signal")
        how = f"was killed by {e['signal']}" if e.get("signal") else f"exited with code {e.get('returncode')}"
        out.append(Violation(IMPLICIT, "process", "high", time_ns, None, None,
                             {"returncode": e.get("returncode"), "signal": e.get("signal")},
                             f"module '{module}' {how} during the run", "Hindering" if clean else "Abort", module))
    return out


def _exited_before(v: Violation, first_exit_ns: Mapping[str | None, int]) -> bool:
    return v.module in first_exit_ns and first_exit_ns[v.module] <= v.time_ns


def _summary(klass: str, first: Violation | None, findings: Sequence[Violation], reasons: Sequence[str]) -> str:
    if klass == "Pass":
        return "Pass: every invariant held and every module kept running"
    text = f"{klass}: {reasons[0]}" if reasons else klass
    if len(findings) > 1:
        text += f" ({len(findings)} findings)"
    if first is not None and reasons and not reasons[0].startswith(first.invariant + ":"):
        text += f"; first: {first.invariant}: {first.detail}"
    return text


def format_verdict(verdict: Verdict | Mapping[str, Any], start_ns: int | None = None) -> str:
    """Console lines for a verdict (a Verdict or its JSON, e.g. a 'verdict' log event)."""
    if not isinstance(verdict, Verdict):
        verdict = Verdict.from_json(verdict)
    lines = [f"verdict: {verdict.summary}"]
    if verdict.first is not None:
        v = verdict.first
        when = f" at +{(v.time_ns - start_ns) / 1e9:.3f} s" if start_ns is not None else ""
        where = f" {v.where}" if v.where else ""
        lines.append(f"first violation: {v.invariant} ({v.kind}){where}{when}: {v.detail}")
    return "\n".join(lines)
