"""A two-stage test SUT (tests/sut/pipe.yaml): 'source' publishes a pose at 20 Hz, 'relay' turns each pose into
a command (speed = x + y). A non-finite pose field makes a non-finite command: the relay is to blame.
Imports nothing from astaa-deft; finds its Zenoh config through ZENOH_CONFIG."""

import argparse
import json
import signal
import threading
import time

import zenoh

ap = argparse.ArgumentParser()
ap.add_argument("--mode", choices=("source", "relay"), required=True)
ap.add_argument("--seconds", type=float, default=4.0)
args = ap.parse_args()

stop = threading.Event()
signal.signal(signal.SIGTERM, lambda *_: stop.set())
signal.signal(signal.SIGINT, lambda *_: stop.set())
session = zenoh.open(zenoh.Config.from_env())

if args.mode == "relay":
    pub = session.declare_publisher("pipe/command")

    def on_pose(sample) -> None:
        try:
            pose = json.loads(sample.payload.to_bytes())
            speed = float(pose["x"]) + float(pose["y"])
        except (ValueError, KeyError, TypeError):
            return
        pub.put(json.dumps({"header": pose.get("header", {}), "speed": speed}).encode())

    sub = session.declare_subscriber("pipe/pose", on_pose)
    print("relay ready", flush=True)
    stop.wait()
    sub.undeclare()
else:
    pub = session.declare_publisher("pipe/pose")
    time.sleep(0.3)
    i, t0 = 0, time.monotonic()
    while not stop.is_set() and time.monotonic() - t0 < args.seconds:
        i += 1
        pub.put(json.dumps({"header": {"seq": i, "stamp": time.time()}, "x": 0.01 * i, "y": 1.0, "v": 2.0}).encode())
        stop.wait(0.05)
session.close()
