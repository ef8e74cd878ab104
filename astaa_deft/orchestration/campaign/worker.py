"""One case, executed where it runs: a child process of the local pool, or a Dask worker.

The payload is a :class:`~.payload.CasePayload` (spec path, planned case,
run directory, horizon, extra dictionaries), the result a
:class:`~.model.CaseOutcome`: the same function serves both.
Run as ``python -m astaa_deft.orchestration.campaign.worker [--warm SPEC [DICTIONARY …]]``
it reads the payload as a message on stdin and writes the outcome as a
message on stdout (:mod:`astaa_deft.io.pipe_messages` frames).
``--warm``: import everything and load that spec and those dictionaries
*before* waiting for the payload — the local pool starts each case's process
while the previous case still runs, so a case does not wait for Python's
imports and the spec (each case still gets a process of its own). It also
starts the case's recorder ahead, forked from itself (:mod:`.forked`: no
second interpreter start, imports or spec parse). Figures:
docs/performance.md, "pipes".
"""

from __future__ import annotations

import os
import sys
import threading
from dataclasses import dataclass
from pathlib import Path

from astaa_deft.engine.bus.processes import ChildProcess
from astaa_deft.engine.intercept.dictionary.model import Dictionary
from astaa_deft.io import pipe_messages
from astaa_deft.io.pipe_messages import FrameError, fd_reader
from astaa_deft.model.errors import InputError
from astaa_deft.model.sut import Spec
from astaa_deft.io.inputfile import SPEC, read_input
from astaa_deft.engine.intercept.dictionary import load_dictionary
from astaa_deft.engine.session.bus_run import release_warm_recorder, warm_recorder
from astaa_deft.engine.spec.loader import load_spec
from astaa_deft.orchestration.campaign.forked import fork_recorder
from astaa_deft.orchestration.journal.model import CaseOutcome
from astaa_deft.orchestration.campaign.payload import CaseMessage, CasePayload, OutcomeMessage
from astaa_deft.orchestration.campaign.runner import CaseLimits, run_case


@dataclass(frozen=True)
class Preloaded:
    """A spec and dictionaries loaded before the payload came (a warm worker, the case template)."""

    spec_path: str
    dictionary_paths: tuple[str, ...]
    spec: Spec
    dictionary: Dictionary

    @classmethod
    def load(cls, spec_path: str, dictionary_paths: tuple[str, ...]) -> Preloaded:
        """Load them now; raises InputError for a bad spec or dictionary."""
        return cls(spec_path, dictionary_paths, load_spec(Path(spec_path)),
                   load_dictionary([Path(p) for p in dictionary_paths]))


@dataclass(frozen=True)
class ParsedSpec:
    """A spec file's text and that text parsed as the recorder parses it (a template's, for its cases' recorders)."""

    text: str
    spec: Spec


def execute(payload: CasePayload, preloaded: Preloaded | None = None,
            warm_recorder: ChildProcess | None = None) -> CaseOutcome:
    """Run the payload's case; its outcome (status "error" for a bad spec, dictionary or test case).

    ``preloaded``: used when it is the payload's spec and dictionaries (else
    they are loaded here); ``warm_recorder``: the run's recorder, started ahead.
    """
    case = payload.case
    try:
        if preloaded is not None and (preloaded.spec_path, preloaded.dictionary_paths) == (payload.spec,
                                                                                         payload.dictionaries):
            spec, dictionary = preloaded.spec, preloaded.dictionary
        else:
            spec = load_spec(Path(payload.spec))
            dictionary = load_dictionary([Path(p) for p in payload.dictionaries])
        testcase = payload.testcase(spec, dictionary)
    except InputError as exc:
        return CaseOutcome(status="error", verdict="?", summary="bad input", error="; ".join(map(str, exc.problems)))
    limits = CaseLimits(horizon=payload.horizon, settle=payload.settle, known=frozenset(payload.known),
                        shutdown_delays=payload.shutdown_delays)
    return run_case(spec, testcase, case.params, Path(payload.run_dir), limits=limits, dictionary=dictionary,
                    warm_recorder=warm_recorder)


