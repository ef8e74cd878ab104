"""The module-level search's workers on a Dask cluster (``fuzz --cluster tcp://HOST:PORT``).

Each job of :mod:`.module_level` (one module, one share of its fault plan)
becomes one Dask task. The task runs the very worker the local search runs
(:mod:`.module_level_worker`) as a process of its own on the Dask worker —
a replayed step is interrupted by SIGALRM, which needs a single-threaded
process, and a module hung in native code is stopped by its group — in a
temporary folder there: the clean log goes with the task (the campaign
folder need not be shared), and the results and the field reads come back
with its CPU time. The spec and its modules are read by path, as a live case
on the cluster reads them.

The time box travels as seconds left (the machines' clocks need not agree);
an interrupted campaign sets a Dask event every task watches, so a task
stops its worker at once instead of at its deadline.
"""

from __future__ import annotations

import contextlib
import json
import resource
import subprocess
import tempfile
import time
import uuid
from collections.abc import Mapping, Sequence
from pathlib import Path

from astaa_deft.engine.bus import process_launch
from astaa_deft.engine.bus.processes import python_module, stop_process, tail
from astaa_deft.model.errors import InputError, Problem

POLL_SECONDS = 0.5  # how often a task looks at the stop event and its worker
CLUSTER_CONNECT_SECONDS = 10.0


def remote_job(job: Mapping[str, object], log: bytes, stop: str, grace: float) -> dict[str, object]:
    """On a Dask worker: run one module-level worker job in a temporary folder; its results, reads and CPU."""
    from distributed import Event

    from astaa_deft.orchestration.campaign.worker import stop_worker_profiler

    stop_worker_profiler()
    stopped = Event(stop)
    with tempfile.TemporaryDirectory(prefix="astaa-deft-module-level-") as tmp:
        folder = Path(tmp)
        (folder / "clean.mcap").write_bytes(log)
        deadline = time.time() + float(job["seconds_left"])  # type: ignore[arg-type]
        local = {**job, "log": str(folder / "clean.mcap"), "results": str(folder / "results.jsonl"),
                 "reads": str(folder / "reads.json") if job["reads"] else None, "deadline": deadline}
        (folder / "job.json").write_text(json.dumps(local), encoding="utf-8")
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        with open(folder / "worker.log", "wb") as out:
            worker = process_launch.start(
                [*python_module("astaa_deft.orchestration.campaign.module_level_worker"), str(folder / "job.json")],
                stdout=out, stderr=subprocess.STDOUT)
        try:
            while worker.poll() is None and time.time() < deadline + grace and not stopped.is_set():
                with contextlib.suppress(subprocess.TimeoutExpired):
                    worker.wait(timeout=POLL_SECONDS)
        finally:
            if worker.poll() is None:
                stop_process(worker, grace=2.0)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        results, reads = folder / "results.jsonl", folder / "reads.json"
        return {"results": results.read_text(encoding="utf-8", errors="replace") if results.is_file() else "",
                "reads": reads.read_text(encoding="utf-8") if reads.is_file() else None,
                "cpu": (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime),
                "log": tail(folder / "worker.log")}


def cluster_cores(address: str) -> int:
    """The cluster's workers (at least one): each runs one share of the plan at a time."""
    from astaa_deft.orchestration.campaign.executors import cluster_workers

    return cluster_workers(address) or 1


def run_on_cluster(address: str, jobs: Sequence[tuple[str, Mapping[str, object]]], *, log_path: Path,
                   folder: Path, deadline: float, grace: float) -> float:
    """Run ``jobs`` ((name, job) of :mod:`.module_level`) on the cluster at ``address``; append each one's results
    to its file in ``folder`` and write its reads where the job names them (as a local worker does); the CPU
    seconds they took."""
    from dask.distributed import Client, Event, wait

    log = log_path.read_bytes()
    try:
        client = Client(address, timeout=CLUSTER_CONNECT_SECONDS)
    except (OSError, TimeoutError) as exc:
        raise InputError(Problem("--cluster", None, None, f"no Dask scheduler answers at {address} ({exc})",
                                 "start one, or drop --cluster")) from None
    stop = f"astaa-deft-module-level-stop-{uuid.uuid4().hex}"
    cpu = 0.0
    try:
        stopped = Event(stop, client=client)
        left = deadline - time.time()
        futures = {client.submit(remote_job, {**job, "seconds_left": left}, log, stop, grace,
                                 key=f"module-level-{name}-{uuid.uuid4().hex[:8]}", pure=False, retries=1): name
                   for name, job in jobs}
        by_name = dict(jobs)
        try:
            done, _pending = wait(list(futures), timeout=max(1.0, deadline + 2 * grace - time.time()))
        except TimeoutError:
            done = {f for f in futures if f.done()}
        except BaseException:  # interrupted: every task stops its worker now
            stopped.set()
            raise
        stopped.set()  # tasks still running past the grace stop too
        for future in done:
            name = futures[future]
            try:
                result = future.result()
            except Exception as exc:  # noqa: BLE001 - a task that failed on every retry: its module's error
                with open(folder / f"{name}.jsonl", "a", encoding="utf-8") as results:
                    results.write(json.dumps({"error": f"on the cluster: {type(exc).__name__}: {exc}"}) + "\n")
                continue
            with open(folder / f"{name}.jsonl", "a", encoding="utf-8") as results:  # after an earlier round's
                results.write(str(result["results"]))
            (folder / f"{name}.log").write_text(str(result["log"]), encoding="utf-8")
            reads = by_name[name]["reads"]
            if reads and result["reads"]:
                Path(str(reads)).write_text(str(result["reads"]), encoding="utf-8")
            cpu += float(str(result["cpu"]))
        client.cancel(list(futures))
    finally:
        client.close()
    return cpu


__all__ = ["cluster_cores", "remote_job", "run_on_cluster"]
