"""`astaa-deft fuzz`: a campaign of generated test cases (astaa_deft.orchestration.campaign does the work)."""

from __future__ import annotations

import re
from collections import Counter
import time
from pathlib import Path

from astaa_deft.orchestration.campaign.campaign import Campaign, CampaignConfig, CampaignStopped, StopReason
from astaa_deft.orchestration.journal.journal import FILE_NAME, Journal, open_existing
from astaa_deft.orchestration.campaign.progress import Progress, snapshot
from astaa_deft.orchestration.campaign.module_level import status_lines as module_level_status
from astaa_deft.orchestration.journal.rows import MinimisationRow, ModuleTestsRow
from astaa_deft.orchestration.campaign.standing import Standing, headline, most_severe, standings
from astaa_deft.orchestration.journal.history import histories
from astaa_deft.orchestration.journal.verifications import verifications
from astaa_deft.model.errors import InputError, Problem
from astaa_deft.io.output_place import Place, ready_dir, writing
from astaa_deft.cli.commands.console import PlainLines, say, stop_as_interrupt

DURATION = re.compile(r"^(\d+(?:\.\d+)?)\s*([smh]?)$")


def parse_budget(text: str) -> float:
    """Seconds of a ``--budget`` (90s, 30m, 2h; plain seconds); InputError for anything else."""
    match = DURATION.match(text.strip())
    if not match:
        raise InputError(Problem("--budget", None, None, f"'{text}' is not a duration", "write e.g. 90s, 30m or 2h"))
    return float(match.group(1)) * {"": 1, "s": 1, "m": 60, "h": 3600}[match.group(2)]


def parse_params(items: list[str]) -> dict[str, list[str]]:
    """``--params KEY=VALUE[,VALUE…]`` items as key → values; InputError for an item of another shape."""
    out: dict[str, list[str]] = {}
    for item in items:
        key, sep, values = item.partition("=")
        if not sep or not key or not values:
            raise InputError(Problem("--params", None, None, f"'{item}' is not KEY=VALUE[,VALUE…]",
                                     "write e.g. --params scenario=cut_in,red_light"))
        key = key.strip()
        given = [v.strip() for v in values.split(",")]
        example = f"e.g. --params {key}=cut_in,red_light"
        if key in out:
            raise InputError(Problem("--params", None, None, f"param '{key}' is given twice",
                                     f"give all its values in one item, {example}"))
        if not any(given):
            raise InputError(Problem("--params", None, None, f"'{item}' gives '{key}' no value", f"write {example}"))
        if not all(given):
            raise InputError(Problem("--params", None, None, f"'{item}' has an empty value",
                                     f"leave no empty value between the commas, {example}"))
        repeated = sorted({v for v, n in Counter(given).items() if n > 1})
        if repeated:
            raise InputError(Problem("--params", None, None, f"'{key}' lists '{repeated[0][:60]}' more than once",
                                     "list each value once (repeated values would only repeat the same runs)"))
        out[key] = given
    return out


def status(out: Path) -> int:
    """``fuzz --status``: the campaign in ``out`` as it stands (its buckets ranked, its notes); exit code 0.
    InputError when ``out`` holds no campaign."""
    journal = open_existing(out)
    meta = journal.meta()
    snap = snapshot(journal, meta.cases, 0.0)
    say(f"campaign {out}: spec {meta.spec}, strategy {meta.strategy}, seed {meta.seed}")
    say(snap.line().split(", 0.0 cases/min")[0])
    minimised = journal.minimisations()
    tests = journal.module_tests()
    ranked = standings(journal)
    say(headline(ranked))
    merged = [b for b in journal.buckets() if b.merged_into]
    checked = histories(verifications(journal))
    for standing in ranked:
        say(_bucket_line(standing, minimised.get(standing.bucket.bucket), tests.get(standing.bucket.bucket)))
        if standing.bucket.bucket in checked:
            say(f"      verified: {checked[standing.bucket.bucket].describe()}")
    for b in merged:
        say(f"  {b.bucket} merged into {b.merged_into}: {b.invariant} {b.family}")
    for name, blame in journal.blames().items():
        say(f"  {name} blame: {blame.root_cause or '?'}: {blame.chain}"
            + (f" — confirmed: {blame.replay}" if blame.replay else ""))
    for note in journal.notes("concurrency"):
        say(f"  {note.text}")
    for line in module_level_status(out, journal):
        say(f"  {line}")
    journal.close()
    return 0


