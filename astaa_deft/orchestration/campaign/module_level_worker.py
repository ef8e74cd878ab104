"""One worker of a campaign's module-level search, in a process of its own.

``python -P -m astaa_deft.orchestration.campaign.module_level_worker JOB.json``:
the job (written by :mod:`.module_level`) names the user's spec file, a clean
baseline log, one module of the spec that can be replayed in process, the
dictionaries, the campaign's seed, the live window, this worker's share of
the plan (``part`` of ``parts``; ``after``: the last fault an earlier round
did) and a deadline. The worker builds the module's :class:`~astaa_deft.analysis.deft.module_search.ModuleBench` once,
plans the module's faults (:func:`~astaa_deft.analysis.deft.fault_plan.plan_faults`),
and replays its share in plan order until the deadline, appending one JSON
line per fault to the job's ``results`` file (flushed: a worker stopped at
its deadline loses at most the fault in flight). Part 0 first writes which
input fields the module reads (``reads``). A setup that fails writes one
``{"error": …}`` line and exits 2.

A process of its own because a replayed step is interrupted by SIGALRM
(``hang_after``), which needs a single-threaded process, and a module that
hangs in native code is stopped by its group from the campaign.
"""

from __future__ import annotations

import json
import sys
import time
import traceback
from pathlib import Path

from astaa_deft.model.errors import AstaaDeftError


def _targets_by_channel(spec: object, dictionaries: list[str]) -> dict:
    from astaa_deft.engine.intercept.dictionary import load_dictionary
    from astaa_deft.engine.intercept.generate import FaultTargets

    targets = FaultTargets.of(spec, load_dictionary([Path(p) for p in dictionaries]))  # type: ignore[arg-type]
    by_channel: dict = {}
    for name, family_targets in targets.by_family.items():
        if name == "stamp":
            continue  # stamps move frames, not values: the message faults cover them
        for channel, found in family_targets.items():
            by_channel.setdefault(channel, []).extend(t for t in found if t.values)
    return by_channel


def run(job: dict) -> int:
    from astaa_deft.analysis.deft.fault_plan import plan_faults
    from astaa_deft.analysis.deft.module_search import ModuleBench
    from astaa_deft.analysis.deft.planner_section import replay_module_of
    from astaa_deft.analysis.deft.workflow import run_params
    from astaa_deft.engine.spec.loader import load_spec
    from astaa_deft.io.log.reader import read_log

    results = Path(job["results"])
    with results.open("a", encoding="utf-8") as out:
        def write(line: dict) -> None:
            out.write(json.dumps(line) + "\n")
            out.flush()

        try:
            spec = load_spec(Path(job["spec"]))
            entry = replay_module_of(spec, job["module"])
            log = read_log(Path(job["log"]))
            started = time.perf_counter()
            settle = job["settle"]
            bench = ModuleBench(spec, entry, log, run_params(log, spec),
                                settle_s=float(settle) if settle is not None else None)
            setup_seconds = time.perf_counter() - started
            times = {name: [r.time_ns for r in stream] for name, stream in bench.streams.items()}
            faults = plan_faults(module=entry.module, inputs=entry.inputs, times=times,
                                 window=(int(job["window"][0]), int(job["window"][1])),
                                 targets=_targets_by_channel(spec, job["dictionaries"]), seed=int(job["seed"]))
        except (AstaaDeftError, OSError, ValueError, KeyError, TypeError) as exc:
            write({"error": f"{type(exc).__name__}: {exc}"})
            return 2
        except Exception as exc:  # the user's module failed to build or to replay its baseline
            write({"error": f"{type(exc).__name__}: {exc}", "trace": traceback.format_exc()[-2000:]})
            return 2
        write({"setup": {"module": entry.module, "frames": len(bench.frames), "faults": len(faults),
                         "baseline_seconds": round(bench.baseline_seconds, 3), "setup_seconds": round(setup_seconds, 3),
                         "baseline_error": bench.error, "known": sorted(bench.known),
                         "judged": [i.name for i in bench.judged.invariants]}})
        deadline = float(job["deadline"])
        part, parts = int(job["part"]), int(job["parts"])
        if part == 0 and job["reads"]:  # from the first frame: a field read once, at start-up, is read
            reads = bench.field_reads(first_frame=0, budget_s=max(1.0, (deadline - time.time()) / 3))
            Path(job["reads"]).write_text(json.dumps(reads.to_json()) + "\n", encoding="utf-8")
        first_of: set[tuple[str, str, str]] = set()  # buckets this worker found: their first fault minimised
        after = int(job["after"])  # a later round goes on past the faults an earlier one did
        exhausted = True
        for number, fault in enumerate(faults):
            if number % parts != part or number <= after:
                continue
            if time.time() >= deadline:
                exhausted = False
                break
            verdict = bench.run(fault)
            if verdict.failed and verdict.bucket_key not in first_of:
                first_of.add(verdict.bucket_key)
                verdict = bench.minimised(verdict)
            if verdict.applicable:
                write({"n": number, "verdict": verdict.to_json()})
        write({"done": True, "exhausted": exhausted})
    return 0


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    job = json.loads(Path(args[0]).read_text(encoding="utf-8"))
    return run(job)


if __name__ == "__main__":
    sys.exit(main())
