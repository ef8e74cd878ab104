"""A controller partner of tick_sim.py: answers each ego message with a command on sim/command."""

import json
import signal
import threading

import zenoh

stop = threading.Event()
signal.signal(signal.SIGTERM, lambda *_: stop.set())
signal.signal(signal.SIGINT, lambda *_: stop.set())
session = zenoh.open(zenoh.Config.from_env())
pub = session.declare_publisher("sim/command")


def on_ego(sample) -> None:
    ego = json.loads(sample.payload.to_bytes())
    pub.put(json.dumps({"header": ego["header"], "acceleration": 0.0}).encode())


sub = session.declare_subscriber("sim/ego", on_ego)
print("controller ready", flush=True)
stop.wait()
sub.undeclare()
session.close()
