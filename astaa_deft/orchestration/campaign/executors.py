"""Where cases run: a pool of local child processes, or a Dask distributed cluster.

Both take payloads and hand back (case id, outcome) as cases finish, so the
campaign's loop is the same either way. Local: each case is its own Python
process (started in its own session and told to die with us), so a crash or
a hang of one case never touches another or the campaign. Dask: each worker
runs its cases on its own loopback and returns the log with the outcome; a
task whose worker died is re-run by the scheduler elsewhere.
"""

from __future__ import annotations

import socket
import subprocess
import threading
import time
from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor, wait
from pathlib import Path
from typing import TYPE_CHECKING
from collections.abc import Iterator

from astaa_deft.engine.bus.process_launch import start
from astaa_deft.engine.bus.processes import python_module, stop_process, tail
from astaa_deft.io import pipe_messages
from astaa_deft.io.pipe_messages import FrameError, bytes_reader
from astaa_deft.model.errors import InputError, Problem
from astaa_deft.model.json import JsonObject
from astaa_deft.orchestration.journal.model import CaseOutcome
from astaa_deft.orchestration.campaign.payload import CaseMessage, CasePayload, OutcomeMessage
from astaa_deft.orchestration.campaign.zygote import Zygote, stop_group

if TYPE_CHECKING:
    from dask.distributed import Client as DaskClient, Future as DaskFuture

CASE_TIMEOUT_MARGIN = 60.0  # seconds beyond the horizon before a case process is stopped


