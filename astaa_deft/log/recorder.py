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
from ..bus import zenoh_config as zc
from ..codecs import get_codec
from ..codecs.base import DecodeError
from ..spec.loader import load_spec
from . import layout
from .writer import LogWriter

_STOP = object()
SHUTDOWN_LIMIT_SECONDS = 20.0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="astaa-deft-recorder")
    ap.add_argument("--spec", required=True, type=Path)
    ap.add_argument("--mode", choices=("star", "passive"), required=True)
    ap.add_argument("--connect", action="append", required=True, help="the bus to record (a router or peer)")
    ap.add_argument("--out", required=True, type=Path)
    ap.add_argument("--meta", default="{}", help="JSON object stored as run metadata")
    ap.add_argument("--chunk-size", type=int, default=64 * 1024)
    ap.add_argument("--intercepted", action="append", default=[],
                    help="a channel the proxy may alter: record what it delivered, and the originals")
    args = ap.parse_args(argv)

    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())

    spec = load_spec(args.spec)
    writer = LogWriter(args.out, spec, chunk_size=args.chunk_size)
    writer.attachment(layout.SPEC_ATTACHMENT, spec.source_text.encode(), "application/yaml")
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

            def on_original(sample: zenoh.Sample, cid=original_cid) -> None:
                q.put((time.time_ns(), cid, None, None, sample.payload.to_bytes(), sample.timestamp))

            subscribers.append(session.declare_subscriber(topology.delivered_key(channel.key), on_sample))
            subscribers.append(session.declare_subscriber(topology.original_key(channel.key), on_original))
        else:
            subscribers.append(session.declare_subscriber(key_expr, on_sample))

    mutations_cid = writer.tool_channel(layout.MUTATIONS_TOPIC)

    def on_mutation(sample: zenoh.Sample) -> None:
        q.put((time.time_ns(), mutations_cid, None, None, sample.payload.to_bytes(), None))

    subscribers.append(session.declare_subscriber(topology.MUTATIONS_KEY, on_mutation))

    def on_tool_event(sample: zenoh.Sample) -> None:
        q.put((time.time_ns(), writer.events_channel, None, None, sample.payload.to_bytes(), None))

    def on_undeclared(sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)[len(topology.UNDECLARED_PREFIX) + 1:]
        q.put((time.time_ns(), ("undeclared", key, str(sample.encoding)), None, None,
               sample.payload.to_bytes(), sample.timestamp))

    subscribers.append(session.declare_subscriber(topology.EVENTS_KEY, on_tool_event))
    subscribers.append(session.declare_subscriber(f"{topology.UNDECLARED_PREFIX}/**", on_undeclared))

    write_thread = threading.Thread(target=_drain, args=(q, writer, counts), daemon=True)
    write_thread.start()
    print("ready", flush=True)

    stop.wait()
    # A recorder must never outlive its run, whatever Zenoh does at shutdown.
    threading.Timer(SHUTDOWN_LIMIT_SECONDS, os._exit, args=(3,)).start()
    # Order matters: no more callbacks, write what is queued, finish the file;
    # only then close the session (which may wait on a peer that is gone).
    for sub in subscribers:
        sub.undeclare()
    q.put(_STOP)
    write_thread.join()
    writer.finish()
    print(json.dumps({"recorded": counts}), flush=True)
    session.close()
    os._exit(0)  # the shutdown timer is a non-daemon thread


def _drain(q: "queue.SimpleQueue", writer: LogWriter, counts: dict[str, int]) -> None:
    undeclared_ids: dict[str, int] = {}
    while True:
        item = q.get()
        if item is _STOP:
            return
        log_time, cid, codec, name, data, ts = item
        publish_time = ts.get_time_as_ntp64().as_nanos() if ts is not None else log_time
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
        try:
            codec.decode(data)
        except DecodeError as exc:
            writer.event("undecodable", time_ns=log_time, channel_id=writer.flags_channel,
                         channel=name, sequence=seq, reason=str(exc), size=len(data))


if __name__ == "__main__":
    sys.exit(main())
