"""Extraction pinned on recorded zoo runs: what the frame rules propose and what extraction writes, as digests.

A refactor of DeFT's frame rules or of the extraction must not change a
byte of either. ``tests/data/extraction_pins/<member>/run.mcap`` is one
recorded run of a short zoo member (``zoo.short``); ``pins.json`` holds, per
member, the sha256 of every candidate frame the rules propose for every
output of that log (in order, with the ways each was derived) and of every
file the extraction writes for it. The test regenerates the member's stack
(``write_member`` is deterministic), extracts the committed log and compares.

A change meant to alter extraction regenerates the pins, and says so:

    PYTHONPATH=. python tests/extraction_pins.py --write     # from the repository's root
"""

from __future__ import annotations

import hashlib
import json
import sys
from collections.abc import Iterator, Mapping
from pathlib import Path

if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))

from zoo import MODULE, by_name, short, write_member
from zoo.judge import extract

from astaa_deft.analysis.deft.extract import extract as extract_frames
from astaa_deft.analysis.deft.replay import make_planner
from astaa_deft.cli.commands.demo import demo_spec_path
from astaa_deft.analysis.deft.frames import Candidate, OutputContext, Stream, candidates, read_times, trigger_candidates
from astaa_deft.analysis.deft.planner_section import replay_module_of
from astaa_deft.engine.spec.loader import load_spec
from astaa_deft.io.log.reader import read_log

PINS = Path(__file__).resolve().parent / "data" / "extraction_pins"
# Members whose whole extraction is pinned (cheap steps: no time limit ever cuts a candidate, so the outcome
# does not depend on the machine's load), and members whose candidate frames alone are.
EXTRACTED = ("each_warm", "mpc", "timer_several")
FRAMES_ONLY = ("drop_cycle_none", "oldest_latched")
MEMBERS = EXTRACTED + FRAMES_ONLY
# The bundled demo's planner on a recorded lane_follow run (its spec ships with the tool: nothing to write).
DEMO = "demo_lane_follow"
DEMO_PARAMS = {"scenario": "lane_follow", "defects": "off"}
STEP_NS = (None, 80_000_000)  # read_times without a measured step, and with a step no instant one


def _candidate_line(cand: Candidate) -> str:
    return json.dumps([cand.frame_time, sorted(cand.choice.items()), sorted(map(repr, cand.patterns)),
                       [sorted(s.items()) for s in cand.silent], cand.walk])


def candidate_lines(log_path: Path, spec_path: Path, module: str | None = MODULE) -> Iterator[str]:
    """Every candidate the frame rules propose for every output of the log, as extraction asks for them: the
    previous frame the first candidate of the output before, each rule's inputs from the log alone
    (``module``: the replayed module, None: the planner)."""
    spec = load_spec(spec_path)
    cfg = replay_module_of(spec, module)
    log = read_log(log_path)
    timed = {name: sorted(log.on(spec.channel(name).key), key=lambda m: m.log_time)
             for name in [*cfg.inputs, cfg.output]}
    outputs = timed.pop(cfg.output)
    streams = {name: Stream(name, [m.log_time for m in msgs]) for name, msgs in timed.items()}
    skew, lookback = int(cfg.skew_ms * 1e6), int(cfg.lookback_ms * 1e6)
    for step_ns in STEP_NS:
        previous: Mapping[str, int] = {}
        for index, output in enumerate(outputs):
            previous_ns = outputs[index - 1].log_time if index else None
            read_at = read_times(streams, cfg.trigger, previous, output_ns=output.log_time,
                                 previous_output_ns=previous_ns, step_ns=step_ns)
            found = candidates(OutputContext(
                streams=streams, trigger=cfg.trigger, output_ns=output.log_time + skew, previous=previous,
                lookback_ns=lookback, previous_output_ns=None if previous_ns is None else previous_ns + skew,
                read_at=read_at, module_started_in_log=index == 0, skew_ns=skew,
                earlier_outputs_ns=[o.log_time for o in reversed(outputs[max(0, index - 4):index - 1])]))
            yield f"output {index} step {step_ns}: {len(found)}"
            yield from map(_candidate_line, found)
            if found:
                previous = dict(found[0].choice)
    previous = {}
    for t_index in range(len(streams[cfg.trigger].times)):
        options = trigger_candidates(streams, cfg.trigger, t_index, previous, lookback_ns=lookback,
                                     answered_at=streams[cfg.trigger].times[t_index] + 5_000_000, skew_ns=skew)
        yield f"trigger {t_index}: " + json.dumps([sorted(o.items()) for o in options])
        previous = options[0]


