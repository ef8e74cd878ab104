"""Joins after --delay seconds, then acknowledges every tick (tests/sut/anchored.yaml)."""

import argparse
import json
import signal
import threading
import time

import zenoh

ap = argparse.ArgumentParser()
ap.add_argument("--delay", type=float, default=0.2)
args = ap.parse_args()
stop = threading.Event()
signal.signal(signal.SIGTERM, lambda *_: stop.set())
signal.signal(signal.SIGINT, lambda *_: stop.set())
time.sleep(args.delay)
session = zenoh.open(zenoh.Config.from_env())
pub = session.declare_publisher("anchored/ack")
count = 0
lock = threading.Lock()


def on_tick(sample):
    global count
    tick = json.loads(sample.payload.to_bytes())
    with lock:
        count += 1
        pub.put(json.dumps({"seq": count, "tick": tick["seq"]}).encode(), encoding=zenoh.Encoding.APPLICATION_JSON)


sub = session.declare_subscriber("anchored/tick", on_tick)
stop.wait()
sub.undeclare()
session.close()
