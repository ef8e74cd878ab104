"""The spec a campaign's journal names, and the refusal to run it unless the user vouches for it.

A journal names the spec its campaign ran (``meta.spec``: a path). A campaign
folder travels, so that path is data: a command that would run what it names
(``verify``, ``export``'s check, ``fuzz --resume``) takes the user's
``--spec FILE``, or the journal's spec only with ``--trust-journal-spec`` —
without either it refuses, listing what that spec would run (module commands,
replay factories), as ``minimise`` does for the spec a log stores.
"""

from __future__ import annotations

from pathlib import Path

from astaa_deft.engine.spec.executes import untrusted_spec_refusal, what_spec_runs
from astaa_deft.engine.spec.loader import load_spec
from astaa_deft.model.errors import InputError, Problem
from astaa_deft.model.sut import Spec

TRUST_JOURNAL_SPEC = "--trust-journal-spec"


def journal_spec(journal: Path, named: str | None, *, trusted: bool, command: str, why: str) -> tuple[Path, Spec]:
    """The spec the journal at ``journal`` names (``named``), loaded; InputError when it names none, or — unless
    ``trusted`` — when it would run anything (the refusal lists what, and the two ways on)."""
    if named is None:
        raise InputError(Problem(str(journal), None, None, "the journal names no spec",
                                 "give the stack's spec with --spec sut.yaml"))
    spec = load_spec(Path(named))
    if not trusted and what_spec_runs(spec):
        raise untrusted_spec_refusal(spec, str(journal), command=command, why=why, flag=TRUST_JOURNAL_SPEC,
                                     holder="journal", stored_as=named[:200])
    return Path(named), spec
