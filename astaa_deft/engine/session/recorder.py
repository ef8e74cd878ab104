"""The recorder: its own process, subscribed to the bus, writing the MCAP log.

It runs apart from the proxy because writing MCAP in the forwarding process
adds millisecond latency spikes (GIL); here it only costs a core. It stops
cleanly (``finish()``) on SIGTERM/SIGINT and when the tool that started it
dies — then first reading what was still on its way to it, until the bus is
quiet — so the log it leaves is complete unless the recorder itself is killed.

Started by the session as ``python -m astaa_deft.engine.session.recorder ARGS``
with the spec's text on stdin (the session's spec, not a file to re-read:
it may have been built in code, or come out of a log); prints ``ready`` on
stdout once subscribed and a JSON line of counts when done.

Kept warm: ``python -m astaa_deft.engine.session.recorder --warm [SPEC_FILE …]``
imports everything (and parses those specs) first, then waits for one line
on stdin — its ARGS as a JSON list — followed by the spec's text, and runs
as above. A campaign's case or a live minimisation test starts it while the
previous run still goes on, so a run does not wait for a Python start-up on
its critical path (seconds on a loaded machine). EOF instead of the line:
nobody needs it, it exits.

It belongs to the session, not to ``log/``: it joins transport (the bus
keys it subscribes to), the run's records (the mutations the proxy sends,
``model.records``) and the file format, which ``log/`` alone owns.

Threads: Zenoh's callbacks only queue typed items (``QueueItem``); one
writing thread writes them in arrival order (``_drain``).
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
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import zenoh

from astaa_deft.engine.bus import topology
from astaa_deft.engine.bus import zenoh_config as zc
from astaa_deft.io.codecs import get_codec
from astaa_deft.io.inputfile import DICTIONARY, POLICY, SPEC, read_input
from astaa_deft.io.codecs.base import Codec, DecodeError
from astaa_deft.io.codecs.rmw_attachment import parse_attachment
from astaa_deft.io.log import layout, records
from astaa_deft.io.log.viewable import ViewableTwins
from astaa_deft.io.log.writer import LogWriter
from astaa_deft.model.json import JsonObject
from astaa_deft.model.records import Mutation, RunMode
from astaa_deft.model.sut import Spec
from astaa_deft.engine.spec.loader import load_spec_text
import contextlib

try:  # a faster first answer to "does this JSON payload decode?" (see undecodable)
    import orjson as _orjson
except ImportError:  # pragma: no cover - a declared dependency; the stdlib alone gives the same verdicts
    _orjson = None  # type: ignore[assignment]
try:  # faster still: it validates without building Python objects (see undecodable)
    import simdjson as _simdjson
except ImportError:  # pragma: no cover - a declared dependency; orjson and the stdlib give the same verdicts
    _simdjson = None  # type: ignore[assignment]

_ORJSON_AS_STDLIB = (_orjson.OPT_PASSTHROUGH_DATETIME | _orjson.OPT_PASSTHROUGH_DATACLASS) if _orjson is not None else 0
# json.dumps(body, default=str) exactly, without building an encoder per call (half its cost on an event).
_EVENT_ENCODER = json.JSONEncoder(default=str)
TOOL_GONE_WAIT_SECONDS = 2.0  # an unannounced stop: how long to wait for the dying tool to show
CAUGHT_UP = "caught up"  # stdout line: the run_stopped event arrived, so did every message before it
SHUTDOWN_LIMIT_SECONDS = 20.0
# An unannounced stop (the tool died): the messages on their way to us are still read, until none came for
# QUIET_SECONDS (at most BACKLOG_LIMIT_SECONDS): a loaded recorder may be a second behind the consumers.
QUIET_SECONDS = 0.25
BACKLOG_LIMIT_SECONDS = 5.0


# -- what the subscriber callbacks queue for the writing thread -----------------------------------


@dataclass(frozen=True, kw_only=True)
class InterceptedChannel:
    """Where one intercepted channel's deliveries go in the log."""

    name: str
    codec: Codec
    delivered: int  # the channel's log id: what its consumers got
    original: int  # the log id of its originals (what the producer sent, where the proxy changed it)
    mutations: int  # the log id of the mutations topic


class BusMessage(NamedTuple):
    """A message on a declared channel, or (codec None) one of the tool's own events."""

    log_time: int
    channel_id: int
    codec: Codec | None
    name: str
    data: bytes
    source_time: int | zenoh.Timestamp | None  # rmw_zenoh's source time (ns), or the Zenoh timestamp