def stop_worker_profiler() -> bool:
    """Stop the Dask worker's stack sampling on this worker; True once it is off (False: not on a worker).

    A Dask worker samples every thread's stack (``sys._current_frames``) from
    its event loop every 10 ms. On CPython 3.11 that deadlocks, now and then,
    with a thread being started while a gc callback runs (seen on a
    LocalCluster: a case's ``Thread.start()`` waited forever, the worker's
    event loop inside distributed's gc callback within ``_current_frames``).
    A case starts dozens of threads, so a campaign meets it; it never looks
    at Dask's profiles. Stopped from the event loop's own thread (tornado's
    callbacks are not thread-safe), waited for before the case starts.
    """
    try:
        from distributed import get_worker

        worker = get_worker()
    except (ImportError, ValueError):  # not inside a Dask task
        return False
    sampling = [pc for pc in (worker.periodic_callbacks.get(name) for name in ("profile", "profile-cycle"))
                if pc is not None and pc.is_running()]
    if not sampling:
        return True
    stopped = threading.Event()

    def stop() -> None:
        for pc in sampling:
            pc.stop()
        stopped.set()

    worker.loop.add_callback(stop)
    return stopped.wait(10.0)


@dataclass(frozen=True)
class RemoteResult:
    """A case run on a Dask worker: its outcome, and its log's bytes (None: the run wrote none)."""

    outcome: CaseOutcome
    log: bytes | None


def execute_remote(payload: CasePayload) -> RemoteResult:
    """On a Dask worker: run in a local temp dir, send the log back with the outcome."""
    import dataclasses
    import tempfile

    stop_worker_profiler()
    with tempfile.TemporaryDirectory(prefix="astaa-deft-case-") as tmp:
        outcome = execute(dataclasses.replace(payload, run_dir=tmp))
        log = Path(tmp) / "run.mcap"
        return RemoteResult(outcome, log.read_bytes() if log.is_file() else None)


def recorder_ahead(spec_path: Path, parsed: ParsedSpec | None = None) -> ChildProcess | None:
    """This case's recorder, started now: forked from this process (still one thread, no Zenoh session),
    else a warm recorder process of its own, else none (the run starts one itself).
    ``parsed``: the spec file's text and its parse, from a template process."""
    try:
        if parsed is not None:
            return fork_recorder(parsed.text, spec_path.name, parsed.spec)
        return fork_recorder(read_input(spec_path, SPEC).decode("utf-8"), spec_path.name)
    except Exception:  # noqa: BLE001 - an unreadable spec is the case's error to report; no fork: a process
        try:
            return warm_recorder([spec_path])
        except OSError:
            return None


def receive_case(read: pipe_messages.Reader, *, source: str) -> CasePayload:
    """The case's payload, the one message on its channel ``read``.

    Raises :class:`FrameError` naming ``source`` when the channel ended before
    it, or held anything else.
    """
    message = pipe_messages.receive(read, (CaseMessage,), source=source)
    if message is None:
        raise FrameError(f"{source}: the channel ended before the case's payload came")
    return message.payload


def run_received(payload: CasePayload, preloaded: Preloaded | None, recorder: ChildProcess | None) -> OutcomeMessage:
    """:func:`execute`, the warm ``recorder`` released whatever happens; the outcome message to send back."""
    try:
        return OutcomeMessage(execute(payload, preloaded, recorder))
    finally:
        release_warm_recorder(recorder)


def main(argv: list[str] | None = None) -> int:
    """A warm case process: payload message on stdin, outcome message on stdout; its exit code.

    Its own stdout is kept for the outcome; anything else printed to it goes
    to stderr (the case's ``case.log``).
    """
    argv = sys.argv[1:] if argv is None else argv
    outcome_fd = os.dup(1)
    os.dup2(2, 1)
    preloaded: Preloaded | None = None
    recorder = None
    if argv[:1] == ["--warm"] and len(argv) >= 2:
        try:
            preloaded = Preloaded.load(argv[1], tuple(argv[2:]))
        except InputError:
            preloaded = None  # execute() loads it again and reports the problem as the case's outcome
        recorder = recorder_ahead(Path(argv[1]))
    payload = receive_case(fd_reader(0), source="the case's payload on stdin")
    pipe_messages.send_fd(outcome_fd, run_received(payload, preloaded, recorder))
    return 0


if __name__ == "__main__":
    sys.exit(main())
