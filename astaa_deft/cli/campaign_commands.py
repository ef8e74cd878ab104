"""The `fuzz` and `report` commands' arguments (campaigns).

Declared here, beside the other commands' parsers, while the work and the
printing stay in :mod:`astaa_deft.cli.commands.fuzz` and
:mod:`astaa_deft.cli.commands.report`.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from astaa_deft.cli.arguments import (
    CAMPAIGN_SEED,
    CASES,
    DAY_S,
    MAX_BUDGET_S,
    PROCESSES,
    RERUNS,
    WINDOW_SECONDS,
    bounded,
    budget,
    cluster,
)
from astaa_deft.model.errors import InputError, Problem
from astaa_deft.model.registry import NamesOf

if TYPE_CHECKING:
    from astaa_deft.cli.arguments import SubParsers


def _strategy_names() -> tuple[str, ...]:
    from astaa_deft.orchestration.campaign.strategies import STRATEGIES  # imported when --strategy is read

    return STRATEGIES.names()


FUZZ_EXAMPLES = """\
examples:
  astaa-deft fuzz --spec specs/demo_av.yaml -o campaign/ --budget 10m
  astaa-deft fuzz --spec sut.yaml -o campaign/ --resume   # after Ctrl-C or a crash
  astaa-deft fuzz -o campaign/ --status
  astaa-deft fuzz --spec sut.yaml -o campaign/ --cases 200 --cluster tcp://127.0.0.1:8786"""


def add_fuzz_parser(subparsers: SubParsers) -> None:
    """Declare the `fuzz` command."""
    fz = subparsers.add_parser("fuzz", help="a campaign: generated test cases, each a fresh run; failures bucketed, "
                                            "re-run for their rate, minimised, reported",
                             epilog=FUZZ_EXAMPLES)
    fz.add_argument("--spec", type=Path,
                    help="the SUT spec (YAML; default with --resume: none — the campaign's only with "
                         "--trust-journal-spec)")
    fz.add_argument("-o", "--out", type=Path, required=True, help="the campaign directory (journal, logs, report)")
    bounded(fz, "--cases", CASES, help="generated cases to run (default: as many as --budget allows)")
    fz.add_argument("--budget", type=budget,
                    help=f"or a time budget: 90s, 30m, 2h [at most {MAX_BUDGET_S / DAY_S:g} days] (default: none; "
                         f"give --cases, --budget or both)")
    bounded(fz, "--workers", PROCESSES, help="cases at once (default: measured from the cores and one run's "
                                             "cost; with --cluster, the "
                                                "cluster's worker count)")
    bounded(fz, "--seed", CAMPAIGN_SEED, default=0, help="the campaign's seed (default 0)")
    fz.add_argument("--strategy", default="random", choices=NamesOf(_strategy_names), metavar="STRATEGY",
                    help="how cases are drawn, one of: %(choices)s (default random: ASTAA's weighted generation; "
                         "decictor looks for non-optimal decisions: docs/decictor.md)")
    fz.add_argument("--dictionary", type=Path, action="append", default=[],
                    help="an exceptional-value dictionary on top of the default one (repeatable; default: the "
                         "bundled one only)")
    fz.add_argument("--params", nargs="+", default=[], metavar="KEY=V1,V2",
                    help="spread cases over these values (default: the spec's params as declared)")
    bounded(fz, "--horizon", WINDOW_SECONDS, default=None,
            help="seconds a run lasts at most (default: from the stack — clean runs go to the scenario's end,"
                 " capped by the spec's run: time_limit, and cases at most 1.25 × the longest)")
    bounded(fz, "--settle", WINDOW_SECONDS, default=3.0,
            help="seconds a mutated case runs on after its last mutation could act")
    bounded(fz, "--baseline", RERUNS, default=2, help="clean runs first, per value of the --params grid")
    bounded(fz, "--reruns", RERUNS, default=2,
            help="re-runs of a new failure and as many unmutated twins, before it is filed as a bug")
    fz.add_argument("--no-minimise", action="store_true",
                    help="do not minimise the buckets, nor write their module tests (default: minimise)")
    fz.add_argument("--no-module-level", action="store_true",
                    help="run every case live: no module-level search (replays of the spec's replayable modules"
                         " under generated faults, each finding confirmed live) before the live hunt (default: "
                         "the search runs when the spec can replay a module)")
    bounded(fz, "--module-level-seconds", WINDOW_SECONDS, default=None,
            help="seconds the module-level search may take (default: its share of --budget, decided from what"
                 " a first round and the live runs measured; else 120)")
    bounded(fz, "--minimise-timeout", WINDOW_SECONDS, default=300.0,
            help="seconds one bucket's minimisation may take (it holds a worker slot)")
    fz.add_argument("--resume", action="store_true", help="continue the campaign in -o, with --spec: your spec "
                                                          "(default: a new campaign; -o must be empty)")
    fz.add_argument("--trust-journal-spec", action="store_true",
                    help="with --resume and no --spec: run the spec the campaign's journal names (default: refuse "
                         "and list what that spec would run; a campaign folder is data)")
    fz.add_argument("--cluster", type=cluster,
                    help=f"tcp://HOST:8786 (a Dask scheduler) or local:K (K local worker processes) [K {PROCESSES}]"
                         " (default: no cluster, cases in local processes)")
    fz.add_argument("--status", action="store_true", help="print the campaign's state from its journal and exit "
                                                          "(default: run the campaign)")
    fz.set_defaults(func=run_fuzz)


