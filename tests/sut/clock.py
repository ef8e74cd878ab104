"""Ticks at 50 Hz from its start; counts the acknowledgements it receives (tests/sut/anchored.yaml)."""

import json
import signal
import threading
import time

import zenoh

stop = threading.Event()
signal.signal(signal.SIGTERM, lambda *_: stop.set())
signal.signal(signal.SIGINT, lambda *_: stop.set())
acks = 0
lock = threading.Lock()


def on_ack(sample):
    global acks
    with lock:
        acks += 1


session = zenoh.open(zenoh.Config.from_env())
sub = session.declare_subscriber("anchored/ack", on_ack)
pub = session.declare_publisher("anchored/tick")
seq = 0
next_t = time.monotonic()
while not stop.is_set():
    seq += 1
    with lock:
        seen = acks
    pub.put(json.dumps({"seq": seq, "acks": seen, "value": 0.0}).encode(), encoding=zenoh.Encoding.APPLICATION_JSON)
    next_t += 0.02
    stop.wait(max(0.0, next_t - time.monotonic()))
sub.undeclare()
session.close()