class LocalPool:
    """``workers`` cases at once, each in a fresh process.

    Each case process is forked from a template that imported everything and
    loaded the spec once (:mod:`.zygote`; its recorder is forked from it in
    turn, :mod:`.forked`). Without a template (it could not start), each
    slot keeps its next case's process warm (started, imports done, spec
    loaded, its recorder started, waiting for its payload) while the current
    case runs. Why: docs/performance.md, "pipes". ``submit``, ``done``,
    ``pending`` and ``close`` are called from one thread (the campaign's);
    the cases run on the pool's threads.
    """

    def __init__(self, workers: int) -> None:
        self.workers = workers
        self._pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="case")
        self._procs: set[subprocess.Popen[bytes]] = set()
        self._warm: list[tuple[tuple[str, ...], subprocess.Popen[bytes]]] = []  # (what it preloaded, process)
        self._zygotes: dict[tuple[str, ...], Zygote | None] = {}  # None: it could not start (processes instead)
        self._forked: set[int] = set()  # case processes forked by a template, running
        self._lock = threading.Lock()
        self._closed = False
        self.futures: dict[Future[CaseOutcome], str] = {}

    def submit(self, case_id: str, payload: JsonObject) -> None:
        """Run the case (``payload``: :meth:`~.payload.CasePayload.to_json`); raises RuntimeError once closed."""
        typed = CasePayload.from_json(payload)
        # The template starts here, before its first case is run by the pool.
        self._zygote(_key(typed))
        self.futures[self._pool.submit(self._run, typed)] = case_id

    def _spawn(self, key: tuple[str, ...]) -> subprocess.Popen[bytes]:
        return start([*python_module("astaa_deft.orchestration.campaign.worker"), "--warm", *key],
                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE)

    def _take(self, payload: CasePayload) -> subprocess.Popen[bytes]:
        """A warm process for this payload's spec (or a new one), and a warm one for the slot's next case."""
        key = _key(payload)
        with self._lock:
            index = next((i for i, (k, p) in enumerate(self._warm) if k == key and p.poll() is None), None)
            proc = self._warm.pop(index)[1] if index is not None else None
            if self._closed:
                raise RuntimeError("the pool is closed")
            if proc is None:
                proc = self._spawn(key)
            self._procs.add(proc)
            # Fill every slot's next process at once: the first wave after the baseline starts warm too.
            while len(self._warm) < self.workers:
                self._warm.append((key, self._spawn(key)))
        return proc

    def _zygote(self, key: tuple[str, ...]) -> Zygote | None:
        with self._lock:
            if self._closed:
                raise RuntimeError("the pool is closed")
            zygote = self._zygotes.get(key)
            if zygote is not None and not zygote.alive():
                zygote.close()
                zygote = self._zygotes[key] = None  # it died: processes of their own from now on
            elif key not in self._zygotes:
                try:
                    zygote = self._zygotes[key] = Zygote(key[0], list(key[1:]))
                except OSError:
                    zygote = self._zygotes[key] = None
            return zygote

    def _run(self, payload: CasePayload) -> CaseOutcome:
        with self._lock:
            zygote = self._zygotes.get(_key(payload))
        if zygote is not None and zygote.alive():
            try:
                pid, conn = zygote.fork()
            except OSError:
                pass  # a process of its own instead
            else:
                return self._run_forked(pid, conn, payload)
        return self._run_warm(payload)

    def _run_warm(self, payload: CasePayload) -> CaseOutcome:
        """A case in a warm process of its own: payload message on its stdin, outcome message on its stdout."""
        proc = self._take(payload)
        try:
            out, err = proc.communicate(pipe_messages.encode(CaseMessage(payload)),
                                        timeout=payload.horizon + CASE_TIMEOUT_MARGIN)
        except subprocess.TimeoutExpired:
            stop_process(proc, grace=5.0)
            return CaseOutcome(status="error", verdict="?", summary="the case did not finish", error="timeout")
        finally:
            with self._lock:
                self._procs.discard(proc)
        log = err.decode("utf-8", "replace")
        Path(payload.run_dir).mkdir(parents=True, exist_ok=True)
        (Path(payload.run_dir) / "case.log").write_text(log)
        try:
            message = pipe_messages.receive(bytes_reader(out), (OutcomeMessage,), source="the case process's output")
        except FrameError as exc:
            log = f"{log}\n{exc}"
            message = None
        if proc.returncode != 0 or message is None:
            return CaseOutcome(status="error", verdict="?", summary="the case process failed",
                               error=log.strip()[-2000:])
        return message.outcome

    def _run_forked(self, pid: int, conn: socket.socket, payload: CasePayload) -> CaseOutcome:
        """A case in a process forked by the template: payload out, outcome back on its socket."""
        with self._lock:
            self._forked.add(pid)
        deadline = time.monotonic() + payload.horizon + CASE_TIMEOUT_MARGIN

        def read(size: int) -> bytes:
            conn.settimeout(max(0.001, deadline - time.monotonic()))
            return conn.recv(size)

        try:
            conn.sendall(pipe_messages.encode(CaseMessage(payload)))
            conn.shutdown(socket.SHUT_WR)
            message = pipe_messages.receive(read, (OutcomeMessage,), source="the forked case's socket")
        except TimeoutError:
            stop_group(pid, grace=5.0)
            return CaseOutcome(status="error", verdict="?", summary="the case did not finish", error="timeout")
        except (OSError, FrameError) as exc:
            stop_group(pid, grace=5.0)
            return CaseOutcome(status="error", verdict="?", summary="the case process failed", error=str(exc))
        finally:
            conn.close()
            with self._lock:
                self._forked.discard(pid)
        if message is None:
            return CaseOutcome(status="error", verdict="?", summary="the case process failed",
                               error=tail(Path(payload.run_dir) / "case.log").strip()[-2000:])
        return message.outcome

    def pending(self) -> int:
        return len(self.futures)

    def done(self, timeout: float | None = None) -> Iterator[tuple[str, CaseOutcome]]:
        finished, _ = wait(list(self.futures), timeout=timeout, return_when=FIRST_COMPLETED)
        for future in finished:
            case_id = self.futures.pop(future)
            yield case_id, future.result()

    def close(self) -> None:
        with self._lock:
            self._closed = True
            forked = list(self._forked)
            zygotes = [z for z in self._zygotes.values() if z is not None]
            procs = list(self._procs)
            warm = [p for _, p in self._warm]
            self._warm.clear()
        for proc in warm:  # waiting for a payload: nothing of a case to lose
            stop_process(proc, grace=1.0)
        for proc in procs:
            stop_process(proc, grace=10.0)
        for pid in forked:
            stop_group(pid, grace=10.0)
        self._pool.shutdown(wait=True, cancel_futures=True)
        for zygote in zygotes:  # after the cases: it reaps them, so their CPU is accounted to it, then to us
            zygote.close()


