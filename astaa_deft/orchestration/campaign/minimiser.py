"""The one adapter between a campaign and minimisation: minimise a bucket's first failing run.

It runs ``astaa-deft minimise`` (:func:`astaa_deft.analysis.minimise.workflow.minimise_log`)
as a child process in its own session over the failing run's log: a
minimisation re-runs the SUT many times, so a hard time bound and a process
group the campaign can stop are worth more than an in-process call.
"""

from __future__ import annotations

import json
import subprocess
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from astaa_deft.engine.bus import process_launch
from astaa_deft.engine.bus.processes import python_module, stop_process
from astaa_deft.model.json import JsonObject

MINIMAL_XML = "minimal.xml"
SUMMARY = "summary.json"
TESTS_DIR = "tests"
OUTPUT_SUFFIX = ".out"  # what the minimiser printed, beside its folder
POLL_SECONDS = 0.5


@dataclass(frozen=True)
class MinimiseLimits:
    """How much one minimisation may do: test runs at most, confirmations of the result, seconds in all."""

    max_tests: int = 40
    confirm: int = 1
    timeout: float = 900.0


@dataclass(frozen=True, kw_only=True)
class Minimised:
    """What a minimisation gave: the minimiser's exit code, the minimal test case, its culprit, its outputs."""

    exit_code: int  # 0 minimised and confirmed, 1 a finding without a clean reproduction, 2 bad input
    minimal_xml: str | None
    culprit: str | None  # what the minimal test case does, e.g. "routing:speed_limit = dict:float.nan"
    out_dir: Path
    tests_dir: Path | None
    seconds: float
    detail: str


def minimise_run(log: Path, spec_path: Path, out_dir: Path, *, invariant: str | None = None,
                 limits: MinimiseLimits = MinimiseLimits(), cancel: threading.Event | None = None) -> Minimised:
    """Minimise ``log`` (towards ``invariant``, when it names a spec invariant) into ``out_dir`` in a child
    process stopped after ``limits.timeout`` seconds (exit code 1), or as soon as ``cancel`` is set (the
    campaign was interrupted: exit code 130). Blocks the calling thread until then; never raises for a
    minimisation that fails (its exit code and output say why)."""
    max_tests, confirm, timeout = limits.max_tests, limits.confirm, limits.timeout
    started = time.monotonic()
    args = [*python_module("astaa_deft.cli"), "minimise", str(log), "--spec", str(spec_path),
            "-o", str(out_dir), "--repeats", "1", "--confirm", str(confirm), "--max-tests", str(max_tests)]
    if invariant and not invariant.startswith("("):
        args += ["--invariant", invariant]
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    output = out_dir.parent / f"{out_dir.name}{OUTPUT_SUFFIX}"  # beside: the minimiser wants an empty -o
    with output.open("w") as sink:
        proc = process_launch.start(args, stdout=sink, stderr=subprocess.STDOUT, text=True)
        code: int | None = None
        while code is None:
            try:
                code = proc.wait(timeout=POLL_SECONDS)
            except subprocess.TimeoutExpired:
                if cancel is not None and cancel.is_set():
                    stop_process(proc, grace=5.0)
                    code = 130
                elif time.monotonic() - started >= timeout:
                    stop_process(proc, grace=5.0)
                    code = 1
    text = output.read_text(errors="replace").strip()
    if code == 1 and time.monotonic() - started >= timeout:
        text += f"\nminimisation stopped after {timeout:.0f} s"
    minimal = out_dir / MINIMAL_XML
    tests = out_dir / TESTS_DIR
    return Minimised(exit_code=code, minimal_xml=minimal.read_text() if minimal.is_file() else None,
                     culprit=_culprit(minimal), out_dir=out_dir, tests_dir=tests if tests.is_dir() else None,
                     seconds=time.monotonic() - started, detail=text[-1500:])


def _culprit(minimal: Path) -> str | None:
    """The minimal test case's mutations, as one comparable line (channel:field = value, sorted)."""
    if not minimal.is_file():
        return None
    from lxml import etree

    parser = etree.XMLParser(resolve_entities=False, no_network=True)
    root = etree.fromstring(minimal.read_bytes(), parser)
    parts: set[str] = set()
    for policy in root.iterfind("policy"):
        channels = [c.text for c in policy.iterfind("channel")] or ["*"]
        action = next((child for child in policy if child.tag not in ("channel", "window", "select", "consumer",
                                                                      "type")), None)
        if action is None:
            continue
        fields = [f"{f.get('path')} = {f.get('value')}" for f in action.iterfind("field")] or [action.tag]
        parts.update(f"{ch}:{f}" for ch in channels for f in fields)
    return "; ".join(sorted(parts)) or None


def summary(out_dir: Path) -> JsonObject:
    """The minimiser's summary.json in ``out_dir`` ({} when it wrote none, or none that reads)."""
    path = out_dir / SUMMARY
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