class InterceptedBatch(NamedTuple):
    """The deliveries of one intercepted channel the proxy sent together (``topology.pack_deliveries``)."""

    log_time: int
    channel: InterceptedChannel
    data: bytes


class UndeclaredMessage(NamedTuple):
    """A message on a key the spec does not declare, which the proxy forwarded."""

    log_time: int
    key: str
    encoding: str
    data: bytes
    source_time: zenoh.Timestamp | None


QueueItem = BusMessage | InterceptedBatch | UndeclaredMessage


class _Stop:
    """The writing thread's last item: everything before it is written."""


_STOP = _Stop()


def main(argv: list[str] | None = None, parsed: dict[tuple[str, str], object] | None = None) -> int:
    """Record one run (module doc); ``parsed``: specs parsed ahead (warm start), by (text, name).

    Returns only on a bad argument (argparse exits 2) or a warm recorder told
    to exit; a run ends this process itself, exit code 0 (4: the log could not
    be written, 3: the shutdown took longer than ``SHUTDOWN_LIMIT_SECONDS``).
    """
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--warm"]:
        return _warm(argv[1:])
    args = _arguments(argv)
    if args.log_file is not None:
        fd = os.open(args.log_file, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
        os.dup2(fd, 2)
        os.close(fd)

    tool_pid = os.getppid()  # if this changes, the tool died (and its death signal is what stops us)
    stopping: list[int] = []  # a signal handler must not take locks (Event.set could deadlock)
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda signum, _frame: stopping.append(signum))

    text = sys.stdin.read()
    spec = (parsed or {}).get((text, args.spec_name)) or load_spec_text(text, name=args.spec_name)
    assert isinstance(spec, Spec)
    writer = _open_log(args, spec)
    # Callbacks (one Python thread each, Zenoh's default) queue what they receive for one writing
    # thread (the alternatives measured worse: docs/performance.md, "records").
    q: queue.SimpleQueue[QueueItem | _Stop] = queue.SimpleQueue()
    counts = {channel.name: 0 for _, channel in topology.recorded_keys(spec, args.mode)}
    run_stopped: list[bool] = []  # the tool's orderly stop announced itself
    arrived = [0]  # messages received (the callbacks count them; a lost count between threads is harmless)
    session = zc.open_session(zc.config_dict(mode="client", connect=args.connect))
    subscribers = _subscribe(session, spec, args, writer, q=q, run_stopped=run_stopped, arrived=arrived)
    twins = ViewableTwins(writer, {ch.name: ch for ch in spec.channels if ch.encoding == "json"})
    write_thread = threading.Thread(target=_drain_or_exit, args=(args.out, q, _Sink(writer, counts, twins)),
                                    daemon=True)
    write_thread.start()
    print("ready", flush=True)

    while not stopping:
        time.sleep(0.05)
    if not run_stopped:  # no orderly end: what the tool forwarded before it died may still be on its way
        _read_backlog(arrived)
    _finish(subscribers, q, write_thread, writer, lost=lambda: _tool_lost(tool_pid, announced=bool(run_stopped)),
            counts=counts)
    return 0  # not reached: _finish exits the process


def _arguments(argv: list[str]) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog="astaa-deft-recorder")
    ap.add_argument("--spec-name", default="spec.yaml",
                    help="the spec's file name, for messages (its text is on stdin)")
    ap.add_argument("--mode", choices=[m.value for m in RunMode], required=True)
    ap.add_argument("--connect", action="append", required=True, help="the bus to record (a router or peer)")
    ap.add_argument("--out", required=True, type=Path)
    ap.add_argument("--meta", default="{}", help="JSON object stored as run metadata")
    ap.add_argument("--chunk-size", type=int, default=64 * 1024)
    ap.add_argument("--attach", action="append", default=[], metavar="NAME=PATH",
                    help="store this file in the log as an attachment (policy, dictionaries)")
    ap.add_argument("--intercepted", action="append", default=[],
                    help="a channel the proxy may alter: record what it delivered, and the originals")
    ap.add_argument("--log-file", type=Path,
                    help="write stderr here (a warm recorder was started before its run directory was known)")
    return ap.parse_args(argv)


