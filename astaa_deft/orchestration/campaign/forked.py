"""A case's recorder forked from its warm worker: no interpreter start, no imports, the spec parsed once.

A warm worker (worker.py ``--warm``) or a case forked by the template has
imported everything a recorder needs and parsed the spec before its payload
comes. Forked from it while it is still one thread and has no Zenoh session,
the recorder starts with all of that done (figures: docs/performance.md,
"pipes"). It is a real child process all the same (its own session and
process group, stopped with its parent,
:func:`astaa_deft.engine.bus.process_launch.fork_child`), driven exactly as a
recorder started with ``--warm`` (its ARGS line, then the spec's text on
stdin), through the same calls as a ``subprocess.Popen`` (poll, wait, its
pipes).
"""

from __future__ import annotations

from astaa_deft.engine.bus.process_launch import ForkedChild, fork_child
from astaa_deft.engine.session import recorder
from astaa_deft.engine.spec.loader import load_spec_text
from astaa_deft.model.sut import Spec


def fork_recorder(spec_text: str, spec_name: str, parsed: Spec | None = None) -> ForkedChild:
    """A warm recorder (see ``session/recorder.py``) forked from this process.

    ``parsed``: ``spec_text`` parsed already, as ``load_spec_text(spec_text,
    name=spec_name)`` does. Raises ``UnsafeFork`` unless this process runs
    one thread (another may hold a lock — Zenoh's runtime, logging's — the
    child would need).
    """
    # Parsed before the fork: the child finds it in memory, as --warm would have parsed it.
    spec = parsed if parsed is not None else load_spec_text(spec_text, name=spec_name)
    known: dict[tuple[str, str], object] = {(spec_text, spec_name): spec}
    return fork_child(lambda: recorder.await_arguments(known), what="a case's recorder")
