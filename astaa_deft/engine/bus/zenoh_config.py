"""Zenoh session configurations the tool hands out and opens.

Every config built here has multicast scouting off and, unless the caller
passes other endpoints, only 127.0.0.1 endpoints: the tool must never talk to
anything but the machine it runs on unless a spec says so.
"""

from __future__ import annotations

import json
import socket
from pathlib import Path
from collections.abc import Iterable, Mapping

import zenoh

from astaa_deft.io.output_place import write_atomic
from astaa_deft.model.json import JsonObject

LOOPBACK = "127.0.0.1"


def free_port(host: str = LOOPBACK) -> int:
    """A TCP port that was free a moment ago (the OS picks it)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind((host, 0))
        return sock.getsockname()[1]


def loopback_endpoint(port: int | None = None) -> str:
    return f"tcp/{LOOPBACK}:{port if port is not None else free_port()}"


def config_dict(
    *,
    mode: str = "peer",
    listen: Iterable[str] = (),
    connect: Iterable[str] = (),
    namespace: str | None = None,
    gossip: bool = False,
    timestamping: bool = False,
) -> JsonObject:
    """A minimal Zenoh JSON5-compatible config as a plain dict."""
    scouting: JsonObject = {
        "multicast": {"enabled": False},
        "gossip": {"enabled": gossip},
    }
    cfg: JsonObject = {
        "mode": mode,
        "scouting": scouting,
        "listen": {"endpoints": list(listen)},
        "connect": {"endpoints": list(connect)},
    }
    if mode == "router" and not gossip:
        # A router waits scouting.delay (500 ms by default) at open for peers to scout; with
        # multicast and gossip off there are none to find, so that is half a second added to
        # every run's start (and every live minimisation test) for nothing.
        scouting["delay"] = 0
    if timestamping:
        cfg["timestamping"] = {"enabled": True}
    if namespace:
        cfg["namespace"] = namespace
    return cfg


def to_zenoh(cfg: Mapping[str, object], base_file: Path | None = None) -> zenoh.Config:
    """Build a zenoh.Config from a dict, optionally on top of the user's JSON5 file.

    Our keys win over the user's file only where we set them; multicast
    scouting is always forced off.
    """
    conf = zenoh.Config.from_file(str(base_file)) if base_file else zenoh.Config()
    for key, value in _flatten(cfg):
        conf.insert_json5(key, json.dumps(value))
    conf.insert_json5("scouting/multicast/enabled", "false")
    return conf


def write_config_file(cfg: Mapping[str, object], path: Path) -> Path:
    """Write a config as JSON (valid JSON5) for a module to load."""
    write_atomic(path, json.dumps(cfg, indent=2) + "\n")  # a new file, never through a link
    return path


def open_session(cfg: Mapping[str, object], base_file: Path | None = None) -> zenoh.Session:
    return zenoh.open(to_zenoh(cfg, base_file))


def _flatten(cfg: Mapping[str, object], prefix: str = "") -> Iterable[tuple[str, object]]:
    # insert_json5 on whole sub-objects would replace the user's sibling keys;
    # descend to leaves (lists are leaves) so only what we set is overwritten.
    for key, value in cfg.items():
        path = f"{prefix}/{key}" if prefix else key
        if isinstance(value, dict):
            yield from _flatten(value, path)
        else:
            yield path, value