def _open_log(args: argparse.Namespace, spec: Spec) -> LogWriter:
    """The log, with the spec, the attached files and the run's metadata written."""
    writer = LogWriter(args.out, spec, chunk_size=args.chunk_size)
    writer.attachment(layout.SPEC_ATTACHMENT, spec.source_text.encode(), "application/yaml")
    for item in args.attach:
        name, _, path = item.partition("=")
        policy = name.endswith(".xml")  # else a dictionary: both checked by the run before, read the same way
        writer.attachment(name, read_input(path, POLICY if policy else DICTIONARY),
                          "application/xml" if policy else "application/yaml")
    writer.metadata(layout.RUN_METADATA, {**json.loads(args.meta), "mode": args.mode})
    return writer


def _subscribe(session: zenoh.Session, spec: Spec, args: argparse.Namespace, writer: LogWriter, *,  # noqa: PLR0913
               q: queue.SimpleQueue[QueueItem | _Stop], run_stopped: list[bool],
               arrived: list[int]) -> list[zenoh.Subscriber]:
    """Subscribers for the recorded channels, the tool's events and undeclared keys, each queueing for ``q``.

    Creates the log's channels in the order logs have always had them: each
    recorded channel (its originals' channel after it), then the mutations topic.
    """
    recorded = []
    for key_expr, channel in topology.recorded_keys(spec, args.mode):
        cid = writer.bus_channel(channel)
        original_cid = (writer.bus_channel(channel, topic=layout.ORIGINAL_PREFIX + channel.key)
                        if channel.name in args.intercepted else None)
        recorded.append((key_expr, channel, cid, original_cid))
    mutations_cid = writer.tool_channel(layout.MUTATIONS_TOPIC)
    subscribers = []
    for key_expr, channel, cid, original_cid in recorded:
        codec = get_codec(channel.encoding)
        if original_cid is not None:
            target = InterceptedChannel(name=channel.name, codec=codec, delivered=cid, original=original_cid,
                                        mutations=mutations_cid)

            def on_intercepted(sample: zenoh.Sample, target: InterceptedChannel = target) -> None:
                arrived[0] += 1
                q.put(InterceptedBatch(time.time_ns(), target, sample.payload.to_bytes()))

            subscribers.append(session.declare_subscriber(topology.intercepted_key(channel.key), on_intercepted))
            continue
        ros2 = channel.encoding.startswith("cdr:")

        def on_sample(sample: zenoh.Sample, *, cid: int = cid, codec: Codec = codec, name: str = channel.name,
                      ros2: bool = ros2) -> None:  # the keywords: this channel's, bound now (Zenoh passes the sample)
            arrived[0] += 1
            q.put(BusMessage(time.time_ns(), cid, codec, name, sample.payload.to_bytes(),
                             _source_time(sample) if ros2 else sample.timestamp))

        subscribers.append(session.declare_subscriber(key_expr, on_sample))

    def on_tool_event(sample: zenoh.Sample) -> None:
        arrived[0] += 1
        data = sample.payload.to_bytes()
        q.put(BusMessage(time.time_ns(), writer.events_channel, None, "", data, None))
        if b'"run_stopped"' in data:
            run_stopped.append(True)
            # Everything the tool forwarded before this event has reached us (one link, in order):
            # the tool may stop us now without losing a backlog.
            _report(CAUGHT_UP)

    def on_undeclared(sample: zenoh.Sample) -> None:
        arrived[0] += 1
        key = str(sample.key_expr)[len(topology.UNDECLARED_PREFIX) + 1:]
        q.put(UndeclaredMessage(time.time_ns(), key, str(sample.encoding), sample.payload.to_bytes(),
                                sample.timestamp))

    subscribers.append(session.declare_subscriber(topology.EVENTS_KEY, on_tool_event))
    subscribers.append(session.declare_subscriber(f"{topology.UNDECLARED_PREFIX}/**", on_undeclared))
    return subscribers


def _read_backlog(arrived: list[int]) -> None:
    """Go on receiving until no message came for QUIET_SECONDS, or for BACKLOG_LIMIT_SECONDS in all.

    A tool killed outright announces no end: the messages it had forwarded to
    the consumers reach a loaded recorder up to a second later (its link's
    socket buffers), and every message a consumer got belongs in the log.
    """
    deadline = time.monotonic() + BACKLOG_LIMIT_SECONDS
    seen = arrived[0]
    while time.monotonic() < deadline:
        time.sleep(QUIET_SECONDS)
        if arrived[0] == seen:
            return
        seen = arrived[0]


