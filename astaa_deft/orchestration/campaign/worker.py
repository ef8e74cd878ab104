"""One case, executed where it runs: a child process of the local pool, or a Dask worker.

The payload is plain JSON (spec path, planned case, run directory, horizon,
extra dictionaries) and so is the result: the same function serves both.
Run as ``python -m astaa_deft.orchestration.campaign.worker [--warm SPEC [DICTIONARY …]]``
it reads the payload on stdin and prints the outcome as its last line.
``--warm``: import everything and load that spec and those dictionaries
*before* waiting for the payload — the local pool starts each case's process
while the previous case still runs, so a case does not wait seconds for
Python's imports and the spec on a loaded machine (each case still gets a
process of its own). It also starts the case's recorder ahead, forked from
itself (:mod:`.forked`: no second interpreter start, imports or spec parse):
the recorder's start-up was the largest fixed wait of a case (~1–2 s of a
loaded machine's wall time before any module could start, ~0.55 CPU s).
"""

from __future__ import annotations

import json
import threading
import sys
from pathlib import Path
from typing import Any

from astaa_deft.engine.bus.processes import ChildProcess
from astaa_deft.model.errors import InputError
from astaa_deft.io.inputfile import SPEC, read_input
from astaa_deft.engine.intercept.dictionary import load_dictionary
from astaa_deft.engine.intercept.testcase import parse_testcase
from astaa_deft.engine.session.bus_run import release_warm_recorder, warm_recorder
from astaa_deft.engine.spec.loader import load_spec
from astaa_deft.orchestration.campaign.forked import fork_recorder
from astaa_deft.orchestration.campaign.model import CaseOutcome, PlannedCase
from astaa_deft.orchestration.campaign.runner import run_case


_Preloaded = tuple[str, list[str], Any, Any]  # spec path, dictionary paths, spec, dictionary


def execute(payload: dict[str, Any], preloaded: _Preloaded | None = None,
            warm_recorder: ChildProcess | None = None) -> dict[str, Any]:
    case = PlannedCase.from_json(payload["case"])
    try:
        if preloaded is not None and (preloaded[0], preloaded[1]) == (payload["spec"], payload.get("dictionaries", [])):
            spec, dictionary = preloaded[2], preloaded[3]
        else:
            spec = load_spec(Path(payload["spec"]))
            dictionary = load_dictionary([Path(p) for p in payload.get("dictionaries", [])])
        testcase = parse_testcase(case.testcase_xml.encode(), case.case_id, spec, dictionary) \
            if case.testcase_xml else None
    except InputError as exc:
        return CaseOutcome("error", "?", "bad input", error="; ".join(map(str, exc.problems))).to_json()
    settle = payload.get("settle")
    outcome = run_case(spec, testcase, case.params, Path(payload["run_dir"]), float(payload["horizon"]), dictionary,
                       float(settle) if settle is not None else None, warm_recorder=warm_recorder,
                       known=frozenset(payload.get("known", ())))
    return outcome.to_json()


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


def execute_remote(payload: dict[str, Any]) -> dict[str, Any]:
    """On a Dask worker: run in a local temp dir, send the log back with the result."""
    import base64
    import tempfile

    stop_worker_profiler()
    with tempfile.TemporaryDirectory(prefix="astaa-deft-case-") as tmp:
        body = execute({**payload, "run_dir": tmp})
        log = Path(tmp) / "run.mcap"
        body["log_b64"] = base64.b64encode(log.read_bytes()).decode() if log.is_file() else None
        return body


def recorder_ahead(spec_path: Path, parsed: tuple[str, Any] | None = None) -> ChildProcess | None:
    """This case's recorder, started now: forked from this process (still one thread, no Zenoh session),
    else a warm recorder process of its own, else none (the run starts one itself).
    ``parsed``: (the spec file's text, that text parsed as the recorder parses it), from a template process."""
    try:
        if parsed is not None:
            return fork_recorder(parsed[0], spec_path.name, parsed[1])
        return fork_recorder(read_input(spec_path, SPEC).decode("utf-8"), spec_path.name)
    except Exception:  # noqa: BLE001 - an unreadable spec is the case's error to report; no fork: a process
        try:
            return warm_recorder([spec_path])
        except OSError:
            return None


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    preloaded: _Preloaded | None = None
    recorder = None
    if argv[:1] == ["--warm"] and len(argv) >= 2:
        try:
            preloaded = (argv[1], argv[2:], load_spec(Path(argv[1])), load_dictionary([Path(p) for p in argv[2:]]))
        except InputError:
            preloaded = None  # execute() loads it again and reports the problem as the case's outcome
        recorder = recorder_ahead(Path(argv[1]))
    payload = json.loads(sys.stdin.read())
    try:
        body = execute(payload, preloaded, recorder)
    finally:
        release_warm_recorder(recorder)
    print(json.dumps(body, default=str), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
