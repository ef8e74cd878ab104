"""A case's recorder started ahead (warm): the same log as a cold one, and no process left behind."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

from astaa_deft.campaign.runner import run_case
from astaa_deft.log import layout
from astaa_deft.log.reader import read_log
from astaa_deft.session.bus_run import warm_recorder
from astaa_deft.spec_loader import load_spec

ECHO = Path(__file__).parent / "sut" / "echo.yaml"
PARAMS = {"count": "40", "rate": "100"}


def test_a_warm_recorder_records_the_case_as_a_cold_one_does(tmp_path: Path):
    spec = load_spec(ECHO)
    cold = run_case(spec, None, PARAMS, tmp_path / "cold", 3.0)
    recorder = warm_recorder([ECHO])
    warm = run_case(spec, None, PARAMS, tmp_path / "warm", 3.0, warm_recorder=recorder)
    assert cold.status == warm.status == "done", (cold, warm)
    assert recorder.wait(timeout=10) == 0  # the warm process was the case's recorder, and it finished cleanly
    logs = {name: read_log(tmp_path / name / "run.mcap") for name in ("cold", "warm")}
    # The talker's messages, less their wall-clock stamps: the same sequence in both logs.
    data = {name: [(d["header"]["seq"], d["value"]) for d in (json.loads(m.data) for m in log.on("test/data"))]
            for name, log in logs.items()}
    assert len(data["warm"]) == len(data["cold"]) == 40
    assert data["warm"] == data["cold"]
    assert logs["warm"].attachments[layout.SPEC_ATTACHMENT] == logs["cold"].attachments[layout.SPEC_ATTACHMENT]
    assert (tmp_path / "warm" / "modules" / "recorder.log").is_file()  # its stderr went to the run's folder


def test_a_dead_warm_recorder_is_replaced_by_a_fresh_one(tmp_path: Path):
    recorder = warm_recorder([ECHO])
    recorder.kill()
    recorder.wait(timeout=10)
    outcome = run_case(load_spec(ECHO), None, PARAMS, tmp_path / "case", 3.0, warm_recorder=recorder)
    assert outcome.status == "done", outcome
    assert len(read_log(tmp_path / "case" / "run.mcap").on("test/data")) == 40


def test_an_unused_warm_recorder_exits_at_end_of_input():
    recorder = warm_recorder([ECHO])
    assert recorder.stdin is not None
    recorder.stdin.close()
    try:
        assert recorder.wait(timeout=20) == 0
    except subprocess.TimeoutExpired:
        recorder.kill()
        raise