def _finish(subscribers: list[zenoh.Subscriber], q: queue.SimpleQueue[QueueItem | _Stop],  # noqa: PLR0913
            write_thread: threading.Thread, writer: LogWriter, *, lost: Callable[[], bool],
            counts: dict[str, int]) -> None:
    """Stop receiving, write what is queued, finish the file, report the counts and exit (never returns).

    ``lost``: whether the tool died (asked once the queue is written: a dying tool shows late).
    """
    # A recorder must never outlive its run, whatever Zenoh does at shutdown.
    threading.Timer(SHUTDOWN_LIMIT_SECONDS, os._exit, args=(3,)).start()
    # Order matters: no more callbacks, write what is queued, finish the file;
    # only then close the session (which may wait on a peer that is gone).
    for sub in subscribers:
        sub.undeclare()
    q.put(_STOP)
    write_thread.join()
    if lost():
        writer.record(records.RunEnd(time.time_ns(), layout.TOOL_LOST))
    writer.finish()
    _report(json.dumps({"recorded": counts}))
    # No session.close(): the log is finished, and closing a session whose router is gone (the tool
    # killed, or the bus router) waits for Zenoh's timeouts; exiting drops the connection just as well.
    os._exit(0)  # the shutdown timer is a non-daemon thread


def _warm(spec_files: list[str]) -> int:
    """Wait, imports done and ``spec_files`` parsed, for the ARGS line on stdin; then run (module doc)."""
    parsed: dict[tuple[str, str], object] = {}
    for name in spec_files:
        with contextlib.suppress(Exception):  # a spec that does not parse is reported when the run reads it
            text = read_input(name, SPEC).decode("utf-8")
            parsed[(text, Path(name).name)] = load_spec_text(text, name=Path(name).name)
    return await_arguments(parsed)


def await_arguments(parsed: dict[tuple[str, str], object]) -> int:
    """A warm recorder's wait for its ARGS line on stdin, then its run (``parsed``: specs parsed ahead)."""
    line = sys.stdin.readline()
    if not line.strip():
        return 0
    return main(json.loads(line), parsed)


def _tool_lost(tool_pid: int, announced: bool) -> bool:
    """Whether the tool died (this process was stopped by its death, not by its orderly end).

    A changed parent says so at once. But the stop can come before the kernel
    has moved this process to a new parent: the reaper sees the tool's pipe
    close, and a killed tool closes its files before it is reparented from.
    So a stop the tool did not announce (no run_stopped event) waits, briefly,
    for the tool to show itself gone or dying.
    """
    if os.getppid() != tool_pid:
        return True
    if announced:
        return False
    deadline = time.monotonic() + TOOL_GONE_WAIT_SECONDS
    while time.monotonic() < deadline:
        if os.getppid() != tool_pid or _state(tool_pid) in (None, "Z", "X"):
            return True
        time.sleep(0.01)
    return False


def _state(pid: int) -> str | None:
    """The process state letter from /proc (None: no such process)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return stat.rsplit(")", 1)[-1].split()[0]


def _report(line: str) -> None:
    """One line to the tool; if the tool is gone (its end of the pipe closed) there is no one to tell."""
    with contextlib.suppress(BrokenPipeError, OSError):
        print(line, flush=True)


@dataclass
class _Sink:
    """What the writing thread writes to, and counts (touched by that thread only)."""

    writer: LogWriter
    counts: dict[str, int]  # messages recorded per declared channel
    twins: ViewableTwins


def _drain_or_exit(out: Path, q: queue.SimpleQueue[QueueItem | _Stop], sink: _Sink) -> None:
    """Write until told to stop; if the log cannot be written (disk full, file size limit), say so and exit 4.

    The tool sees its recorder gone and withholds the verdict; every chunk
    written before the failure stays readable.
    """
    try:
        _drain(q, sink)
    except OSError as exc:
        print(f"recorder: cannot write the log {out}: {exc.strerror or exc}", file=sys.stderr, flush=True)
        os._exit(4)


def _drain(q: queue.SimpleQueue[QueueItem | _Stop], sink: _Sink) -> None:
    """Write what the callbacks queued, in arrival order; the common case (a declared channel) first and short."""
    writer, counts, twins = sink.writer, sink.counts, sink.twins
    undeclared_ids: dict[str, int] = {}
    message, get = writer.message, q.get
    json_object = _JsonObjectCheck() if _simdjson is not None else None  # this thread's own parser
    while True:
        item = get()
        if type(item) is BusMessage:
            log_time, cid, codec, name, data, ts = item
            seq = message(cid, log_time, data, _publish_time(ts, log_time))
            if codec is None:  # the tool's own event
                continue
            counts[name] += 1
            if codec.name == "json":
                # The twins' own first check, without their call (_may_hold_nan inline: it runs per message).
                if (78 in data and b"NaN" in data) or (73 in data and b"Infinity" in data):
                    twins.add(name, log_time, data, _publish_time(ts, log_time))  # a NaN on the wire: viewable too
                if json_object is not None and len(data) < FAST_JSON_LIMIT and json_object(data):
                    continue  # undecodable's first answer, without its call
            reason = undecodable(codec, data)
            if reason is not None:
                writer.record(
                    records.FlagRecord(time_ns=log_time, channel=name, sequence=seq, reason=reason, size=len(data)),
                    channel_id=writer.flags_channel)
        elif type(item) is InterceptedBatch:
            _write_batch(sink, item.channel, item.data, item.log_time)
        elif type(item) is UndeclaredMessage:  # an undeclared key the proxy forwarded
            if item.key not in undeclared_ids:
                undeclared_ids[item.key] = writer.undeclared_channel(item.key, item.encoding)
            message(undeclared_ids[item.key], item.log_time, item.data, _publish_time(item.source_time, item.log_time))
        else:
            return  # _STOP


def _publish_time(source: int | zenoh.Timestamp | None, log_time: int) -> int:
    """A message's publish time: the rmw_zenoh source time (ns) of a ROS 2 message, else the Zenoh timestamp."""
    if source is None:
        return log_time
    return source if type(source) is int else source.get_time_as_ntp64().as_nanos()  # type: ignore[union-attr]


