"""A catastrophic pattern in a spec never hangs the tool: the three acceptance figures, measured once.

    python benchmarks/bench_redos.py [--duration 8]

A module prints ``"a" * 5000 + "!"`` every 50 ms; the spec's ``exceptions`` and ``log`` monitors watch it
with ``(a+)+$`` (hours per line for a backtracking engine). Prints: how long past its ``--duration`` a
``proxy`` run ends; how long a ``proxy`` run takes to end after SIGTERM; how long ``check`` of the recorded
log takes. Asserts nothing (targets: ≤ 5 s each).
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

CLI = [sys.executable, "-c", "import sys; from astaa_deft.cli import main; sys.exit(main())"]
MODULE = """\
import time
print("ready", flush=True)
while True:
    print("a" * 5000 + "!", flush=True)
    time.sleep(0.05)
"""


def write_spec(work: Path) -> Path:
    (work / "mod.py").write_text(MODULE)
    spec = work / "sut.yaml"
    spec.write_text(textwrap.dedent(f"""\
        name: redos
        modules:
          - {{name: planning, command: ["{sys.executable}", "{work / 'mod.py'}"], ready: {{log: "ready"}}}}
        channels:
          - {{name: plan, key: t/plan, producer: planning, type: Plan}}
        types:
          Plan: {{seq: uint64}}
        invariants:
          - {{name: errors, kind: exceptions, modules: [planning], pattern: "(a+)+$"}}
          - {{name: watched, kind: log, modules: [planning], pattern: "(a+)+$"}}
        """))
    return spec


def proxy(spec: Path, log: Path, duration: float, sigterm_after: float | None) -> tuple[float, str]:
    """Seconds from start to exit (or from SIGTERM to exit), and the output's last lines."""
    proc = subprocess.Popen([*CLI, "proxy", "--spec", str(spec), "--record", str(log), "--duration", str(duration)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True)
    started = time.monotonic()
    try:
        if sigterm_after is not None:
            time.sleep(sigterm_after)
            started = time.monotonic()
            proc.send_signal(signal.SIGTERM)
        out, _ = proc.communicate(timeout=duration + 120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    return time.monotonic() - started, "\n".join(out.splitlines()[-2:])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--duration", type=float, default=8.0)
    duration = parser.parse_args().duration
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        spec = write_spec(work)
        seconds, tail = proxy(spec, work / "run.mcap", duration, None)
        print(f"proxy --duration {duration:g}: ended after {seconds:.2f} s (+{seconds - duration:.2f} s)\n  {tail}")
        seconds, tail = proxy(spec, work / "term.mcap", 60.0, 4.0)
        print(f"proxy, SIGTERM after 4 s: ended {seconds:.2f} s after the signal\n  {tail}")
        started = time.monotonic()
        out = subprocess.run([*CLI, "check", str(work / "run.mcap")], capture_output=True, text=True, timeout=600)
        print(f"check of that log: {time.monotonic() - started:.2f} s, exit {out.returncode}\n  "
              + out.stdout.strip().splitlines()[-2])


if __name__ == "__main__":
    main()
