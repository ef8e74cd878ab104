"""What a spec would run on this machine, and the refusal to run it from a spec nobody vouched for.

A spec names programs: each module's command (with its working directory
and environment), and for a module that runs alone its replay factory
(imported and called inside the tool) and its replay command. A spec the
user names (``--spec FILE``) is theirs to run. The copy stored in a log is
data written by whoever recorded the log — logs are mailed, attached to bug
reports, kept from other teams — so a command that would run what it names
refuses until the user either names a spec or, having read the list this
module prints, passes ``--trust-log-spec`` (docs/minimise.md, "Logs are
data"). Pure: nothing is imported or started here.
"""

from __future__ import annotations

import shlex
from dataclasses import dataclass

from astaa_deft.model.errors import InputError, Problem
from astaa_deft.model.sut import Spec

TRUST_FLAG = "--trust-log-spec"


@dataclass(frozen=True)
class WouldRun:
    """One thing a spec would execute: who runs it, and what exactly (a command line or a factory)."""

    who: str  # "module 'planning'", "planner replay factory (imported and called in the tool)"
    what: str  # the command line as written in the spec (placeholders unfilled), or 'package.module:Name'

    def __str__(self) -> str:
        return f"{self.who}: {self.what}"


def what_spec_runs(spec: Spec) -> tuple[WouldRun, ...]:
    """Every module command (with cwd and env), replay factory and replay command ``spec`` names, in order."""
    out: list[WouldRun] = []
    for module in spec.modules:
        line = shlex.join(module.command)
        if module.cwd is not None:
            line += f" (in {module.cwd})"
        if module.env:
            line += " with " + " ".join(f"{key}={shlex.quote(value)}" for key, value in module.env.items())
        out.append(WouldRun(f"module '{module.name}'", line))
    entries = [("planner", spec.planner)] if spec.planner is not None else []
    entries += [(f"replay module '{entry.module}'", entry) for entry in spec.replay]
    for name, entry in entries:
        if entry.factory:
            out.append(WouldRun(f"{name} factory (imported and called in the tool)", entry.factory))
        if entry.command:
            out.append(WouldRun(f"{name} command", shlex.join(entry.command)))
    return tuple(out)


def untrusted_spec_refusal(spec: Spec, source: str, *, command: str, why: str, flag: str = TRUST_FLAG,
                           holder: str = "log", stored_as: str = "spec.yaml") -> InputError:
    """The InputError a ``command`` raises instead of running what the spec stored in ``source`` names.

    ``source`` is a log (the spec it stores) or a campaign journal (the spec it
    names: ``holder`` "journal", ``flag`` ``--trust-journal-spec``). ``why``:
    what the command would run it for ("module replays and whole-system
    re-runs"). The first problem says what was refused and the two ways on;
    one more problem per item of :func:`what_spec_runs`, so the user reads
    exactly what ``flag`` would let run.
    """
    head = Problem(source, None, None,
                   f"{command} would run programs named only by the spec {'stored in' if holder == 'log' else 'that'}"
                   f" this {holder}{'' if holder == 'log' else ' names'} ({why}), and a {holder} is data: nothing it "
                   f"names runs unless you say so",
                   f"pass --spec FILE (your own copy of the SUT spec), or, if you trust whoever "
                   f"{'recorded' if holder == 'log' else 'wrote'} this {holder} "
                   f"to run what is listed below on this machine, {flag}")
    items = [Problem(f"{source}:{stored_as}", None, None, f"would run {item}") for item in what_spec_runs(spec)]
    return InputError([head, *items])