def _bucket_line(standing: Standing, m: MinimisationRow | None, t: ModuleTestsRow | None) -> str:
    """One bucket of ``--status``: status, severity, failure, family, counts, minimisation, module tests."""
    b = standing.bucket
    rate = f"{standing.failures}/{standing.runs}" if standing.runs else "-"
    checked = ("" if t is None else " module tests fail on it" if t.fails_on_defect is True
               else " module tests do NOT fail on it" if t.fails_on_defect is False else " module tests did not run")
    twins = f" twins {b.control_failures}/{b.controls}" if b.controls else ""
    return (f"  {b.bucket} {standing.status:12} {standing.severity:8} {b.verdict:9} {b.invariant:22} {b.family:40}"
            f" cases {b.cases:3} rate {rate:5}{twins} {m.status if m else ''}"
            f"{' ' + m.culprit if m and m.culprit else ''}{checked}")


def run(config: CampaignConfig, resume: bool, *, spec_given: bool = True, trust_journal_spec: bool = False) -> int:
    """``fuzz``: run (or with ``resume`` continue) the campaign ``config`` describes; the exit code (0 no
    bucket, 1 buckets, 130 interrupted by Ctrl-C or SIGTERM: the summary and the line to resume). InputError
    for bad input or a SUT that does not start; OutputError when ``config.out`` cannot take the campaign."""
    place = Place(config.out, "-o")
    ready_dir(place, temp=True)  # before the journal and the baseline runs
    with writing(place), stop_as_interrupt():  # SIGTERM (timeout, a CI cancel) stops it as Ctrl-C does
        return _run(config, resume, spec_given=spec_given, trust_journal_spec=trust_journal_spec)


def _run(config: CampaignConfig, resume: bool, *, spec_given: bool, trust_journal_spec: bool) -> int:
    exists = (config.out / FILE_NAME).is_file()
    if exists and not resume:
        raise InputError(Problem(str(config.out), None, None, "a campaign is already here",
                                 "add --resume to continue it, or give another -o directory"))
    if resume and not exists:
        raise InputError(Problem(str(config.out), None, None, "no campaign to resume here",
                                 "drop --resume to start one"))
    from astaa_deft.engine.spec.loader import load_spec

    spec = None  # loaded once for the command: the campaign takes it as loaded here
    if not resume:  # bad --params (undeclared, outside the choices, a grid past the cap): no journal left behind
        from astaa_deft.orchestration.campaign.campaign import param_grid

        spec = load_spec(config.spec_path)
        param_grid(config.params, spec)
    journal = Journal(config.out)
    if resume:
        meta = journal.meta()
        if not spec_given:  # the spec the journal names runs only when the user vouches for it
            from astaa_deft.orchestration.campaign.journal_spec import journal_spec

            try:
                _, spec = journal_spec(journal.path, meta.spec, trusted=trust_journal_spec, command="fuzz --resume",
                                       why="the campaign's runs")
            except BaseException:
                journal.close()
                raise
        config = config.resuming(meta, keep_spec=spec_given)
    progress = Progress(journal, config.cases)
    lines = None if progress.live is not None else PlainLines("fuzz")  # not a terminal: the shared plain lines

    def on_progress(campaign: Campaign) -> None:
        if lines is None:
            progress(campaign.workers)
        else:
            lines.show(snapshot(journal, config.cases, time.monotonic() - progress.started).line())

    try:
        campaign = Campaign(config, journal, spec=spec if spec is not None else load_spec(config.spec_path),
                            on_progress=on_progress, say=progress.say)
        workers = ("runs at once calibrated from the baseline" if campaign.calibrated
                   else f"{campaign.workers} worker(s){' on ' + config.cluster if config.cluster else ''}")
        progress.say(f"astaa-deft fuzz: spec '{campaign.spec.name}', strategy {config.strategy}, seed {config.seed},"
                     f" {workers}, journal {journal.path}")
        result = campaign.run()
    except CampaignStopped as exc:
        progress.close()
        raise InputError(Problem(str(config.spec_path), None, None, f"campaign stopped: {exc}",
                                 "make the SUT start (try: astaa-deft proxy --spec … --duration 5)")) from None
    finally:
        progress.close()
        if lines is not None:
            lines.close()
    if config.report:
        from astaa_deft.orchestration.campaign.report import write_report

        say(f"report: {write_report(config.out)}")
    ranked = standings(journal)
    say(f"campaign {result.stopped}: {result.cases_done} cases in {result.seconds:.0f} s, "
        f"{result.failures} failing, {result.buckets} bucket(s): {headline(ranked)}")
    top = most_severe(ranked)
    if top is not None:
        say(f"most severe: {top.describe()}")
    if result.stopped == StopReason.INTERRUPTED:
        say(f"continue with: astaa-deft fuzz --spec {config.spec_path} -o {config.out} --resume")
        journal.close()
        return 130
    journal.close()
    return 1 if result.buckets else 0
