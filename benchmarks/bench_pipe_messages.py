"""The replay pool's round trip over its pipes: a job out to a worker process, its answer back.

Measures the transport alone (the worker answers at once, no planner runs):
the old protocol (``multiprocessing.connection.Connection``, pickles) against
pipe_messages frames with a JSON and with a CBOR body. A job keeps ``--kept``
mutations, each with a field selection (ddmin's jobs early in a
minimisation carry about a hundred).

    python benchmarks/bench_pipe_messages.py [--rounds 2000] [--kept 100]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from multiprocessing.connection import Connection

from astaa_deft.analysis.minimise.ddmin import Outcome, TestResult
from astaa_deft.analysis.minimise.replay_model import Job, ReplayAnswer
from astaa_deft.analysis.minimise.replay_pool import AnswerMessage, JobMessage, StopMessage
from astaa_deft.engine.bus import process_launch
from astaa_deft.engine.bus.processes import stop_process
from astaa_deft.io import pipe_messages
from astaa_deft.io.pipe_messages import CBOR, JSON, BodyEncoding, fd_reader

MODES = {"pickle-connection": None, "frames-json": JSON, "frames-cbor": CBOR}
ANSWER = ReplayAnswer(TestResult(Outcome.FAIL, "planned_speed broke at output 12: 13.0 > 12.5"), 12)


def _echo(mode: str, read_fd: int, write_fd: int) -> int:
    """The worker's side: answer every job with :data:`ANSWER` until stopped."""
    encoding = MODES[mode]
    if encoding is None:
        jobs, answers = Connection(read_fd, writable=False), Connection(write_fd, readable=False)
        while jobs.recv() is not None:
            answers.send(ANSWER)
        return 0
    while isinstance(pipe_messages.receive(fd_reader(read_fd), (JobMessage, StopMessage), source="bench"),
                     JobMessage):
        pipe_messages.write_fd(write_fd, pipe_messages.encode(AnswerMessage(ANSWER), encoding))
    return 0


def _round_trips(mode: str, job: Job, rounds: int) -> list[float]:
    """Seconds per round trip, ``rounds`` of them, with a worker started for ``mode``."""
    job_read, job_write = os.pipe()
    answer_read, answer_write = os.pipe()
    child = process_launch.start([sys.executable, __file__, "--echo", mode, str(job_read), str(answer_write)],
                                 pass_fds=(job_read, answer_write), stderr=None)
    os.close(job_read)
    os.close(answer_write)
    encoding: BodyEncoding | None = MODES[mode]
    times = []
    try:
        if encoding is None:
            jobs, answers = Connection(job_write, readable=False), Connection(answer_read, writable=False)
            for _ in range(rounds):
                began = time.perf_counter()
                jobs.send(job)
                answers.recv()
                times.append(time.perf_counter() - began)
            jobs.send(None)
        else:
            for _ in range(rounds):
                began = time.perf_counter()
                pipe_messages.write_fd(job_write, pipe_messages.encode(JobMessage(job), encoding))
                pipe_messages.receive(fd_reader(answer_read), (AnswerMessage,), source="bench")
                times.append(time.perf_counter() - began)
            pipe_messages.write_fd(job_write, pipe_messages.encode(StopMessage(), encoding))
    finally:
        stop_process(child, grace=5.0)
    return times


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=2000)
    parser.add_argument("--kept", type=int, default=100)
    parser.add_argument("--echo", nargs=3, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.echo:
        return _echo(args.echo[0], int(args.echo[1]), int(args.echo[2]))
    job = Job(tuple((n, (0, 2) if n % 3 else None) for n in range(args.kept)))
    for mode in MODES:
        times = sorted(_round_trips(mode, job, args.rounds))
        print(f"{mode:18s} median {statistics.median(times) * 1e6:7.1f} µs   "
              f"p90 {times[int(len(times) * 0.9)] * 1e6:7.1f} µs   ({args.rounds} round trips, {args.kept} kept)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