def digest(lines: Iterator[str]) -> str:
    h = hashlib.sha256()
    for line in lines:
        h.update(line.encode() + b"\n")
    return h.hexdigest()


def suite_digests(directory: Path, stack_dir: Path) -> dict[str, str]:
    """sha256 of each file the extraction wrote (relative path → digest), the stack's folder (which the
    manifest names as the spec's) read as ``<stack>``: it is a fresh temporary folder on every run."""
    stack = json.dumps(str(stack_dir))[1:-1].encode()
    return {p.relative_to(directory).as_posix(): hashlib.sha256(p.read_bytes().replace(stack, b"<stack>")).hexdigest()
            for p in sorted(directory.rglob("*")) if p.is_file()}


def member_stack(name: str, directory: Path):
    """The member's stack (spec, factory) written afresh, beside a copy of its pinned log (returns both)."""
    stack = write_member(short(by_name(name)), directory / name)
    log = stack.directory / "pinned.mcap"
    log.write_bytes((PINS / name / "run.mcap").read_bytes())
    return stack, log


def pins_now(name: str, directory: Path) -> dict[str, object]:
    """The member's pins as the code now makes them from its committed log."""
    stack, log = member_stack(name, directory)
    out: dict[str, object] = {"candidates": digest(candidate_lines(log, stack.spec_path))}
    if name in EXTRACTED:
        suite = stack.directory / "suite"
        extracted = extract(stack, log, suite)
        out["suite"] = suite_digests(suite, stack.directory)
        out["exact"], out["tests"] = extracted.exact, extracted.tests
    return out


def demo_pins_now(directory: Path) -> dict[str, object]:
    """The demo's pins as the code now makes them from its committed log: the planner's candidates, and the
    frames an in-process extraction keeps (candidates stepped from deep copies, one after another: the
    forked search may keep either of two candidates that both settle an output, whichever reports first) —
    each frame's inputs, trigger and judgement. Not its frame time: a frame read at the cycle's start is
    timed by the step the replay measured (``read_at``), which varies from run to run."""
    log = directory / "demo.mcap"
    log.write_bytes((PINS / DEMO / "run.mcap").read_bytes())
    spec = load_spec(demo_spec_path())
    extraction = extract_frames(read_log(log), spec, make_planner(spec, DEMO_PARAMS))
    kept = [json.dumps([f.index, f.trigger_time, sorted((k, m.log_time) for k, m in f.inputs.items()),
                        f.comparison.distance, f.exact, f.accepted]) for f in extraction.frames]
    return {"candidates": digest(candidate_lines(log, demo_spec_path(), None)), "frames": digest(iter(kept)),
            "exact": extraction.accepted_at(0.0), "tests": len(kept)}


def record_lane_follow(path: Path) -> Path:
    """One passive recording of the demo's lane_follow scenario (as tests/test_deft_demo.py makes its own)."""
    from astaa_deft.cli.commands.demo import StatusWatch
    from astaa_deft.cli.commands.proxy import run_bus
    from astaa_deft.engine.session import RunOptions

    watch = StatusWatch()
    outcome = run_bus(load_spec(demo_spec_path()), RunOptions(mode="passive", record=path, params=DEMO_PARAMS), 40.0,
                      on_start=lambda r: r.subscribe("status", watch.on_sample), verbose=False)
    assert watch.goal, outcome.end_reason
    return path


def committed() -> dict[str, dict[str, object]]:
    return json.loads((PINS / "pins.json").read_text())


if __name__ == "__main__":
    import argparse
    import tempfile

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", action="store_true", help="rewrite pins.json from the committed logs")
    parser.add_argument("--record", action="store_true", help="record each member's log afresh first")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        if args.record:
            from zoo import record
            for name in MEMBERS:
                stack = write_member(short(by_name(name)), Path(tmp) / "rec" / name)
                (PINS / name).mkdir(parents=True, exist_ok=True)
                (PINS / name / "run.mcap").write_bytes(record(stack).read_bytes())
        if args.record:
            (PINS / DEMO).mkdir(parents=True, exist_ok=True)
            (PINS / DEMO / "run.mcap").write_bytes(record_lane_follow(Path(tmp) / "demo-rec.mcap").read_bytes())
        pins = {name: pins_now(name, Path(tmp)) for name in MEMBERS}
        pins[DEMO] = demo_pins_now(Path(tmp))
    if args.write:
        (PINS / "pins.json").write_text(json.dumps(pins, indent=1, sort_keys=True) + "\n")
    print(json.dumps(pins, indent=1, sort_keys=True))
