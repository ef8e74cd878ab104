"""What both nodes share: where the Zenoh router is, and local message definitions.

The nodes are ordinary zenoh-ros2-sdk programs and import nothing from
astaa-deft. Like rmw_zenoh nodes they take their Zenoh session config from
ZENOH_SESSION_CONFIG_URI; zenoh-ros2-sdk then replaces the config's connect
endpoints with its own router_ip/router_port arguments, so we pass the
endpoint the config file names. Message definitions come from ./msg (the SDK
would otherwise download them).
"""

import json
import os
import signal
import threading
from pathlib import Path

HERE = Path(__file__).resolve().parent


def router_address() -> tuple[str, int]:
    """(ip, port) of the first connect endpoint in the session config, else rmw_zenoh's default."""
    uri = os.environ.get("ZENOH_SESSION_CONFIG_URI", "")
    if uri:
        with open(uri) as fh:
            endpoints = json.load(fh).get("connect", {}).get("endpoints", [])
        if endpoints:  # "tcp/127.0.0.1:PORT"
            host, _, port = endpoints[0].split("/", 1)[1].rpartition(":")
            return host, int(port)
    return "127.0.0.1", 7447


def use_local_definitions() -> None:
    from zenoh_ros2_sdk import get_registry

    get_registry(str(HERE / "msg"))  # the first call fixes where the SDK looks


def stop_event() -> threading.Event:
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    return stop