def _key(payload: CasePayload) -> tuple[str, ...]:
    """What a case process preloads: the spec and the dictionaries."""
    return (payload.spec, *payload.dictionaries)


CLUSTER_CONNECT_SECONDS = 10.0  # a scheduler that does not answer within this is unreachable


def cluster_workers(address: str) -> int | None:
    """How many workers the cluster at ``address`` has: K for ``local:K``, else the running scheduler's count
    (None: ``local:`` without K, or a scheduler with no worker yet). InputError when the scheduler cannot be
    reached, naming it."""
    kind, _, count = address.partition(":")
    if kind == "local":
        return int(count) if count else None
    from dask.distributed import Client

    try:
        with Client(address, timeout=CLUSTER_CONNECT_SECONDS) as client:
            return _workers_of(client) or None
    except (OSError, TimeoutError) as exc:
        raise InputError(Problem("--cluster", None, None, f"no Dask scheduler answers at {address} ({exc})",
                                 "start one (dask scheduler --host 127.0.0.1 --dashboard-address 127.0.0.1:0, "
                                 "then dask worker ADDRESS --host 127.0.0.1 --dashboard-address 127.0.0.1:0) "
                                 "or give local:K")) from None


def _workers_of(client: DaskClient) -> int:
    """The workers a Dask scheduler has now."""
    return len(client.scheduler_info().get("workers", {}))


class DaskPool:
    """Cases on a Dask cluster: ``tcp://HOST:PORT`` (a running scheduler) or ``local:K`` (K worker processes)."""

    def __init__(self, address: str, workers: int) -> None:
        import dask
        from dask.distributed import Client, LocalCluster

        self.cluster = None
        if address.startswith("local:"):
            count = int(address.split(":", 1)[1] or workers)
            # Workers without stack sampling (see worker.stop_worker_profiler: it can deadlock a case).
            with dask.config.set({"distributed.worker.profile.enabled": False}):
                self.cluster = LocalCluster(n_workers=count, threads_per_worker=1, processes=True,
                                            host="127.0.0.1", dashboard_address=None, protocol="tcp")
            self.client = Client(self.cluster)
        else:
            self.client = Client(address)
        self.workers = max(1, _workers_of(self.client) or workers)
        self.futures: dict[DaskFuture, tuple[str, CasePayload]] = {}

    def submit(self, case_id: str, payload: JsonObject) -> None:
        """Run the case on the cluster (``payload``: :meth:`~.payload.CasePayload.to_json`)."""
        from astaa_deft.orchestration.campaign.worker import execute_remote

        typed = CasePayload.from_json(payload)
        # retries: a task lost with its worker (killed, machine gone) is re-queued on another.
        future = self.client.submit(execute_remote, typed, key=f"case-{case_id}-0", pure=False, retries=3)
        self.futures[future] = (case_id, typed)

    def pending(self) -> int:
        return len(self.futures)

    def done(self, timeout: float | None = None) -> Iterator[tuple[str, CaseOutcome]]:
        from dask.distributed import wait as dwait

        try:
            result = dwait(list(self.futures), timeout=timeout, return_when="FIRST_COMPLETED")
        except TimeoutError:  # nothing finished yet (dask raises instead of returning an empty set)
            return
        for future in result.done:
            case_id, payload = self.futures.pop(future)
            try:
                result = future.result()
            except Exception as exc:  # noqa: BLE001 - a task that failed on every retry
                yield case_id, CaseOutcome(status="error", verdict="?", summary="the case failed on the cluster",
                                           error=str(exc))
                continue
            run_dir = Path(payload.run_dir)
            run_dir.mkdir(parents=True, exist_ok=True)
            outcome = result.outcome
            if result.log:
                (run_dir / "run.mcap").write_bytes(result.log)
                outcome.log_path = str(run_dir / "run.mcap")
            yield case_id, outcome

    def close(self) -> None:
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()
