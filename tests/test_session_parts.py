"""A run built from parts: the stop order that follows from the start order, and what callbacks see (real runs)."""

from __future__ import annotations

import os
from pathlib import Path

from astaa_deft.engine.session import BusRun, RunOptions, RunView, run_session
from astaa_deft.engine.spec.loader import load_spec
from astaa_deft.io.log import records as rec
from astaa_deft.io.log.reader import read_log
from astaa_deft.model.records import ProcessExit

from proxy_helpers import ECHO_SPEC

PARAMS = {"count": "20", "rate": "200"}


def _delivered(view: RunView) -> str | None:
    out = view.run_dir / "listener.out"
    return "all delivered" if out.exists() and out.read_text().count("\n") >= 20 else None


def test_the_run_ends_then_is_judged_then_stops_its_modules_then_its_recorder(tmp_path: Path):
    events: list[rec.Record] = []
    log = tmp_path / "run.mcap"
    result = run_session(load_spec(ECHO_SPEC), RunOptions(record=log, run_dir=tmp_path / "run", params=PARAMS,
                                                          time_limit=60.0),
                         stop_when=_delivered, on_event=events.append)
    assert result.end_reason == "all delivered" and result.complete and result.observed
    kinds = [type(r) for r in events]
    assert kinds[0] is rec.RunStarted
    # The end, then the verdict (judged up to the stop), then the modules stopped and the drain before the
    # recorder stops: the reverse of the start order (recorder, judge, modules).
    order = [kinds.index(k) for k in (rec.RunEnd, rec.RunStopping, rec.RunVerdict, rec.RunStopped)]
    assert order == sorted(order)
    stopped = [e for e in events[order[2] + 1:order[3]] if isinstance(e, ProcessExit)]
    assert stopped and all(e.during_shutdown for e in stopped)
    # The recorder was still up for the last event: the log holds it.
    logged = [rec.decode(e) for e in read_log(log).events()]
    assert isinstance(logged[-1], rec.RunStopped)


def test_callbacks_get_a_read_only_view_with_pids_endpoints_and_run_dir(tmp_path: Path):
    seen: dict[str, object] = {}

    def on_start(view: RunView) -> None:
        assert not isinstance(view, BusRun)
        seen["recorder_alive"] = view.recorder_pid is not None and os.kill(view.recorder_pid, 0) is None
        seen["modules"] = sorted(view.module_pids)
        seen["endpoints"] = view.endpoints
        seen["run_dir"] = view.run_dir
        seen["started"] = view.started_ns > 0

    def stop_when(view: RunView) -> str | None:
        seen["violations"], seen["exits"] = view.violations, view.exits
        return _delivered(view)

    spec = load_spec(ECHO_SPEC)
    result = run_session(spec, RunOptions(record=tmp_path / "run.mcap", run_dir=tmp_path / "run", params=PARAMS,
                                          time_limit=60.0), on_start=on_start, stop_when=stop_when)
    assert result.end_reason == "all delivered"
    assert seen["recorder_alive"] and seen["started"]
    assert seen["modules"] == sorted(m.name for m in spec.modules)
    assert seen["run_dir"] == (tmp_path / "run").resolve()
    assert isinstance(seen["endpoints"], tuple) and seen["endpoints"]
    assert seen["violations"] == () and seen["exits"] == ()  # snapshots: tuples, not the run's own lists
