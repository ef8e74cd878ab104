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

from collections.abc import Mapping, Sequence

from astaa_deft.model.json import JsonValue
from astaa_deft.engine.monitor.base import ReplayJudges
from astaa_deft.engine.monitor.kinds import invariant_class
from astaa_deft.engine.monitor.violation import SEVERITIES, Violation
from astaa_deft.model.records import CRASH_SCALE, ProcessExit, RunVerdict, Verdict

ORDER = CRASH_SCALE  # worst first, Pass last (the name the campaign imports)
IMPLICIT = "(module exit)"  # the name of the finding made from an exit no invariant reported
BUS_LOST = "bus_lost"  # the kind of the log event saying the bus was lost


def run_verdict(violations: Sequence[Violation], exits: Sequence[ProcessExit],
                modules: Sequence[str], *, bus_lost: bool = False) -> RunVerdict:
    """The CRASH class of a run from its violations, its process exits and its module names.

    ``exits``: the run's process exits. The bus lost (``bus_lost``) makes
    the run Catastrophic. Pure: the same inputs give the same verdict.
    """
    mid_run = [e for e in exits if not e.during_shutdown]
    first_exit_ns: dict[str | None, int] = {}
    for e in sorted(mid_run, key=lambda e: e.time_ns):
        first_exit_ns.setdefault(e.module, e.time_ns)
    findings = list(violations) + _unreported_exits(mid_run, violations)
    findings.sort(key=lambda v: v.time_ns)

    classes: dict[Verdict, list[str]] = {c: [] for c in CRASH_SCALE}
    if bus_lost:
        classes[Verdict.CATASTROPHIC].append("the bus was lost")
    if modules and set(modules) <= set(first_exit_ns):
        classes[Verdict.CATASTROPHIC].append("every module exited during the run")
    for v in sorted(findings, key=_most_severe_first):  # stable: in time order within a severity
        klass = Verdict.named(v.crash) or Verdict.SILENT  # an unknown class counts as Silent
        if klass is Verdict.RESTART and invariant_class(v.invariant_kind).replay_judges is ReplayJudges.TIMING and (
                _exited_before(v, first_exit_ns)):
            continue  # silence after a crash is the crash's consequence, not a hang
        classes[klass].append(f"{v.invariant}: {v.detail}")
    klass = next(c for c in CRASH_SCALE if classes[c] or c is Verdict.PASS)
    first = findings[0] if findings else None
    return RunVerdict(klass=klass, first=first, summary=_summary(klass, first, findings, classes[klass]),
                      reasons=tuple(classes[klass]))


def _most_severe_first(v: Violation) -> int:
    return -SEVERITIES.index(v.severity) if v.severity in SEVERITIES else 0


def _unreported_exits(mid_run: Sequence[ProcessExit], violations: Sequence[Violation]) -> list[Violation]:
    """Findings for mid-run exits that no process invariant reported."""
    reported = {(v.module, v.time_ns) for v in violations
                if invariant_class(v.invariant_kind).replay_judges is ReplayJudges.PROCESS}
    out = []
    for e in mid_run:
        if (e.module, e.time_ns) in reported:
            continue
        clean = e.returncode == 0 and not e.signal
        out.append(Violation(invariant=IMPLICIT, invariant_kind="process", severity="high", time_ns=e.time_ns,
                             channel=None, seq=None, message={"returncode": e.returncode, "signal": e.signal},
                             detail=f"{e.as_finding()} during the run",
                             crash=Verdict.HINDERING if clean else Verdict.ABORT, module=e.module))
    return out


def _exited_before(v: Violation, first_exit_ns: Mapping[str | None, int]) -> bool:
    return v.module in first_exit_ns and first_exit_ns[v.module] <= v.time_ns


def _summary(klass: Verdict, first: Violation | None, findings: Sequence[Violation], reasons: Sequence[str]) -> str:
    if klass is Verdict.PASS:
        return "Pass: every invariant held and every module kept running"
    text = f"{klass}: {reasons[0]}" if reasons else klass
    if len(findings) > 1:
        text += f" ({len(findings)} findings)"
    if first is not None and reasons and not reasons[0].startswith(first.invariant + ":"):
        text += f"; first: {first.invariant}: {first.detail}"
    return text


def format_verdict(verdict: RunVerdict | Mapping[str, JsonValue], start_ns: int | None = None) -> str:
    """Console lines for a verdict (a RunVerdict or its JSON, e.g. a 'verdict' log event)."""
    if not isinstance(verdict, RunVerdict):
        verdict = RunVerdict.from_json(verdict)
    lines = [f"verdict: {verdict.summary}"]
    if verdict.first is not None:
        v = verdict.first
        when = f" at +{(v.time_ns - start_ns) / 1e9:.3f} s" if start_ns is not None else ""
        where = f" {v.where}" if v.where else ""
        lines.append(f"first violation: {v.invariant} ({v.invariant_kind}){where}{when}: {v.detail}")
    return "\n".join(lines)
