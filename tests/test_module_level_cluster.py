"""The module-level search on a real Dask LocalCluster of worker processes on 127.0.0.1 (dashboard off):
`fuzz --cluster ADDRESS` sends the module replays there, and finds there what it finds locally."""

from __future__ import annotations

import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import distributed.utils
import pytest
from dask.distributed import Client, LocalCluster

from astaa_deft.orchestration.campaign.module_level import read_state

SPEC = Path(__file__).parent / "sut" / "modlevel.yaml"


@pytest.fixture(autouse=True, scope="module")
def _leave_no_dask_thread_behind():
    """As in test_campaign_cluster.py: distributed's offload thread, started by an in-process client, would live
    on in this test process and make later in-process forks unsafe; it is replaced by a fresh pool."""
    yield
    old = distributed.utils._offload_executor
    distributed.utils._offload_executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="Dask-Offload")
    old.shutdown(wait=True)


def _task_prefixes(dask_scheduler) -> list[str]:
    return list(dask_scheduler.task_prefixes)


@pytest.mark.slow  # ~1 min: a whole campaign on a LocalCluster; the cluster's campaign path stays in the default run
@pytest.mark.promise  # (test_campaign_cluster.py)
def test_module_level_replays_run_on_the_cluster_and_find_every_seeded_defect(tmp_path: Path):
    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                           dashboard_address=None)
    try:
        out = tmp_path / "campaign"
        done = subprocess.run([sys.executable, "-m", "astaa_deft.cli", "fuzz", "--spec", str(SPEC), "-o", str(out),
                               "--cases", "1", "--seed", "0", "--baseline", "1", "--reruns", "1", "--no-minimise",
                               "--params", "seconds=3", "--module-level-seconds", "15",
                               "--cluster", cluster.scheduler_address],
                              capture_output=True, text=True, timeout=400)
        with Client(cluster.scheduler_address) as client:
            prefixes = client.run_on_scheduler(_task_prefixes)
    finally:
        cluster.close()
    assert done.returncode in (0, 1), done.stdout + done.stderr
    assert f"worker(s) of the cluster at {cluster.scheduler_address}" in done.stderr, done.stderr
    assert any(p.startswith("module-level") for p in prefixes), prefixes  # the replays were the cluster's tasks
    folder = out / "module_level"
    assert not list(folder.glob("*.job.json"))  # no local worker was started
    state = read_state(out)
    assert state is not None and state.modules == ("ctrl", "watch") and state.cases > 0
    assert state.core_seconds > 0  # the workers' CPU came back with their results
    found = {(f.verdict.module, f.verdict.signature) for f in state.findings}
    assert found == {("ctrl", "invariant finite_u"), ("ctrl", "crash ValueError in modlevel_ctrl.py:step"),
                     ("watch", "crash OverflowError in modlevel_watch.py:step")}
    assert {("state", "debug.note"), ("state", "debug.score")} <= set(state.unread)  # part 0's reads came back
    assert all(f.case_id for f in state.findings)  # each planned as a live case
