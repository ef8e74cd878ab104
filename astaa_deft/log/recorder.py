"""The recorder: its own process, subscribed to the bus, writing the MCAP log.

It runs apart from the proxy because writing MCAP in the forwarding process
adds millisecond latency spikes (GIL); here it only costs a core. It stops
cleanly (``finish()``) on SIGTERM/SIGINT and when the tool that started it
dies, so the log it leaves is complete unless the recorder itself is killed.

Started by the tool as ``python -m astaa_deft.log.recorder ARGS``; prints
``ready`` on stdout once subscribed and a JSON line of counts when done.
"""

from __future__ import annotations

import argparse
import os
import json
import queue
import signal
import sys
import threading
import time
from pathlib import Path

import zenoh

from ..bus import topology
from ..bus.topology import read_intercept_record
from ..bus import zenoh_config as zc
from ..codecs import get_codec
from ..codecs.base import DecodeError
from ..spec_loader import load_spec
from . import layout, records
from .viewable import ViewableTwins
from .writer import LogWriter

_STOP = object()
CAUGHT_UP = "caught up"  # stdout line: the run_stopped event arrived, so did every message before it
SHUTDOWN_LIMIT_SECONDS = 20.0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="astaa-deft-recorder")
    ap.add_argument("--spec", required=True, type=Path)
    ap.add_argument("--mode", choices=("star", "passive"), required=True)
    ap.add_argument("--connect", action="append", required=True, help="the bus to record (a router or peer)")
    ap.add_argument("--out", required=True, type=Path)
    ap.add_argument("--meta", default="{}", help="JSON object stored as run metadata")
    ap.add_argument("--chunk-size", type=int, default=64 * 1024)
    ap.add_argument("--attach", action="append", default=[], metavar="NAME=PATH",
                    help="store this file in the log as an attachment (policy, dictionaries)")
    ap.add_argument("--intercepted", action="append", default=[],
                    help="a channel the proxy may alter: record what it delivered, and the originals")
    args = ap.parse_args(argv)

    tool_pid = os.getppid()  # if this changes, the tool died (and its death signal is what stops us)
    stopping: list[int] = []  # a signal handler must not take locks (Event.set could deadlock)
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda signum, _frame: stopping.append(signum))

    spec = load_spec(args.spec)
    writer = LogWriter(args.out, spec, chunk_size=args.chunk_size)
    writer.attachment(layout.SPEC_ATTACHMENT, spec.source_text.encode(), "application/yaml")
    for item in args.attach:
        name, _, path = item.partition("=")
        media = "application/xml" if name.endswith(".xml") else "application/yaml"
        writer.attachment(name, Path(path).read_bytes(), media)
    writer.metadata(layout.RUN_METADATA, {**json.loads(args.meta), "mode": args.mode})

    q: "queue.SimpleQueue" = queue.SimpleQueue()
    counts: dict[str, int] = {}

    session = zc.open_session(zc.config_dict(mode="client", connect=args.connect))
    subscribers = []
    for key_expr, channel in topology.recorded_keys(spec, args.mode):
        cid = writer.bus_channel(channel)
        codec = get_codec(channel.encoding)
        counts[channel.name] = 0

        def on_sample(sample: zenoh.Sample, cid=cid, codec=codec, name=channel.name) -> None:
            q.put((time.time_ns(), cid, codec, name, sample.payload.to_bytes(), sample.timestamp))

        if channel.name in args.intercepted:
            original_cid = writer.bus_channel(channel, topic=layout.ORIGINAL_PREFIX + channel.key)

            def on_intercepted(sample: zenoh.Sample, cid=cid, codec=codec, name=channel.name,
                               original_cid=original_cid) -> None:
                att = sample.attachment.to_bytes() if sample.attachment is not None else None
                q.put((time.time_ns(), ("intercepted", cid, original_cid, att), codec, name,
                       sample.payload.to_bytes(), sample.timestamp))

            subscribers.append(session.declare_subscriber(topology.intercepted_key(channel.key), on_intercepted))
        else:
            subscribers.append(session.declare_subscriber(key_expr, on_sample))

    mutations_cid = writer.tool_channel(layout.MUTATIONS_TOPIC)
    twins = ViewableTwins(writer, {ch.name: ch for ch in spec.channels if ch.encoding == "json"})

    def on_tool_event(sample: zenoh.Sample) -> None:
        data = sample.payload.to_bytes()
        q.put((time.time_ns(), writer.events_channel, None, None, data, None))
        if b'"run_stopped"' in data:
            # Everything the tool forwarded before this event has reached us (one link, in order):
            # the tool may stop us now without losing a backlog.
            _report(CAUGHT_UP)

    def on_undeclared(sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)[len(topology.UNDECLARED_PREFIX) + 1:]
        q.put((time.time_ns(), ("undeclared", key, str(sample.encoding)), None, None,
               sample.payload.to_bytes(), sample.timestamp))

    subscribers.append(session.declare_subscriber(topology.EVENTS_KEY, on_tool_event))
    subscribers.append(session.declare_subscriber(f"{topology.UNDECLARED_PREFIX}/**", on_undeclared))

    write_thread = threading.Thread(target=_drain_or_exit, args=(args.out, q, writer, counts, mutations_cid, twins),
                                    daemon=True)
    write_thread.start()
    print("ready", flush=True)

    while not stopping:
        time.sleep(0.05)
    # A recorder must never outlive its run, whatever Zenoh does at shutdown.
    threading.Timer(SHUTDOWN_LIMIT_SECONDS, os._exit, args=(3,)).start()
    # Order matters: no more callbacks, write what is queued, finish the file;
    # only then close the session (which may wait on a peer that is gone).
    for sub in subscribers:
        sub.undeclare()
    q.put(_STOP)
    write_thread.join()
    if os.getppid() != tool_pid:
        writer.record(records.RunEnd(time.time_ns(), layout.TOOL_LOST))
    writer.finish()
    _report(json.dumps({"recorded": counts}))
    # No session.close(): the log is finished, and closing a session whose router is gone (the tool
    # killed, or the bus router) waits for Zenoh's timeouts; exiting drops the connection just as well.
    os._exit(0)  # the shutdown timer is a non-daemon thread


