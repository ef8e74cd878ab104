"""Shared fixtures: real Zenoh sessions on loopback, never multicast."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Callable

import pytest

from astaa_deft.engine.bus import zenoh_config as zc


@pytest.fixture
def zenoh_router():
    """A Zenoh router session on a free 127.0.0.1 port; yields (session, endpoint)."""
    endpoint = zc.loopback_endpoint()
    session = zc.open_session(zc.config_dict(mode="router", listen=[endpoint]))
    try:
        yield session, endpoint
    finally:
        session.close()


@pytest.fixture
def client_config_file(tmp_path: Path, zenoh_router) -> Callable[..., Path]:
    """Write a client config (connects to the test router) and return its path."""
    _, endpoint = zenoh_router
    counter = iter(range(10**6))

    def make(namespace: str | None = None) -> Path:
        cfg = zc.config_dict(mode="client", connect=[endpoint], namespace=namespace)
        return zc.write_config_file(cfg, tmp_path / f"zenoh-{next(counter)}.json5")

    return make


def wait_for(predicate: Callable[[], bool], timeout: float = 10.0, step: float = 0.02) -> bool:
    """Poll until predicate() is true or the timeout passes; returns the last value."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(step)
    return predicate()


def json_bytes(value) -> bytes:
    return json.dumps(value).encode()
