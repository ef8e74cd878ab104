"""A test-SUT module for campaign tests: it burns CPU or sleeps, and can crash on chosen launches.

--burn 1: a busy loop (one core, like a sampling planner); 0: it sleeps.
--crash-on-nan 1: exit with code 3 on a non-finite value on --fail-key (a bug a test case can trigger).
--counter-dir DIR --fail-launches 2,3: every start takes the next launch number
(an atomically created file DIR/launch-N), and launches in the list exit with
code 3 --fail-after seconds after the first message on --fail-key (counted from
the bus, so a test case's early mutation comes first, however slowly each
process starts) — a SUT that fails on some runs and not on others, in an order
a test fixes (one run at a time). Imports nothing from astaa-deft.
"""

import argparse
import json
import math
import os
import signal
import sys
import threading
import time
import traceback

ap = argparse.ArgumentParser()
ap.add_argument("--burn", default="0")
ap.add_argument("--counter-dir", default="")
ap.add_argument("--fail-launches", default="")
ap.add_argument("--fail-after", type=float, default=0.8)
ap.add_argument("--fail-key", default="")
ap.add_argument("--crash-on-nan", default="0", help="1: exit with code 3 on a non-finite 'value' on --fail-key")
ap.add_argument("--raise-launches", default="", help="launches that log a KeyError raised in step, --fail-after"
                " seconds in, and carry on")
ap.add_argument("--late-launches", default="", help="launches that log a ValueError raised in finish_route,"
                " --late-after seconds in, and carry on")
ap.add_argument("--late-after", type=float, default=2.5)
args = ap.parse_args()

stop = threading.Event()
signal.signal(signal.SIGTERM, lambda *_: stop.set())


def launch_number(directory: str) -> int:
    n = 1
    while True:
        try:
            os.close(os.open(os.path.join(directory, f"launch-{n}"), os.O_CREAT | os.O_EXCL | os.O_WRONLY))
            return n
        except FileExistsError:
            n += 1


fail = raises = late = False
if args.counter_dir:
    number = launch_number(args.counter_dir)
    fail = str(number) in args.fail_launches.split(",")
    raises = str(number) in args.raise_launches.split(",")
    late = str(number) in args.late_launches.split(",")
    print(f"worker: launch {number}{' (fails)' if fail else ''}", flush=True)


def step(world: dict) -> float:
    return world["lane"]  # KeyError: the early bug a test case triggers


def finish_route(remaining: float) -> float:
    if remaining <= 0:
        raise ValueError("route already finished")  # the late error of an unmutated run
    return remaining


def logged(call, *args) -> None:
    try:
        call(*args)
    except Exception:  # noqa: BLE001 - logged, and the worker carries on, as many stacks do
        traceback.print_exc()
        sys.stderr.flush()
first_message = threading.Event()
non_finite = threading.Event()


def on_sample(sample) -> None:
    first_message.set()
    try:
        value = json.loads(sample.payload.to_bytes())["value"]
    except (ValueError, KeyError, TypeError):
        return
    if isinstance(value, float) and not math.isfinite(value):
        non_finite.set()


crash_on_nan = args.crash_on_nan == "1"
if args.fail_key and (fail or crash_on_nan or raises or late):
    import zenoh

    session = zenoh.open(zenoh.Config.from_env())
    subscriber = session.declare_subscriber(args.fail_key, on_sample)
if not (fail or raises or late):
    first_message.set()
print("worker ready", flush=True)
first_message.wait()
started = time.monotonic()
while not stop.is_set():
    if raises and time.monotonic() - started >= args.fail_after:
        raises = False
        logged(step, {})
    if late and time.monotonic() - started >= args.late_after:
        late = False
        logged(finish_route, 0.0)
    if (fail and time.monotonic() - started >= args.fail_after) or (crash_on_nan and non_finite.is_set()):
        sys.stderr.write("worker: simulated crash\n")
        sys.stderr.flush()
        os._exit(3)  # at once: an open Zenoh session would hold a normal exit
    if args.burn == "1":
        deadline = time.monotonic() + 0.05
        while time.monotonic() < deadline:
            pass
    else:
        stop.wait(0.05)
