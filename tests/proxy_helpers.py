"""Run `astaa-deft proxy` as a real subprocess and inspect what it left behind."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

SUT_DIR = Path(__file__).parent / "sut"
ECHO_SPEC = SUT_DIR / "echo.yaml"


def proxy_cmd(spec: Path, *args: str) -> list[str]:
    return [sys.executable, "-m", "astaa_deft.cli", "proxy", "--spec", str(spec), *args]


def run_proxy(spec: Path, *args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run(proxy_cmd(spec, *args), capture_output=True, text=True, timeout=timeout)


def received(path: Path) -> list[tuple[str, bytes, str]]:
    """(key, payload, attachment hex) lines written by tests/sut/listener.py."""
    if not path.exists():
        return []
    out = []
    for line in path.read_text().split("\n")[:-1]:  # the last piece: empty, or a line still being written
        key, payload, att = line.split(" ")
        out.append((key, bytes.fromhex(payload), att))
    return out


def started_pids(run_dir: Path) -> dict[str, int]:
    return json.loads((run_dir / "processes.json").read_text())


def alive(pid: int) -> bool:
    """True if the process exists and is not a zombie."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().split(") ", 1)[1][0] != "Z"
    except OSError:
        return False