def _report(line: str) -> None:
    """One line to the tool; if the tool is gone (its end of the pipe closed) there is no one to tell."""
    try:
        print(line, flush=True)
    except (BrokenPipeError, OSError):
        pass


def _drain_or_exit(out: Path, *args) -> None:
    """Write until told to stop; if the log cannot be written (disk full, file size limit), say so and exit 4.

    The tool sees its recorder gone and withholds the verdict; every chunk
    written before the failure stays readable.
    """
    try:
        _drain(*args)
    except OSError as exc:
        print(f"recorder: cannot write the log {out}: {exc.strerror or exc}", file=sys.stderr, flush=True)
        os._exit(4)


def _drain(q: "queue.SimpleQueue", writer: LogWriter, counts: dict[str, int], mutations_cid: int,
           twins: ViewableTwins) -> None:
    undeclared_ids: dict[str, int] = {}
    while True:
        item = q.get()
        if item is _STOP:
            return
        log_time, cid, codec, name, data, ts = item
        publish_time = ts.get_time_as_ntp64().as_nanos() if ts is not None else log_time
        if isinstance(cid, tuple) and cid[0] == "intercepted":
            _, cid, original_cid, attachment = cid
            if attachment is not None:  # the proxy changed something: log it three ways
                if _write_intercepted(writer, cid, original_cid, mutations_cid, attachment, log_time, data,
                                      publish_time):
                    counts[name] += 1
                    if codec.name == "json":
                        twins.add(name, log_time, data, publish_time)  # a NaN mutation: viewable too
                continue
        if isinstance(cid, tuple):  # an undeclared key the proxy forwarded
            _, key, encoding = cid
            if key not in undeclared_ids:
                undeclared_ids[key] = writer.undeclared_channel(key, encoding)
            writer.message(undeclared_ids[key], log_time, data, publish_time)
            continue
        seq = writer.message(cid, log_time, data, publish_time)
        if codec is None:
            continue
        counts[name] += 1
        if codec.name == "json":
            twins.add(name, log_time, data, publish_time)
        try:
            codec.decode(data)
        except DecodeError as exc:
            writer.record(records.FlagRecord(log_time, name, seq, str(exc), len(data)), channel_id=writer.flags_channel)


def _write_intercepted(writer: LogWriter, cid: int, original_cid: int, mutations_cid: int, attachment: bytes,
                       log_time: int, data: bytes, publish_time: int) -> bool:
    """Original, delivered message and mutation event, cross-referenced; True if something was delivered."""
    event, original, delivered = read_intercept_record(attachment)
    original_seq = writer.message(original_cid, log_time, original, publish_time) if original is not None else None
    delivered_seq = writer.message(cid, log_time, data, publish_time) if delivered else None
    body = {**event, "original_sequence": original_seq, "delivered_sequence": delivered_seq}
    writer.message(mutations_cid, log_time, json.dumps(body, default=str).encode())
    return delivered


if __name__ == "__main__":
    sys.exit(main())
