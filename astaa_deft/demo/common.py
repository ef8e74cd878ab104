"""Plumbing every demo module shares: command line, Zenoh session, JSON I/O, shutdown.

Each module is one process with one main thread that owns all of its state.
Zenoh delivers samples on its own threads; those threads only decode JSON
and queue the result (``Inbox``), so module logic never needs a lock and runs
in the order messages arrived.
"""

from __future__ import annotations

import argparse
import faulthandler
import json
import os
import queue
import signal
import sys
import traceback
from typing import Any
from collections.abc import Callable

import zenoh

DEFAULT_SCENARIO = "lane_follow"

# Spec channel name -> Zenoh key. Must match astaa_deft/data/specs/demo_av.yaml;
# the keys are plain: the tool's config may add a namespace the modules never see.
KEYS = {
    "obstacles": "demo/sim/obstacles",
    "localization": "demo/sim/localization",
    "traffic_light": "demo/sim/traffic_light",
    "routing": "demo/sim/routing",
    "status": "demo/sim/status",
    "prediction": "demo/prediction/obstacles",
    "trajectory": "demo/planning/trajectory",
    "command": "demo/control/command",
}


class Shutdown(BaseException):
    """Raised in the main thread by SIGTERM/SIGINT; a BaseException so no ``except Exception`` eats it."""


class ConfigError(RuntimeError):
    pass


def log(module: str, text: str) -> None:
    print(f"[{module}] {text}", file=sys.stderr, flush=True)


def parse_args(prog: str, description: str, argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog=prog, description=description)
    parser.add_argument(
        "--zenoh-config", metavar="PATH",
        help="Zenoh JSON5 config file (default: the file named by $ZENOH_CONFIG)",
    )
    parser.add_argument(
        "--scenario", default=DEFAULT_SCENARIO, metavar="NAME_OR_PATH",
        help=f"a bundled scenario's name or a scenario YAML file (default: {DEFAULT_SCENARIO})",
    )
    parser.add_argument(
        "--defects", choices=("on", "off"), default="on",
        help="seeded robustness defects (see astaa_deft/demo/README.md; default: on)",
    )
    args = parser.parse_args(argv)
    args.defects = args.defects == "on"
    return args


def load_zenoh_config(path: str | None) -> zenoh.Config:
    """The config the tool generated for us; modules never invent endpoints of their own."""
    if path:
        return zenoh.Config.from_file(path)
    if os.environ.get("ZENOH_CONFIG"):
        return zenoh.Config.from_env()
    raise ConfigError("no Zenoh config: pass --zenoh-config PATH or set ZENOH_CONFIG")


def install_shutdown_handlers() -> None:
    """SIGTERM and SIGINT interrupt the main thread once, wherever it is (even stuck in a loop)."""
    fired = False

    def handler(signum: int, frame: Any) -> None:
        nonlocal fired
        if not fired:  # a second signal must not interrupt the clean-up of the first
            fired = True
            raise Shutdown(signal.Signals(signum).name)

    signal.signal(signal.SIGTERM, handler)
    signal.signal(signal.SIGINT, handler)
    # `kill -USR1 <pid>` prints every thread's stack to stderr: the way to see where a module hangs.
    faulthandler.register(signal.SIGUSR1, all_threads=True)


def run_module(
    name: str,
    description: str,
    main: Callable[[zenoh.Session, argparse.Namespace], None],
    argv: list[str] | None = None,
) -> int:
    """Parse the command line, open the session, run ``main`` until a signal; the exit code.

    An exception from ``main`` is a crash: it prints its traceback and the
    process exits with code 1 at once, which is what a crash must look like to
    the tool. It does not close the session on the way down: a crashing node
    (a segfault) closes nothing, and a graceful close can take longer than a
    deadline on a loaded machine, so the exit would come after the silence it
    caused and the run would read as a hang.
    """
    args = parse_args(f"python -m astaa_deft.demo.{name}", description, argv)
    install_shutdown_handlers()
    zenoh.init_log_from_env_or("error")
    session = None
    try:
        session = zenoh.open(load_zenoh_config(args.zenoh_config))
        main(session, args)
    except Shutdown:
        pass
    except ConfigError as exc:
        log(name, str(exc))
        return 2
    except Exception:
        traceback.print_exc()
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(1)
    finally:
        if session is not None:
            session.close()
    return 0


def header(seq: int, stamp: float) -> dict[str, Any]:
    return {"seq": seq, "stamp": stamp}


class JsonPublisher:
    """One declared publisher per key, numbering its messages from 1 (``header.seq``)."""

    def __init__(self, session: zenoh.Session, key: str):
        self.key = key
        self._publisher = session.declare_publisher(key, encoding=zenoh.Encoding.APPLICATION_JSON)
        self._seq = 0

    def publish(self, body: dict[str, Any], stamp: float) -> dict[str, Any]:
        """Publish ``body`` under a fresh header; returns the message sent."""
        self._seq += 1
        message = {"header": header(self._seq, stamp), **body}
        self.publish_message(message)
        return message

    def publish_message(self, message: dict[str, Any]) -> None:
        """Publish a message that already carries its header (the planner numbers its own)."""
        # Plain json.dumps on purpose: NaN and Infinity go out as the tokens
        # NaN/Infinity, so a non-finite value is visible on the bus, not hidden.
        self._publisher.put(json.dumps(message))


class Inbox:
    """Subscriptions that feed one queue, drained by the module's main thread."""

    def __init__(self, session: zenoh.Session, module: str):
        self._session = session
        self._module = module
        self._queue: queue.SimpleQueue[tuple[str, dict[str, Any]]] = queue.SimpleQueue()
        self._subscribers: list[zenoh.Subscriber] = []  # keep them declared

    def subscribe(self, key: str, channel: str) -> None:
        def on_sample(sample: zenoh.Sample) -> None:
            try:
                message = json.loads(sample.payload.to_bytes())
            except (ValueError, UnicodeDecodeError) as exc:
                # Like a middleware that cannot deserialise: drop it, say so, keep going.
                log(self._module, f"dropped undecodable message on {key}: {exc}")
                return
            self._queue.put((channel, message))

        self._subscribers.append(self._session.declare_subscriber(key, on_sample))

    def get(self, timeout: float) -> tuple[str, dict[str, Any]] | None:
        """The next (channel, message), or None after ``timeout`` seconds without one."""
        try:
            return self._queue.get(timeout=timeout)
        except queue.Empty:
            return None

    def drain(self) -> list[tuple[str, dict[str, Any]]]:
        """Everything queued so far, oldest first, without waiting."""
        received = []
        while True:
            try:
                received.append(self._queue.get_nowait())
            except queue.Empty:
                return received
