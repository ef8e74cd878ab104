"""The default test suite (or any pytest selection) with CPU-bound loops beside it: results that must not depend on
the machine's load.

    python benchmarks/loaded_suite.py                        # the default run, two loops, once
    python benchmarks/loaded_suite.py --repeat 3             # three runs in a row
    python benchmarks/loaded_suite.py --loops 0              # the same, quiet (the time to compare with)
    python benchmarks/loaded_suite.py --repeat 3 --keep DIR  # each run's whole output in DIR/run-N.txt, its
                                                             # tests' files (logs, suites) in DIR/tmp-N
    python benchmarks/loaded_suite.py -- tests/test_deft_demo.py -k lockstep -n 0   # a selection

Starts ``--loops`` Python processes that spin (``while True: pass``) for the
whole of each pytest run, and stops exactly those (by their pids) when it
ends, however it ends. Everything after ``--`` goes to pytest (the default
run's options of pyproject.toml apply as always). For each run it prints
pytest's last line, its wall time and the load average before and after;
at the end one line per run and how many failed. Exit code: 0 when every
run passed, 1 otherwise. Asserts nothing of the times.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
# A loop ignores Ctrl-C (the terminal sends it to the whole group): this script stops it by its pid on the way out.
LOOP = "import signal\nsignal.signal(signal.SIGINT, signal.SIG_IGN)\nwhile True: pass"


def loaded_run(pytest_args: list[str], loops: int, keep: Path | None = None) -> tuple[int, float, str, float, float]:
    """One pytest run with ``loops`` spinning processes beside it: (exit code, seconds, last line, load before,
    load after). With ``keep``, pytest's whole output is written there (a failure's detail)."""
    before = os.getloadavg()[0]
    spinners = [subprocess.Popen([sys.executable, "-c", LOOP]) for _ in range(loops)]
    started = time.monotonic()
    try:
        run = subprocess.run([sys.executable, "-m", "pytest", *pytest_args], cwd=ROOT, capture_output=True,
                             text=True)
    finally:
        for spinner in spinners:  # ours only, by their pids
            spinner.kill()
            spinner.wait()
    seconds = time.monotonic() - started
    if keep is not None:
        keep.write_text(run.stdout + run.stderr)
    lines = [line for line in run.stdout.splitlines() if line.strip()]
    failures = [line for line in lines if line.startswith(("FAILED", "ERROR"))]
    for line in failures:
        print(f"  {line}")
    return run.returncode, seconds, lines[-1] if lines else run.stderr[-300:], before, os.getloadavg()[0]


def main() -> None:
    # SIGTERM ends the run as Ctrl-C does: the loops this script started are stopped on the way out.
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))
    argv = sys.argv[1:]
    pytest_args = argv[argv.index("--") + 1:] if "--" in argv else []
    mine = argv[:argv.index("--")] if "--" in argv else argv
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--loops", type=int, default=2, help="CPU-bound loops beside each run (default 2)")
    ap.add_argument("--repeat", type=int, default=1, help="runs in a row (default 1)")
    ap.add_argument("--keep", type=Path, help="write each run's whole pytest output to DIR/run-N.txt and keep its "
                    "tests' temporary files (their recordings) in DIR/tmp-N")
    args = ap.parse_args(mine)
    if args.keep:
        args.keep.mkdir(parents=True, exist_ok=True)
    results = []
    for n in range(1, args.repeat + 1):
        keep = args.keep / f"run-{n}.txt" if args.keep else None
        # pytest keeps only its last three runs' temporary folders: a failure's recording is kept apart.
        basetemp = [f"--basetemp={(args.keep / f'tmp-{n}').resolve()}"] if args.keep else []
        code, seconds, last, before, after = loaded_run([*basetemp, *pytest_args], args.loops, keep)
        minutes, rest = divmod(round(seconds), 60)
        print(f"run {n}: {last} — {minutes} min {rest:02d} s, {args.loops} loops, load {before:.1f} → {after:.1f}",
              flush=True)
        results.append(code)
    failed = sum(code != 0 for code in results)
    print(f"{len(results)} run(s) with {args.loops} CPU-bound loops beside: {failed} failed")
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    try:
        main()
    except KeyboardInterrupt:  # Ctrl-C: the loops are stopped on the way out; no traceback
        sys.exit(130)
