"""A third-party-style Zenoh module for liveliness and request-reply: imports nothing from astaa-deft.

--token KEY      declare a liveliness token on KEY (after --delay seconds)
--serve KEY      answer queries on KEY with b"echo:" + the query's payload
--wait-token KEY wait for a liveliness token matching KEY; write "token <key>" to OUT
--call KEY       query KEY (payload --ask) until a reply comes or --patience passes;
                 write "reply <key> <payload>" or "noreply" to OUT
Idles until terminated.
"""

import argparse
import signal
import threading
import time

import zenoh

ap = argparse.ArgumentParser()
ap.add_argument("--token", action="append", default=[])
ap.add_argument("--serve", action="append", default=[])
ap.add_argument("--wait-token", action="append", default=[])
ap.add_argument("--call", action="append", default=[])
ap.add_argument("--ask", default="hello")
ap.add_argument("--delay", type=float, default=0.0)
ap.add_argument("--patience", type=float, default=6.0)
ap.add_argument("--out", default="")
args = ap.parse_args()

stop = threading.Event()
signal.signal(signal.SIGTERM, lambda *_: stop.set())
signal.signal(signal.SIGINT, lambda *_: stop.set())
out = open(args.out, "w", buffering=1) if args.out else None
lock = threading.Lock()


def write(line):
    with lock:
        out.write(line + "\n")


session = zenoh.open(zenoh.Config.from_env())
keep = []
for key in args.serve:
    keep.append(session.declare_queryable(
        key, lambda q: q.reply(q.key_expr, b"echo:" + (q.payload.to_bytes() if q.payload is not None else b""))))
for key in args.wait_token:
    keep.append(session.liveliness().declare_subscriber(
        key, lambda s: write(f"token {s.key_expr}") if s.kind == zenoh.SampleKind.PUT else None, history=True))
print("peer: ready", flush=True)
time.sleep(args.delay)
for key in args.token:
    keep.append(session.liveliness().declare_token(key))
for key in args.call:
    deadline = time.monotonic() + args.patience
    answer = None
    while answer is None and time.monotonic() < deadline and not stop.is_set():
        for reply in session.get(key, payload=args.ask.encode(), timeout=1.0):
            if reply.ok is not None:
                answer = (str(reply.ok.key_expr), reply.ok.payload.to_bytes().decode())
        if answer is None:
            time.sleep(0.1)
    write(f"reply {answer[0]} {answer[1]}" if answer else "noreply")
stop.wait()
session.close()
