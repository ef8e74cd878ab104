"""Cases on a real Dask LocalCluster of worker processes on 127.0.0.1 (dashboard off)."""

from __future__ import annotations

import json
import os
import signal
import socket
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

from concurrent.futures import ThreadPoolExecutor

import distributed.utils
import pytest
from dask.distributed import Client, LocalCluster

from astaa_deft.orchestration.campaign.executors import DaskPool
from astaa_deft.orchestration.journal.model import BASELINE, PlannedCase
from astaa_deft.orchestration.campaign.payload import case_json
from astaa_deft.orchestration.campaign.strategies import STRATEGIES
from astaa_deft.orchestration.campaign.strategies.base import Timing
from astaa_deft.engine.intercept.dictionary import load_dictionary
from astaa_deft.engine.spec.loader import load_spec

ECHO = Path(__file__).parent / "sut" / "echo.yaml"


@pytest.fixture(autouse=True, scope="module")
def _leave_no_dask_thread_behind():
    """An in-process Dask client starts distributed's offload thread, which would live on in this test process.
    Tests that run after these fork planner replays in-process, and a fork is allowed only from a
    single-threaded process (bus/process_launch.py), as in a real `astaa-deft extract`: the pool is shut down
    and replaced by a fresh one (its thread starts only when used)."""
    yield
    old = distributed.utils._offload_executor
    distributed.utils._offload_executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="Dask-Offload")
    old.shutdown(wait=True)


def test_cluster_campaign_runs_the_same_cases_as_local_and_brings_logs_back(tmp_path: Path):
    out = tmp_path / "campaign"
    done = subprocess.run([sys.executable, "-m", "astaa_deft.cli", "fuzz", "--spec", str(ECHO), "-o", str(out),
                           "--cases", "3", "--seed", "11", "--horizon", "2", "--baseline", "1", "--no-minimise",
                           "--cluster", "local:2"], capture_output=True, text=True, timeout=240)
    assert done.returncode in (0, 1), done.stdout + done.stderr
    db = sqlite3.connect(out / "journal.sqlite")
    cases = db.execute("SELECT number, testcase_xml, status, log_path FROM cases WHERE kind='mutated'"
                       " ORDER BY number").fetchall()
    random = STRATEGIES["random"](load_spec(ECHO), load_dictionary(), 11, 2.0)
    (timing,), = db.execute("SELECT value FROM meta WHERE key='timing'").fetchall()
    random.calibrate(Timing(**json.loads(timing)))  # as measured in the campaign's baseline
    assert [c[1] for c in cases] == [random.propose(n).testcase.to_xml().decode() for n in (1, 2, 3)]
    for _number, _xml, status, log_path in cases:
        assert status == "done" and Path(log_path).is_file() and Path(log_path).is_relative_to(out.resolve())


def test_a_killed_workers_cases_are_requeued(tmp_path: Path):
    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                           dashboard_address=None)
    try:
        pool = DaskPool(cluster.scheduler_address, 2)
        for n in range(1, 5):
            case = PlannedCase(case_id=f"b-{n}", kind=BASELINE, number=n, seed=0, params={"count": "20"}, testcase=None)
            pool.submit(case.case_id, {"spec": str(ECHO), "case": case_json(case), "run_dir": str(tmp_path / str(n)),
                                       "horizon": 2.0, "dictionaries": []})
        with Client(cluster.scheduler_address) as client:
            busy = None
            deadline = time.monotonic() + 60
            while busy is None and time.monotonic() < deadline:  # until a worker is inside a case (its processes)
                processing = client.processing()
                busy = next((w for w, inside in client.run(_has_children).items() if inside and processing.get(w)),
                            None)
                time.sleep(0.05)
            assert busy is not None, "no worker started a case"
            pid = client.run(os.getpid, workers=[busy])[busy]
        os.kill(pid, signal.SIGKILL)
        outcomes = {}
        deadline = time.monotonic() + 180
        while pool.pending() and time.monotonic() < deadline:
            outcomes.update(dict(pool.done(timeout=1.0)))
        assert sorted(outcomes) == ["b-1", "b-2", "b-3", "b-4"]
        assert all(o.status == "done" for o in outcomes.values()), outcomes
        assert all((tmp_path / str(n) / "run.mcap").is_file() for n in range(1, 5))
        pool.client.close()
    finally:
        cluster.close()


def _has_children() -> bool:
    """On a worker: whether it runs processes of a case now."""
    import psutil

    return bool(psutil.Process().children())


def _profiling(dask_worker) -> bool:
    pc = dask_worker.periodic_callbacks.get("profile")
    return pc is not None and pc.is_running()


def test_cases_run_on_workers_that_do_not_sample_their_stacks():
    """Dask's 10 ms stack sampling can deadlock a case's Thread.start() on CPython 3.11 (seen on a
    LocalCluster): the campaign's own LocalCluster starts without it, and a case turns it off on any worker."""
    from astaa_deft.orchestration.campaign.worker import stop_worker_profiler

    pool = DaskPool("local:1", 1)
    try:
        assert not any(pool.client.run(_profiling).values())
    finally:
        pool.client.close()
        assert pool.cluster is not None
        pool.cluster.close()
    cluster = LocalCluster(n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1",
                           dashboard_address=None)
    try:
        with Client(cluster) as client:
            assert all(client.run(_profiling).values())  # Dask's default
            assert client.submit(stop_worker_profiler, pure=False).result(timeout=60) is True
            assert not any(client.run(_profiling).values())
    finally:
        cluster.close()


def test_a_campaign_on_a_cluster_runs_as_many_cases_at_once_as_it_has_workers(tmp_path: Path):
    """No --workers: the runs at once are the cluster's worker count (one case a worker), not a local guess."""
    cluster = LocalCluster(n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1",
                           dashboard_address=None)
    try:
        out = tmp_path / "campaign"
        done = subprocess.run([sys.executable, "-m", "astaa_deft.cli", "fuzz", "--spec", str(ECHO), "-o", str(out),
                               "--cases", "1", "--seed", "3", "--horizon", "2", "--baseline", "1", "--no-minimise",
                               "--cluster", cluster.scheduler_address], capture_output=True, text=True, timeout=240)
    finally:
        cluster.close()
    assert done.returncode in (0, 1), done.stdout + done.stderr
    assert f"1 worker(s) on {cluster.scheduler_address}" in done.stderr, done.stderr  # the start line


def test_an_unreachable_scheduler_is_named_with_the_fix(tmp_path: Path):
    with socket.socket() as s:  # a free loopback port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    done = subprocess.run([sys.executable, "-m", "astaa_deft.cli", "fuzz", "--spec", str(ECHO), "-o", str(tmp_path / "c"),
                           "--cases", "1", "--cluster", f"tcp://127.0.0.1:{port}"], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 2, done.stdout + done.stderr
    assert f"no Dask scheduler answers at tcp://127.0.0.1:{port}" in done.stderr and "Traceback" not in done.stderr
