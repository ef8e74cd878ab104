"""Extraction's wall time on a committed pinned log, and the share of it the written suite's pytest check takes.

    python benchmarks/bench_extract_pinned.py {demo_lane_follow,timer_several,each_warm,...} STACKS OUT

The log is one of ``tests/data/extraction_pins`` (beside this script's
checkout), extracted as ``astaa-deft extract LOG --spec SPEC -o OUT --jobs 1``
does (the library call: ``extract_module_tests``): the bundled demo's
planner for ``demo_lane_follow``, the zoo member's ``module`` at θ 0 (as
tests/test_deft_extraction_pinned.py extracts it) for the others. A zoo
member's stack is written once under ``STACKS`` by this checkout's
tests/zoo and reused, so that code of another checkout (``PYTHONPATH``) can
be timed on the very same files. Prints one JSON line: the seconds of the
whole call, of the suite's check (``check_suite``: pytest on the written
suite, in a process of its own) and of the rest, the tests written, and
``os.getloadavg()`` before and after. Asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent
PINS = HERE / "tests" / "data" / "extraction_pins"
DEMO = "demo_lane_follow"


def zoo_stack(name: str, stacks: Path) -> Path:
    """The member's spec, its stack written under ``stacks`` the first time (by this checkout's zoo)."""
    spec = stacks / name / "spec.yaml"
    if not spec.is_file():
        sys.path.insert(0, str(HERE / "tests"))
        from zoo import by_name, short, write_member

        written = write_member(short(by_name(name)), stacks / name)
        assert written.spec_path == spec, written.spec_path
    return spec


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("log", help="a folder of tests/data/extraction_pins")
    parser.add_argument("stacks", type=Path, help="where the zoo member's stack is written once and reused")
    parser.add_argument("out", type=Path, help="the suite's folder (emptied first)")
    args = parser.parse_args()
    from astaa_deft.analysis.deft import workflow

    if args.log == DEMO:
        from astaa_deft.cli.commands.demo import demo_spec_path

        spec, options = demo_spec_path(), workflow.ExtractOptions(jobs=1)
    else:
        spec, options = zoo_stack(args.log, args.stacks), workflow.ExtractOptions(module="module", threshold=0.0,
                                                                                   jobs=1)
    shutil.rmtree(args.out, ignore_errors=True)
    check = [0.0]
    real_check = workflow.check_suite

    def timed_check(*a, **kw):
        t0 = time.perf_counter()
        try:
            return real_check(*a, **kw)
        finally:
            check[0] += time.perf_counter() - t0

    workflow.check_suite = timed_check
    load_before = os.getloadavg()
    t0 = time.perf_counter()
    report = workflow.extract_module_tests(PINS / args.log / "run.mcap", spec, args.out, options)
    seconds = time.perf_counter() - t0
    print(json.dumps({"log": args.log, "seconds": round(seconds, 3), "check_s": round(check[0], 3),
                      "extraction_s": round(seconds - check[0], 3), "tests": report.accepted,
                      "load_before": [round(x, 2) for x in load_before],
                      "load_after": [round(x, 2) for x in os.getloadavg()],
                      "package": str(Path(workflow.__file__).resolve().parents[2])}))


if __name__ == "__main__":
    main()
