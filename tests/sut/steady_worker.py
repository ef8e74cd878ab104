"""A test-SUT module for campaign tests: it burns CPU or sleeps, and can crash on chosen launches.

--burn 1: a busy loop (one core, like a sampling planner); 0: it sleeps.
--counter-dir DIR --fail-launches 2,3: every start takes the next launch number
(an atomically created file DIR/launch-N), and launches in the list exit with
code 3 after --fail-after seconds — a SUT that fails on some runs and not on
others, in an order a test fixes (one run at a time). Imports nothing from astaa-deft.
"""

import argparse
import os
import signal
import sys
import threading
import time

ap = argparse.ArgumentParser()
ap.add_argument("--burn", default="0")
ap.add_argument("--counter-dir", default="")
ap.add_argument("--fail-launches", default="")
ap.add_argument("--fail-after", type=float, default=0.8)
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


fail = False
if args.counter_dir:
    number = launch_number(args.counter_dir)
    fail = str(number) in args.fail_launches.split(",")
    print(f"worker: launch {number}{' (fails)' if fail else ''}", flush=True)
print("worker ready", flush=True)
started = time.monotonic()
while not stop.is_set():
    if fail and time.monotonic() - started >= args.fail_after:
        sys.stderr.write("worker: simulated crash\n")
        sys.exit(3)
    if args.burn == "1":
        deadline = time.monotonic() + 0.05
        while time.monotonic() < deadline:
            pass
    else:
        stop.wait(0.05)
