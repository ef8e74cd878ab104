"""The SUT's bus in passive runs: a Zenoh router in a process of its own.

Passive mode must add nothing to the SUT's message path, so the tool does
not route: this process plays the part `zenohd` plays in a deployment
(routing happens in Zenoh's native threads here, never in the tool's Python),
and the tool and its recorder attach to it as ordinary clients.

    python -m astaa_deft.engine.bus.router --listen tcp/127.0.0.1:PORT
prints ``ready`` once listening and runs until SIGTERM/SIGINT.
"""

from __future__ import annotations

import argparse
import signal
import sys
import time

from astaa_deft.engine.bus import zenoh_config as zc


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="astaa-deft-router")
    ap.add_argument("--listen", action="append", required=True)
    args = ap.parse_args(argv)
    stopping: list[int] = []  # a signal handler must not take locks (Event.set could deadlock)
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda signum, _frame: stopping.append(signum))
    session = zc.open_session(zc.config_dict(mode="router", listen=args.listen))
    print("ready", flush=True)
    while not stopping:
        time.sleep(0.05)
    session.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