# A JSON document this short cannot nest deeply enough to exhaust the stdlib parser's recursion
# limit (~1000 levels), the one case orjson and simdjson (limit 1024 each) accept and the stdlib may not.
FAST_JSON_LIMIT = 1800


class _JsonObjectCheck:
    """Does simdjson read ``data`` as a JSON object? (One parser per thread: simdjson's parsers are not shared.)

    simdjson validates strict RFC 8259 JSON (UTF-8, escapes, numbers) without
    building Python objects (docs/performance.md, "records"). What it accepts, the stdlib accepts
    too (it refuses NaN tokens, lone surrogates, integers beyond 64 bits,
    numbers beyond a double), but for a byte order mark, which it skips and
    is refused here; tests/test_recorder.py holds it to the codec.
    """

    def __init__(self) -> None:
        self._parser = _simdjson.Parser()
        self._object = _simdjson.Object

    def __call__(self, data: bytes) -> bool:
        if data.startswith(b"\xef\xbb\xbf"):  # simdjson skips a UTF-8 byte order mark; the stdlib refuses it
            return False
        try:
            document = self._parser.parse(data)
        except (ValueError, RuntimeError):  # invalid (UnicodeDecodeError included), or the parser busy
            return False
        is_object = type(document) is self._object
        del document  # simdjson reuses the parser's memory only once its documents are gone
        return is_object


_checks = threading.local()


def undecodable(codec: Codec, data: bytes) -> str | None:
    """Why ``codec`` cannot decode ``data`` (the flag's reason), or None if it can.

    The verdict is the codec's own; for short JSON payloads simdjson, then
    orjson, answer first when they accept an object (whatever they accept,
    the stdlib's parser accepts too: it is the more lenient one, see
    tests/test_recorder.py), and the codec decides everything else.
    """
    if _simdjson is not None and codec.name == "json" and len(data) < FAST_JSON_LIMIT:
        check = getattr(_checks, "json_object", None)
        if check is None:
            check = _checks.json_object = _JsonObjectCheck()
        if check(data):
            return None
    if _orjson is not None and codec.name == "json" and len(data) < FAST_JSON_LIMIT:
        try:
            if type(_orjson.loads(data)) is dict:
                return None
        except _orjson.JSONDecodeError:
            pass
    try:
        codec.decode(data)
    except DecodeError as exc:
        return str(exc)
    return None


def _may_hold_nan(data: bytes) -> bool:
    """The twins' own first check (NaN or Infinity in the bytes), each search only where its first letter occurs.

    (Why: docs/performance.md, "records".)
    """
    return (78 in data and b"NaN" in data) or (73 in data and b"Infinity" in data)  # 78: "N", 73: "I"


class _Delivery(NamedTuple):
    """One intercepted delivery as the proxy framed it (``topology.pack_deliveries``)."""

    time_ns: int  # when the proxy delivered it (when the consumers got it)
    payload: bytes
    original: bytes | None  # the real message it was made from, where it differs
    delivered: bool  # False: dropped (only the mutation is logged)
    event: topology.WireEvent | None  # what the proxy changed; None: delivered untouched


