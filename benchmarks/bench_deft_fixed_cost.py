"""DeFT's fixed costs on cheap modules: extraction against a plain replay, wall and CPU, code trees side by side.

    python benchmarks/bench_deft_fixed_cost.py [--members each_several,timer_several] [--rounds 8]
                                               [--code before=/path/to/old/tree,after=.] [--keep DIR]

For each member (tests/zoo; default: the cheap members with ≥ 100 outputs
and one whose step costs nothing, ``null_several``, where all that is left
is the extraction's own cost) one recorded run, then ``--rounds`` rounds,
each in a rotating order: the plain replay (the zoo's ``at_output`` way: one
step per recorded output, what the extraction has to step at least; or the
member's own plain way with ``--floor-way``) and ``extract --module module
--threshold 0`` (the library call) of every code tree given (``--code
NAME=DIR``: a directory holding an ``astaa_deft`` package, put first on
PYTHONPATH; default: this checkout). Every measurement is a fresh Python
process, so the trees do not share imports; its wall time and the CPU time
of it and every process it forked (the replay's runner, shadows,
candidates) count, the interpreter's start-up and imports do not.

Prints, per member and tree, the medians and their ratios to the plain
replay's (the machine's load moves both: the pairs are interleaved). CPU time
says what the extraction does on top of the steps; wall time what a user
waits for. Asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))

from zoo import Member, by_name, record, write_member  # noqa: E402

NULL = Member("null_several", trigger="each", state="counters", outputs="several", cost_ms=(0.001, 0.001),
              note="a step that costs nothing: what is left is the extraction's own cost")
DEFAULT = ("null_several", "each_several", "timer_several", "oldest_several_late")

# One measurement, in its own interpreter: argv = kind (plain WAY | extract OUT), the stack's directory.
MEASURE = r"""
import dataclasses, json, resource, shutil, sys, time
from pathlib import Path
sys.path.insert(0, sys.argv[1])
from zoo import Member, plain_replay
from zoo.generate import Stack
kind, arg, d = sys.argv[2], sys.argv[3], Path(sys.argv[4])
def cpu():
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime
if kind == "plain":
    names = {f.name for f in dataclasses.fields(Member)}
    described = json.loads((d / "member.json").read_text())["member"]
    member = Member(**{k: tuple(v) if k == "cost_ms" else v for k, v in described.items() if k in names})
    wall, used = time.perf_counter(), cpu()
    floor = plain_replay(Stack(member, d), d / "run.mcap", ways=None if arg == "floor" else (arg,))
    print(json.dumps({"wall": time.perf_counter() - wall, "cpu": cpu() - used, "count": floor.count,
                      "way": floor.way}))
else:
    from astaa_deft.analysis.deft.workflow import ExtractOptions, extract_module_tests
    shutil.rmtree(arg, ignore_errors=True)
    wall, used = time.perf_counter(), cpu()
    report = extract_module_tests(d / "run.mcap", d / "spec.yaml", Path(arg),
                                  ExtractOptions(module="module", threshold=0.0))
    exact = sum(1 for f in report.extraction.frames if f.output is not None and f.comparison.distance == 0.0)
    print(json.dumps({"wall": time.perf_counter() - wall, "cpu": cpu() - used, "count": exact}))
"""


def measure(code: Path, *args: str) -> dict:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(code), os.environ.get("PYTHONPATH", "")]))
    done = subprocess.run([sys.executable, "-c", MEASURE, str(ROOT / "tests"), *args], env=env,
                          capture_output=True, text=True, timeout=600)
    if done.returncode:
        raise SystemExit(f"measurement {args[:2]} with {code} failed:\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--members", default=",".join(DEFAULT), help="comma-separated zoo members (null_several too)")
    ap.add_argument("--rounds", type=int, default=8, help="interleaved rounds (plain and every tree once each)")
    ap.add_argument("--code", default=f"this={ROOT}", help="NAME=DIR,… code trees to compare (default: this one)")
    ap.add_argument("--floor-way", action="store_true", help="the plain replay of the member's floor way instead")
    ap.add_argument("--keep", type=Path, help="record the stacks here (kept; an existing run.mcap is reused)")
    args = ap.parse_args()
    trees = {name: Path(path).resolve() for name, path in (item.split("=", 1) for item in args.code.split(","))}
    base = args.keep or Path(tempfile.mkdtemp(prefix="deft-fixed-"))
    say = lambda text: print(text, flush=True)  # noqa: E731
    say(f"DeFT fixed costs: {args.rounds} interleaved round(s); trees {', '.join(trees)}; "
        f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")
    for name in args.members.split(","):
        member = NULL if name == NULL.name else by_name(name)
        stack = write_member(member, base / name)
        if not (stack.directory / "run.mcap").is_file():
            record(stack)
        runs: dict[str, list[dict]] = {key: [] for key in ("plain", *trees)}
        for round_ in range(args.rounds):
            order = ["plain", *trees]
            for key in order[round_ % len(order):] + order[:round_ % len(order)]:
                if key == "plain":
                    way = "floor" if args.floor_way else "at_output"
                    runs[key].append(measure(ROOT, "plain", way, str(stack.directory)))
                else:
                    runs[key].append(measure(trees[key], "extract", str(stack.directory / f"suite_{key}"),
                                             str(stack.directory)))
        wall = {key: statistics.median(r["wall"] for r in rows) for key, rows in runs.items()}
        cpu = {key: statistics.median(r["cpu"] for r in rows) for key, rows in runs.items()}
        line = (f"{name:20} {member.cost_ms[0]:g}-{member.cost_ms[1]:g} ms  plain ({runs['plain'][0]['way']}) "
                f"{wall['plain']:.2f} s, cpu {cpu['plain']:.2f} s")
        for key in trees:
            line += (f" | {key}: {wall[key]:.2f} s {wall[key] / wall['plain']:.2f}×, cpu {cpu[key]:.2f} s "
                     f"{cpu[key] / cpu['plain']:.2f}×, θ = 0 {runs[key][-1]['count']}")
        say(line)
    say(f"load average now {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
