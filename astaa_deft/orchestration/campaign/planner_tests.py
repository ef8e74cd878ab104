"""A bucket's DeFT module tests of the module to blame (the planner or a ``replay:`` entry), built in a
process of their own.

The campaign's process runs threads (minimisations, progress, a Dask
client), and a replay that must fork the planner's native state may only
fork a single-threaded process (``bus.process_launch.guarded_fork``); a
planner that cannot be deep-copied (native objects, e.g. OMPL's) could not
be replayed there at all. So the campaign starts this module as a child
(``python -P -m astaa_deft.orchestration.campaign.planner_tests``): it extracts the suite
of the module (``--module``; default the planner) from the failing run, adds
the frame the module failed on (crash buckets) and the invariant oracle, and
prints one JSON line — ``{"accepted": N, "failure_frame": bool, "error": str
| null}``.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

from astaa_deft.engine.bus import process_launch
from astaa_deft.engine.bus.processes import python_module
from astaa_deft.analysis.deft.export import MANIFEST
from astaa_deft.model.errors import AstaaDeftError
from astaa_deft.model.sut import Spec
from astaa_deft.engine.spec.loader import load_spec
from astaa_deft.orchestration.campaign.module_tests import add_failure_frame, is_crash_bucket

TIMEOUT_S = 3600.0  # an extraction of a long run of an expensive planner: bounded, never forever


@dataclass(frozen=True)
class PlannerTests:
    accepted: int  # frames replayed exactly and written as tests (0 and no failure frame: no suite)
    failure_frame: bool  # the frame of the cycle the module failed on was added (crash buckets)
    error: str | None = None  # why there is no suite, when extraction refused the run


def build(log: Path, spec_path: Path, tests_dir: Path, *, verdict: str, invariant: str,
          module: str | None = None) -> PlannerTests:
    """Extract ``module``'s tests (None: the planner's) into ``tests_dir`` from ``log`` (InputError: ``error``
    set) with the bucket's extra frame and oracle.

    Runs the replay in this process: call it from a single-threaded one
    (:func:`build_in_child` does).
    """
    from astaa_deft.analysis.deft.workflow import ExtractOptions, extract_module_tests

    spec = load_spec(spec_path)
    try:
        report = extract_module_tests(log, spec, tests_dir, ExtractOptions(jobs=1, module=module))
    except AstaaDeftError as exc:
        return PlannerTests(0, False, str(exc))
    # A crash bucket's test is the failing cycle's frame, after every frame found (stepped for the state they
    # build, exact or not): it stands even when no output of the run replayed exactly (a module that died early).
    crash = is_crash_bucket(verdict, invariant, spec)
    added = crash and (tests_dir / MANIFEST).is_file() and add_failure_frame(tests_dir, log, spec, report,
                                                                             invariant=invariant)
    if not report.accepted and not added:
        shutil.rmtree(tests_dir, ignore_errors=True)
        return PlannerTests(0, False, f"no output of {report.entry.module} "
                                      "in the run replayed exactly")
    add_invariant_oracle(tests_dir, spec, invariant, output=report.entry.output)
    return PlannerTests(report.accepted, added)


def build_in_child(log: Path, spec_path: Path, tests_dir: Path, *, verdict: str, invariant: str,
                   module: str | None = None, timeout: float = TIMEOUT_S) -> PlannerTests:
    """:func:`build` in a child process started through the launcher; its answer, or why there is none."""
    argv = [*python_module("astaa_deft.orchestration.campaign.planner_tests"), str(log), str(spec_path), str(tests_dir),
            "--verdict", verdict, "--invariant", invariant, *(["--module", module] if module else [])]
    try:
        done = process_launch.run(argv, timeout=timeout)
    except subprocess.TimeoutExpired:
        return PlannerTests(0, False, f"the extraction did not finish in {timeout:.0f} s")
    lines = done.stdout.strip().splitlines()
    try:
        return PlannerTests(**json.loads(lines[-1]))
    except (IndexError, ValueError, TypeError):
        tail = (done.stderr.strip().splitlines() or [f"exit {done.returncode}"])[-1]
        return PlannerTests(0, False, f"the extraction process failed: {tail[:300]}")


def add_invariant_oracle(tests_dir: Path, spec: Spec, invariant: str, *, output: str | None = None) -> bool:
    """Give an extracted suite an oracle that fails while the replayed outputs break ``invariant``.

    Only for an invariant on the replayed module's output channel (``output``;
    default the planner's), what a replay produces; the frames alone only
    check that the replay matches the recording, which a defect reproduced
    exactly passes. True if added.
    """
    from astaa_deft.analysis.deft.invariant_oracle import oracle_entry

    if output is None and spec.planner is not None:
        output = spec.planner.output
    watched = next((inv for inv in spec.invariants if inv.name == invariant), None)
    if output is None or watched is None or getattr(watched, "channel", None) != output:
        return False
    manifest_path = tests_dir / MANIFEST
    manifest = json.loads(manifest_path.read_text())
    frames = manifest.get("frames") or []
    if not frames:
        return False
    manifest.setdefault("oracles", []).append(
        oracle_entry(invariant, frames[-1]["index"], int(frames[0]["output_time_ns"])))
    manifest_path.write_text(json.dumps(manifest, indent=1) + "\n")
    return True


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="astaa_deft.orchestration.campaign.planner_tests")
    parser.add_argument("log", type=Path)
    parser.add_argument("spec", type=Path)
    parser.add_argument("tests_dir", type=Path)
    parser.add_argument("--verdict", required=True)
    parser.add_argument("--invariant", required=True)
    parser.add_argument("--module", help="a module of the spec's replay: section (default: the planner)")
    args = parser.parse_args(argv)
    result = build(args.log, args.spec, args.tests_dir, verdict=args.verdict, invariant=args.invariant,
                   module=args.module)
    print(json.dumps(asdict(result)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
