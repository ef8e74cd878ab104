"""The `astaa-deft` command line: parse arguments, call one command module.

Exit codes: 0 ok, 1 a finding (a test failed, a module crashed), 2 usage or
input error (printed as one line per problem, never a traceback), 3 a run not
fully observed (verdict withheld), 4 the output cannot be written (read-only,
full, over the file size limit, a file in the way, no temporary directory:
``output_place.EXIT_CANNOT_WRITE``).
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from astaa_deft import __version__
from astaa_deft.model.errors import AstaaDeftError, InputError, Problem
from astaa_deft.io.output_place import ignore_file_size_signal


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="astaa-deft",
        description="Test robot software on its own Zenoh bus: record, replay, intercept.",
    )
    p.add_argument("--version", action="version", version=f"astaa-deft {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    # spec
    spec = sub.add_parser("spec", help="work with SUT specs").add_subparsers(dest="spec_command", metavar="ACTION")
    spec.required = True
    check = spec.add_parser("check", help="validate a SUT spec")
    check.add_argument("file", type=Path)
    check.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                       help="also check a param value (against the param's declared choices)")
    check.set_defaults(func=lambda a: _cmd("spec_check").run(a.file, a.param))
    disc = spec.add_parser("discover", help="write a spec skeleton from a running ROS 2 system (rmw_zenoh)")
    disc.add_argument("--connect", action="append", required=True, metavar="ENDPOINT",
                      help="the running system's Zenoh router, e.g. tcp/127.0.0.1:7447")
    _bounded(disc, "--seconds", LISTEN_SECONDS, default=3.0, help="how long to listen (default 3)")
    disc.add_argument("-o", "--out", type=Path, required=True, help="the spec file to write")
    disc.add_argument("--name", default="discovered", help="the spec's name")
    _bounded(disc, "--domain", DOMAIN_ID, help="ROS_DOMAIN_ID to keep (default: the first one seen)")
    disc.add_argument("--all-topics", action="store_true", help="keep /rosout and /parameter_events too")
    disc.set_defaults(func=lambda a: _cmd("discover").run(a.out, a.connect, a.seconds, a.name, a.domain,
                                                          a.all_topics))

    # proxy
    proxy = sub.add_parser("proxy", help="run the SUT through the proxy and record the bus")
    proxy.add_argument("--spec", type=Path, required=True, help="the SUT spec (YAML)")
    proxy.add_argument("--record", type=Path, help="write the MCAP test log here")
    proxy.add_argument("--passive", action="store_true",
                       help="observe only (no man in the middle): adds nothing to the SUT's message path")
    _bounded(proxy, "--duration", RUN_SECONDS, help="stop after S seconds (default: until Ctrl-C)")
    proxy.add_argument("--launch", action=argparse.BooleanOptionalAction, default=True,
                       help="start the spec's modules (default) or attach to a running SUT (--no-launch)")
    proxy.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                       help="override a spec param used in module commands")
    proxy.add_argument("--run-dir", type=Path, help="keep module logs and Zenoh configs here")
    proxy.add_argument("--stop-on-violation", action="store_true", help="end the run at the first broken invariant")
    proxy.add_argument("--policy", type=Path,
                       help="an ASTAA test case (XML): rewrite, drop, delay or inject live messages")
    proxy.add_argument("--dictionary", type=Path, action="append", default=[],
                       help="an exceptional-value dictionary on top of the default one (repeatable)")
    proxy.set_defaults(func=_proxy)

    # generate
    gen = sub.add_parser("generate", help="write ASTAA test cases drawn from a spec and the dictionary")
    gen.add_argument("--spec", type=Path, required=True)
    _bounded(gen, "--count", CASES, required=True, help="test cases to write")
    _bounded(gen, "--seed", SEED, required=True, help="the seed of the draw (the same seed, the same cases)")
    gen.add_argument("-o", "--out", type=Path, required=True)
    _bounded(gen, "--duration", WINDOW_SECONDS, default=30.0, help="windows fall inside this many seconds")
    gen.add_argument("--include-brittle", action="store_true", help="also target timestamps, sequence numbers…")
    gen.add_argument("--dictionary", type=Path, action="append", default=[])
    gen.set_defaults(func=lambda a: _cmd("generate").run(a.spec, a.count, a.seed, a.out, a.duration,
                                                          a.include_brittle, a.dictionary))

    # policy
    pol = sub.add_parser("policy", help="work with ASTAA test cases").add_subparsers(dest="policy_command",
                                                                                     metavar="ACTION")
    pol.required = True
    pc = pol.add_parser("check", help="validate test case files (or directories of them)")
    pc.add_argument("files", type=Path, nargs="+")
    pc.add_argument("--spec", type=Path, help="also check channels, fields and values against this spec")
    pc.add_argument("--dictionary", type=Path, action="append", default=[])
    pc.set_defaults(func=lambda a: _cmd("policy_check").run(a.files, a.spec, a.dictionary))

    # check
    chk = sub.add_parser("check", help="evaluate the spec's invariants over a recorded log (exit 1 on a finding)")
    chk.add_argument("log", type=Path, help="the MCAP test log")
    chk.add_argument("--spec", type=Path, help="the SUT spec (default: the one stored in the log)")
    chk.add_argument("--json", action="store_true", help="print the result as one JSON object")
    chk.set_defaults(func=lambda a: _cmd("check").run(a.log, a.spec, as_json=a.json))

    # log
    log = sub.add_parser("log", help="inspect test logs").add_subparsers(dest="log_command", metavar="ACTION")
    log.required = True
    info = log.add_parser("info", help="channels, counts, rates, events of a log")
    info.add_argument("file", type=Path)
    info.set_defaults(func=lambda a: _cmd("log_info").run(a.file))

    # extract
    ext = sub.add_parser("extract", help="DeFT: turn a recorded run into deterministic planner module tests")
    ext.add_argument("log", type=Path, help="a log recorded by astaa-deft proxy")
    ext.add_argument("--spec", type=Path, required=True)
    ext.add_argument("-o", "--out", type=Path, required=True, help="directory for the module tests")
    _bounded(ext, "--threshold", THRESHOLD_M, help="accept a frame within this distance, m (default: the spec's)")
    ext.add_argument("--process", action="store_true",
                     help="replay with the planner's own process in lock-step (needs planner.replay.command)")
    ext.add_argument("--ground-truth", metavar="FIELD",
                     help="evaluation only: the output field naming the inputs' header.seq (e.g. debug.inputs)")
    _bounded(ext, "--jobs", PROCESSES, metavar="N",
             help="candidate frames tried at once, in forked processes (default: the idle cores)")
    ext.add_argument("--module", help="a module of the spec's replay: section (default: the planner)")
    ext.add_argument("--resume", action="store_true",
                     help="continue an interrupted extraction into the same -o directory")
    ext.set_defaults(func=lambda a: _cmd("extract").run(a.log, a.spec, a.out, a.threshold, a.process,
                                                         a.ground_truth, jobs=a.jobs, module=a.module,
                                                         resume=a.resume))

    # minimise
    mini = sub.add_parser("minimise", aliases=["minimize"],
                          help="delta-debug a failing intercepted run down to the mutations, frames and fields "
                               "that cause it")
    mini.add_argument("log", type=Path, help="a log recorded by astaa-deft proxy --policy …")
    trust = mini.add_mutually_exclusive_group()
    trust.add_argument("--spec", type=Path, help="the SUT spec (the one stored in the log runs only with "
                                                 "--trust-log-spec)")
    trust.add_argument("--trust-log-spec", action="store_true",
                       help="run the module commands and replay factories the spec stored in the log names "
                            "(without it, minimise lists them and stops: a log is data)")
    mini.add_argument("--invariant", help="the failure to keep (default: the run's first violation)")
    mini.add_argument("-o", "--out", type=Path, required=True, help="directory for the minimised test case and tests")
    _bounded(mini, "--repeats", REPEATS, default=1, help="whole-SUT re-runs per test when no replay applies")
    _bounded(mini, "--parallel", PROCESSES, default=2, help="tests run at once where the replay allows")
    mini.add_argument("--live-only", action="store_true", help="always re-run the whole SUT (no module replay)")
    _bounded(mini, "--confirm", RERUNS, default=3, help="live re-runs of the final result, to report its rate")
    _bounded(mini, "--max-tests", CASES, help="stop after this many tests and keep the smallest failure")
    mini.add_argument("--no-live-fallback", action="store_true",
                      help="when the planner replay does not reproduce the failure, stop (exit 1) "
                           "instead of re-running the SUT")
    _bounded(mini, "--jobs", PROCESSES, default=1,
             help="whole-system runs at once (live tests, confirmations), each an isolated session")
    mini.set_defaults(func=lambda a: _cmd("minimise").run(a.log, a.spec, a.invariant, a.out, a.repeats,
                                                          a.parallel, a.live_only, confirm=a.confirm,
                                                          max_tests=a.max_tests,
                                                          live_fallback=not a.no_live_fallback, jobs=a.jobs,
                                                          trust_log_spec=a.trust_log_spec))

    # fuzz, report (campaigns)
    fz = sub.add_parser("fuzz", help="a campaign: generated test cases, each a fresh run; failures bucketed, "
                                     "re-run for their rate, minimised, reported")
    fz.add_argument("--spec", type=Path, help="the SUT spec (YAML)")
    fz.add_argument("-o", "--out", type=Path, required=True, help="the campaign directory (journal, logs, report)")
    _bounded(fz, "--cases", CASES, help="generated cases to run")
    fz.add_argument("--budget", type=_budget,
                    help=f"or a time budget: 90s, 30m, 2h [at most {MAX_BUDGET_S / DAY_S:g} days]")
    _bounded(fz, "--workers", PROCESSES, help="cases at once (default: from the cores and the spec's modules)")
    _bounded(fz, "--seed", CAMPAIGN_SEED, default=0, help="the campaign's seed (default 0)")
    fz.add_argument("--strategy", default="random",
                    help="random (ASTAA's weighted generation), guided, or decictor (non-optimal decisions; "
                         "baselines decictor-random, decictor-random-delta: docs/decictor.md)")
    fz.add_argument("--dictionary", type=Path, action="append", default=[])
    fz.add_argument("--params", nargs="+", default=[], metavar="KEY=V1,V2", help="spread cases over these values")
    _bounded(fz, "--horizon", WINDOW_SECONDS, default=20.0, help="seconds a case runs at most")
    _bounded(fz, "--settle", WINDOW_SECONDS, default=3.0,
             help="seconds a mutated case runs on after its last mutation could act")
    _bounded(fz, "--baseline", RERUNS, default=2, help="clean runs first, per value of the --params grid")
    _bounded(fz, "--reruns", RERUNS, default=2,
             help="re-runs of a new failure and as many unmutated twins, before it is filed as a bug")
    fz.add_argument("--no-minimise", action="store_true", help="do not minimise the buckets")
    _bounded(fz, "--minimise-timeout", WINDOW_SECONDS, default=300.0,
             help="seconds one bucket's minimisation may take (it holds a worker slot)")
    fz.add_argument("--resume", action="store_true", help="continue the campaign in -o")
    fz.add_argument("--cluster", type=_cluster,
                    help=f"tcp://HOST:8786 (a Dask scheduler) or local:K (K local worker processes) [K {PROCESSES}]")
    fz.add_argument("--status", action="store_true", help="print the campaign's state from its journal and exit")
    fz.set_defaults(func=_fuzz)
    rep = sub.add_parser("report", help="regenerate a campaign's report.html")
    rep.add_argument("campaign", type=Path)
    rep.set_defaults(func=lambda a: _cmd("report").run(a.campaign))

    # demo
    demo = sub.add_parser("demo", help="the bundled driving stack through the whole tool: record, DeFT tests, "
                                       "live interception, minimisation")
    demo.add_argument("--scenario", default="lane_follow", help="a bundled scenario name or a scenario YAML path")
    demo.add_argument("--out", type=Path, default=Path("astaa-deft-demo"), help="where everything is written")
    demo.set_defaults(func=lambda a: _cmd("demo").run_all(a.scenario, a.out, sys.argv))
    demo_sub = demo.add_subparsers(dest="demo_command", metavar="ACTION")
    demo_run = demo_sub.add_parser("run", help="run one demo scenario through the proxy")
    _demo_args(demo_run)
    demo_run.set_defaults(func=_demo)
    return p


def _demo_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--scenario", default="lane_follow", help="a bundled scenario name or a scenario YAML path")
    _bounded(p, "--duration", RUN_SECONDS, help="stop after S seconds (default: the scenario's time limit)")
    p.add_argument("--no-defects", action="store_true", help="switch the demo's seeded defects off")
    p.add_argument("--passive", action="store_true", help="observe only, no star")
    p.add_argument("--record", type=Path, help="where to write the log (default: astaa-deft-demo/SCENARIO.mcap)")


def _proxy(a: argparse.Namespace) -> int:
    from astaa_deft.cli.commands import console, proxy
    from astaa_deft.engine.spec.loader import load_spec

    spec = load_spec(a.spec)
    interceptor, attachments = None, {}
    if a.policy is not None:
        from astaa_deft.engine.intercept import load_interceptor
        from astaa_deft.io.log import layout

        interceptor = load_interceptor(a.policy, spec, a.dictionary)
        attachments[layout.POLICY_ATTACHMENT] = a.policy
        for n, path in enumerate(a.dictionary, start=1):
            attachments[layout.DICTIONARY_ATTACHMENT.format(n=n)] = path
    return proxy.run(spec, a.record, a.passive, a.duration, a.launch, console.parse_params(a.param),
                     sys.argv, a.run_dir, stop_on_violation=a.stop_on_violation, interceptor=interceptor,
                     attachments=attachments)


def _fuzz(a: argparse.Namespace) -> int:
    from astaa_deft.orchestration.campaign.campaign import CampaignConfig
    from astaa_deft.cli.commands import fuzz

    if a.status:
        return fuzz.status(a.out)
    if a.spec is None and not a.resume:
        raise InputError(Problem("astaa-deft fuzz", None, None, "no spec given",
                                 "give --spec sut.yaml (or --resume to go on with the campaign in -o DIR)"))
    if a.cases is None and a.budget is None and not a.resume:
        raise InputError(Problem("astaa-deft fuzz", None, None, "no size given for the campaign",
                                 "give --cases N or --budget DURATION (e.g. 10m)"))
    config = CampaignConfig(a.spec or Path("."), a.out, cases=a.cases,
                            budget=a.budget, workers=a.workers,
                            seed=a.seed, strategy=a.strategy, dictionaries=a.dictionary,
                            params=fuzz.parse_params(a.params), cluster=a.cluster, horizon=a.horizon,
                            baseline_runs=a.baseline, reruns=a.reruns, minimise=not a.no_minimise,
                            settle=a.settle, minimise_timeout=a.minimise_timeout)
    return fuzz.run(config, a.resume)


def _demo(a: argparse.Namespace) -> int:
    from astaa_deft.cli.commands import demo

    return demo.run(a.scenario, a.duration, not a.no_defects, a.passive, a.record, sys.argv)


def _cmd(name: str):
    import importlib

    return importlib.import_module(f".commands.{name}", __package__)


@dataclass(frozen=True)
class NumberRange:
    """An argparse ``type``: a finite int or float in [low, high] (``low`` excluded when ``above_low``).

    Called with the option's text, returns the number or raises
    ``argparse.ArgumentTypeError`` (a usage error, exit 2) saying the range.
    """

    kind: type[int] | type[float]
    low: int | float
    high: int | float
    unit: str = ""
    above_low: bool = False

    def __call__(self, text: str) -> int | float:
        try:
            value = self.kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"'{text}' is not {self._noun}") from None
        if not math.isfinite(value) or value > self.high or value < self.low or (self.above_low and value == self.low):
            raise argparse.ArgumentTypeError(f"'{text}' is out of range: give {self._noun} {self}")
        return value

    @property
    def _noun(self) -> str:
        return "a whole number" if self.kind is int else "a number"

    def __str__(self) -> str:
        unit = f" {self.unit}" if self.unit else ""
        low = f"> {self.low:g}" if self.above_low else f"≥ {self.low:g}"
        if self.kind is int:
            return f"from {self.low:,} to {self.high:,}{unit}"
        return f"{low} and ≤ {self.high:g}{unit}"


DAY_S = 86_400.0
CASES = NumberRange(int, 1, 1_000_000)
SEED = NumberRange(int, 0, 2**64 - 1)  # the test case schema's seed range
CAMPAIGN_SEED = NumberRange(int, 0, 2**63 - 1)  # kept in the journal's SQLite INTEGER column
PROCESSES = NumberRange(int, 1, 256)
RERUNS = NumberRange(int, 0, 100)
REPEATS = NumberRange(int, 1, 100)
DOMAIN_ID = NumberRange(int, 0, 232)  # ROS 2's valid domain ids
LISTEN_SECONDS = NumberRange(float, 0, 3600, "s", above_low=True)
WINDOW_SECONDS = NumberRange(float, 0, DAY_S, "s", above_low=True)
RUN_SECONDS = NumberRange(float, 0, 7 * DAY_S, "s", above_low=True)
THRESHOLD_M = NumberRange(float, 0, 1000, "m")
MAX_BUDGET_S = 30 * DAY_S


def _bounded(parser: argparse.ArgumentParser, flag: str, bounds: NumberRange, *, help: str = "",
             **kwargs: Any) -> None:
    """``parser.add_argument`` for a number option; its range is checked and said in ``--help``."""
    parser.add_argument(flag, type=bounds, help=f"{help} [{bounds}]".strip(), **kwargs)


def _budget(text: str) -> float:
    """A fuzz campaign's time budget in seconds, at most MAX_BUDGET_S (argparse ``type``)."""
    from astaa_deft.cli.commands.fuzz import parse_budget

    try:
        seconds = parse_budget(text)
    except InputError as exc:
        raise argparse.ArgumentTypeError("; ".join(f"{p.message} ({p.fix})" for p in exc.problems)) from None
    if not 0 < seconds <= MAX_BUDGET_S:
        raise argparse.ArgumentTypeError(f"'{text}' is out of range: give more than 0 s and at most "
                                         f"{MAX_BUDGET_S / DAY_S:g} days (e.g. 90s, 30m, 2h)")
    return seconds


def _cluster(text: str) -> str:
    """``--cluster``: a scheduler address as given, or ``local:K`` with K in PROCESSES (argparse ``type``)."""
    kind, sep, count = text.partition(":")
    if sep and kind == "local":
        if count:
            PROCESSES(count)
    elif "://" not in text:
        raise argparse.ArgumentTypeError(f"'{text}' is neither local:K nor a scheduler address like tcp://HOST:8786")
    return text


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    ignore_file_size_signal()  # past `ulimit -f` a write fails with EFBIG, reported, instead of killing the tool
    try:
        return args.func(args)
    except AstaaDeftError as exc:
        if exc.exit_code is None:  # an internal error escaping is a bug: keep its traceback
            raise
        for line in exc.user_lines():
            print(f"astaa-deft: error: {line}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print("astaa-deft: interrupted", file=sys.stderr)
        return 130

