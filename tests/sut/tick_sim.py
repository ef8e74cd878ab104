"""A third-party-style simulator: each tick it publishes the ego, then --split-ms later the other vehicles.

Imports nothing from astaa-deft; finds its Zenoh config through ZENOH_CONFIG.
Both messages of a tick carry the tick's number (header.seq) and the
simulator's time (sim_time). One vehicle (id 14) drives --clearance metres
ahead of the ego at the ego's speed (negative: overlapping). After --ticks
ticks the simulator publishes nothing more and exits (code 0) --teardown
seconds later, as a real simulator writing its results and closing its
sessions does.
"""

import argparse
import json
import signal
import sys
import threading
import time

import zenoh

ap = argparse.ArgumentParser()
ap.add_argument("--rate", type=float, default=15.0)
ap.add_argument("--ticks", type=int, default=30)
ap.add_argument("--split-ms", type=float, default=20.0)
ap.add_argument("--clearance", type=float, default=0.1)
ap.add_argument("--speed", type=float, default=10.0)
ap.add_argument("--start-delay", type=float, default=0.3)
ap.add_argument("--teardown", type=float, default=0.3, help="seconds its exit takes after the last tick (results"
                " written, sessions closed), as a real simulator's does")
args = ap.parse_args()

EGO_LENGTH, VEHICLE_LENGTH = 4.5, 4.5
stop = threading.Event()
signal.signal(signal.SIGTERM, lambda *_: stop.set())
signal.signal(signal.SIGINT, lambda *_: stop.set())

session = zenoh.open(zenoh.Config.from_env())
ego_pub = session.declare_publisher("sim/ego")
vehicles_pub = session.declare_publisher("sim/vehicles")
time.sleep(args.start_delay)
period = 1.0 / args.rate
start = time.monotonic()
for tick in range(1, args.ticks + 1):
    if stop.is_set():
        break
    t = tick * period  # the simulator's clock
    x = args.speed * t
    header = {"seq": tick, "stamp": t}
    ego_pub.put(json.dumps({"header": header, "sim_time": t, "x": x, "y": 0.0, "heading": 0.0}).encode())
    time.sleep(args.split_ms / 1000.0)
    ahead = x + (EGO_LENGTH + VEHICLE_LENGTH) / 2 + args.clearance
    vehicle = {"id": 14, "x": ahead, "y": 0.0, "heading": 0.0, "length": VEHICLE_LENGTH, "width": 1.9}
    vehicles_pub.put(json.dumps({"header": header, "sim_time": t, "vehicles": [vehicle]}).encode())
    if tick < args.ticks:
        stop.wait(max(0.0, start + tick * period - time.monotonic()))
print(f"tick_sim: {tick} ticks, clearance {args.clearance} m", flush=True)
time.sleep(args.teardown)  # writing its results, closing its sessions: silent, and no more ticks
sys.exit(0)  # the scenario is over