def _write_batch(sink: _Sink, target: InterceptedChannel, data: bytes, received_ns: int) -> None:
    """The deliveries of one intercepted channel the proxy sent together, each logged when it was delivered."""
    writer = sink.writer
    try:
        rows = topology.unpack_deliveries(data)
    except ValueError as exc:
        writer.record(
            records.FlagRecord(time_ns=received_ns, channel=target.name, sequence=None, reason=str(exc),
                               size=len(data)),
            channel_id=writer.flags_channel)
        return
    json_twins = target.codec.name == "json"
    for row in rows:
        delivery = _Delivery._make(row)
        time_ns, payload = delivery.time_ns, delivery.payload
        if delivery.event is not None:  # the proxy changed something: log it three ways
            if _write_mutation(writer, target, delivery, publish_time=time_ns):
                sink.counts[target.name] += 1
                if json_twins and _may_hold_nan(payload):
                    sink.twins.add(target.name, time_ns, payload, time_ns)  # a NaN mutation: viewable too
            continue
        seq = writer.message(target.delivered, time_ns, payload, time_ns)
        sink.counts[target.name] += 1
        if json_twins and _may_hold_nan(payload):
            sink.twins.add(target.name, time_ns, payload, time_ns)
        reason = undecodable(target.codec, payload)
        if reason is not None:
            writer.record(
                records.FlagRecord(time_ns=time_ns, channel=target.name, sequence=seq, reason=reason,
                                   size=len(payload)),
                channel_id=writer.flags_channel)


def _source_time(sample: zenoh.Sample) -> int | zenoh.Timestamp | None:
    """A ROS 2 message's publish time: rmw_zenoh's source timestamp, else the Zenoh timestamp."""
    attachment = parse_attachment(sample.attachment.to_bytes()) if sample.attachment is not None else None
    return attachment.source_time_ns if attachment is not None else sample.timestamp


def _write_intercepted(writer: LogWriter, target: InterceptedChannel, attachment: bytes, data: bytes, *,
                       log_time: int, publish_time: int) -> bool:
    """One delivery as ``topology.intercept_record`` frames it (see ``_write_mutation``); flagged if malformed."""
    try:
        wire, original, delivered = topology.read_intercept_record(attachment)
    except ValueError as exc:
        writer.record(
            records.FlagRecord(time_ns=log_time, channel=target.name, sequence=None, reason=str(exc),
                               size=len(attachment)),
            channel_id=writer.flags_channel)
        return False
    return _write_mutation(writer, target, _Delivery(log_time, data, original, delivered, wire),
                           publish_time=publish_time)


def _write_mutation(writer: LogWriter, target: InterceptedChannel, delivery: _Delivery, *, publish_time: int) -> bool:
    """Original, delivered message and mutation, cross-referenced; True if something was delivered."""
    log_time, original = delivery.time_ns, delivery.original
    assert delivery.event is not None  # (called for changed deliveries only)
    original_seq = writer.message(target.original, log_time, original, publish_time) if original is not None else None
    delivered_seq = (writer.message(target.delivered, log_time, delivery.payload, publish_time)
                     if delivery.delivered else None)
    body = records.MutationRecord.logged(event_json(delivery.event), original_seq, delivered_seq)
    writer.message(target.mutations, log_time, _event_text(body))
    return delivery.delivered


def _event_text(body: JsonObject) -> bytes:
    """A mutation's JSON text: orjson's compact UTF-8 where it can (docs/performance.md, "records"), else the stdlib's.

    Both read back to the same object (the event's values are strict JSON
    data, see ``to_tagged``; anything else is written as ``str`` by both);
    orjson refuses only what it cannot write exactly (integers beyond 64
    bits), which the stdlib then writes. Dates and dataclasses go to ``str``
    as with the stdlib (orjson would write its own form of them).
    """
    if _orjson is not None:
        try:
            return _orjson.dumps(body, default=str, option=_ORJSON_AS_STDLIB)
        except TypeError:  # orjson.JSONEncodeError: an integer beyond 64 bits, a nesting too deep
            pass
    return _EVENT_ENCODER.encode(body).encode()


def event_json(wire: topology.WireEvent) -> JsonObject:
    """A mutation's JSON form (``Mutation.to_json``), from what the proxy sent."""
    value = wire.value
    if isinstance(value, dict):  # the form EVENT_JSON (read_intercept_record checks the JSON is an object)
        return dict(value)
    return Mutation.row_json(value)  # the compact form (topology.intercept_record)


if __name__ == "__main__":
    sys.exit(main())