def run_fuzz(args: argparse.Namespace) -> int:
    """The parsed `fuzz` arguments as a CampaignConfig, to :func:`astaa_deft.cli.commands.fuzz.run`.

    Raises InputError when neither a spec nor ``--resume`` is given, or no campaign size.
    """
    from astaa_deft.cli.commands import fuzz
    from astaa_deft.orchestration.campaign.campaign import CampaignConfig

    if args.status:
        return fuzz.status(args.out)
    if args.spec is None and not args.resume:
        raise InputError(Problem("astaa-deft fuzz", None, None, "no spec given",
                                 "give --spec sut.yaml (or --resume to go on with the campaign in -o DIR)"))
    if args.cases is None and args.budget is None and not args.resume:
        raise InputError(Problem("astaa-deft fuzz", None, None, "no size given for the campaign",
                                 "give --cases N or --budget DURATION (e.g. 10m)"))
    config = CampaignConfig(spec_path=args.spec or Path("."), out=args.out, cases=args.cases,
                            budget=args.budget, workers=args.workers,
                            seed=args.seed, strategy=args.strategy, dictionaries=args.dictionary,
                            params=fuzz.parse_params(args.params), cluster=args.cluster, horizon=args.horizon,
                            baseline_runs=args.baseline, reruns=args.reruns, minimise=not args.no_minimise,
                            settle=args.settle, minimise_timeout=args.minimise_timeout,
                            module_level=not args.no_module_level,
                            module_level_seconds=args.module_level_seconds)
    return fuzz.run(config, args.resume, spec_given=args.spec is not None,
                    trust_journal_spec=args.trust_journal_spec)


def add_report_parser(subparsers: SubParsers) -> None:
    """Declare the `report` command."""
    rep = subparsers.add_parser("report", help="regenerate a campaign's report.html from its journal",
                                epilog="example:\n  astaa-deft report campaign/ && xdg-open campaign/report.html")
    rep.add_argument("campaign", type=Path, help="a campaign directory (astaa-deft fuzz -o DIR)")
    rep.set_defaults(func=run_report)


def run_report(args: argparse.Namespace) -> int:
    """The parsed `report` arguments to :func:`astaa_deft.cli.commands.report.run`."""
    from astaa_deft.cli.commands import report

    return report.run(args.campaign)
