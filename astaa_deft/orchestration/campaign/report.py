"""The campaign's report: one static, self-contained HTML page built from the journal alone.

A headline that counts confirmed bugs by severity apart from unconfirmed,
flaky and clean-run failures and names the most severe finding
(``standing.py``), a summary, a table of buckets ranked by status, severity
and rate (status and its evidence, severity, verdict, invariant, culprit,
rate, minimal XML, links to the log and the module tests, and whether those
fail on the bucket's defect), and plots (new buckets over cases
and over time, verdict classes, closest approach per invariant by strategy,
time per case) as embedded base64 PNGs: the page opens from a file, offline.

Escaped by construction: the page is one Jinja2 template with autoescape on
(``_TEMPLATE``); the functions below hand it plain values and rows, never
HTML, so no journal cell — whatever its declared type — reaches the page
as markup.
"""

from __future__ import annotations

import base64
import io
import json
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

import jinja2

from astaa_deft.model.records import Verdict
from astaa_deft.io.output_place import Place, ready_dir, write_atomic, writing
from astaa_deft.orchestration.campaign.campaign import REPLAY_TESTS_SUFFIX
from astaa_deft.orchestration.campaign.module_level import status_lines as module_level_status
from astaa_deft.orchestration.journal.journal import Journal, open_existing
from astaa_deft.orchestration.journal.model import BASELINE, MUTATED, CaseStatus
from astaa_deft.orchestration.journal.rows import Bucket, CampaignMeta, CaseRow, MinimisationRow, ModuleTestsRow
from astaa_deft.orchestration.campaign.standing import CONFIRMED, Standing, headline, most_severe, standings

if TYPE_CHECKING:  # matplotlib is imported when the plots are drawn, not with the module
    from matplotlib.figure import Figure

REPORT_NAME = "report.html"
PLOTTED_MOST = 1e12  # a closest approach beyond this is off any plot's scale (left out)

CSS = """
body{font-family:system-ui,sans-serif;margin:2em auto;max-width:1150px;padding:0 1em;color:#222}
table{border-collapse:collapse;width:100%;font-size:13px;table-layout:auto}td,th{border:1px solid #ccc;
padding:4px 6px;vertical-align:top;text-align:left}th{background:#f0f0f0;white-space:nowrap}
td.family,td.culprit{overflow-wrap:anywhere}
table.summary{width:auto}table.summary th{width:14em}
pre{white-space:pre-wrap;font-size:11px;margin:4px 0 0;max-height:18em;overflow:auto;background:#fafafa;
padding:4px}.bad{color:#a00;font-weight:bold}.ok{color:#070;font-weight:bold}.muted{color:#777}
tr.xml td{border-top:none;background:#fcfcfc}details summary{cursor:pointer;color:#345}
.family div{white-space:nowrap}.headline{font-size:1.15em}
.plots{display:grid;grid-template-columns:1fr 1fr;gap:12px}.plots img{width:100%;border:1px solid #eee}
"""
VERDICT_COLOURS = {Verdict.PASS: "#2a9d4b", Verdict.HINDERING: "#e0a030", Verdict.SILENT: "#d05a1e",
                   Verdict.ABORT: "#b3202a", Verdict.RESTART: "#7a2ca0", Verdict.CATASTROPHIC: "#222222",
                   "?": "#999999"}


# The page. Every {{ value }} is escaped by Jinja2 (autoescape on, no |safe anywhere): the Python code hands it
# plain values only — text, numbers, rows — never HTML.
_TEMPLATE = """<!doctype html><html><head><meta charset='utf-8'><title>astaa-deft campaign: {{ spec_name }}</title>
<style>{{ css }}</style></head><body>
<h1>astaa-deft campaign: {{ spec_name }}</h1>
<p class='headline'><span class='{{ 'bad' if confirmed else 'ok' }}'>{{ headline }}</span> in {{ mutated }} \
generated case(s) and {{ clean }} clean run(s).</p>
{% if most_severe is not none %}<p>most severe: <b>{{ most_severe }}</b></p>\
{% else %}<p class='ok'>no failure caused by a mutation</p>{% endif %}
<h2>Summary</h2><table class='summary'>
{% for key, value in summary %}<tr><th>{{ key }}</th><td>{{ value }}</td></tr>
{% endfor %}</table><h2>Buckets</h2>
{% if not buckets %}<p class='ok'>No failures found.</p>
{% else %}<table><tr><th>bucket</th><th>status</th><th>severity</th><th>verdict</th><th>invariant</th>\
<th title='the module that died, or whose output broke the invariant: not the module to blame (see Blame)'>\
seen at</th><th>mutation family</th><th>culprit (minimised)</th><th>cases</th>\
<th title='re-runs of the first failure that failed the same way'>rate</th><th>files</th></tr>
{% for row in buckets %}{% set b = row.bucket %}\
<tr id='{{ b.bucket }}'><td><b>{{ b.bucket }}</b>\
{% if b.merged_into %}<br><span class='muted'>merged into {{ b.merged_into }}</span>{% endif %}</td>\
<td>{% if row.standing is not none %}<span class='{{ 'bad' if row.confirmed else 'muted' }}'>\
{{ row.standing.status }}</span><br><span class='muted'>{{ row.standing.why }}</span>{% endif %}</td>\
<td>{{ row.standing.severity if row.standing is not none else '' }}</td>\
<td style='color:{{ row.colour }};font-weight:bold'>{{ b.verdict }}</td>\
<td>{{ b.invariant }}</td><td>{{ b.module or '-' }}</td>\
<td class='family'>{% if b.without_mutation %}<span class='muted'>without mutation</span>\
{% else %}{% for part in row.family %}<div>{{ part }}</div>{% endfor %}{% endif %}</td>\
<td class='culprit'>{% if row.culprit is not none %}{{ row.culprit }}\
{% else %}<span class='muted'>not minimised: {{ row.not_minimised }}</span>{% endif %}</td>\
<td>{{ b.cases }}</td><td>{{ row.rate }}</td><td>\
{% for link in row.links %}{% if not loop.first %}<br>{% endif %}\
{% if link.what == 'log' %}<a href='{{ link.href }}'>failing log</a> \
<span class='muted'>(MCAP: Foxglove opens it)</span>\
{% elif link.what == 'tests' %}<a href='{{ link.href }}'>module tests</a> \
<span class='muted'>({{ link.tests_kind }}; <code>pytest {{ link.href }}</code>)</span>\
{% if link.tests is not none %}{% if link.tests.fails_on_defect is true %}\
<br><span class='ok'>fail on the defect</span> <span class='muted'>({{ link.tests.detail }})</span>\
{% elif link.tests.fails_on_defect is false %}\
<br><span class='bad'>do not fail on the defect</span> <span class='muted'>({{ link.tests.detail }})</span>\
{% else %}<br><span class='muted'>could not run ({{ link.tests.detail }})</span>{% endif %}{% endif %}\
{% else %}<a href='{{ link.href }}'>minimisation</a>{% endif %}{% endfor %}</td></tr>
{% if row.xml %}<tr class='xml'><td></td><td colspan='10'><details{{ ' open' if row.minimal else '' }}>\
<summary>{{ 'minimal test case' if row.minimal else 'first failing test case (not minimised)' }} (XML)</summary>\
<pre>{{ row.xml }}</pre></details></td></tr>
{% endif %}{% endfor %}</table><p class='muted'>status: confirmed — a re-run failed the same way, or the minimal \
test case failed live; fault alone — reproduced, but the fault alone breaks the invariant through a plant (the \
simulator carries the mutated value on) and no module under test is involved (not counted as a bug); \
unconfirmed — no re-run reproduced it (not counted as a bug); flaky — the campaign's run without mutation failed \
too; without mutation — clean runs fail this way. Ranked by status, severity, rate. \
rate: re-runs of a bucket's first failure that failed the same way (for a bucket without mutation: clean runs \
that failed this way). cases: generated cases filed in the bucket.</p>
{% endif %}{% if blames %}<h2>Blame</h2><table><tr><th>bucket</th><th>module to blame</th><th>chain</th>\
<th>evidence</th><th>same root cause (merged)</th></tr>
{% for r in blames %}<tr><td><b>{{ r.bucket }}</b></td><td>{{ r.module }}</td><td>{{ r.chain }}</td>\
<td class='muted'>{{ r.evidence }}{% if r.replay %}<br>confirmed: {{ r.replay }}{% endif %}</td>\
<td>{% for m in r.merged %}<div>{{ m }}</div>{% endfor %}</td></tr>
{% endfor %}</table>
{% endif %}{% if verification %}<h2>Verification</h2><p class='muted'>Each bucket re-checked against the \
stack (astaa-deft verify): its test case run live beside unmutated twins. fixed — no run failed; still failing — \
runs failed its way (k/N); changed — they fail another way; flaky — its unmutated twins fail that way too.</p>
<table><tr><th>bucket</th><th>now</th><th>on</th><th>runs failing its way</th><th>history</th>\
<th>every check (oldest first)</th></tr>
{% for v in verification %}<tr><td><a href='#{{ v.bucket }}'>{{ v.bucket }}</a></td>\
<td><span class='{{ 'ok' if v.status == 'fixed' else 'bad' }}'>{{ v.status }}</span></td>\
<td>{{ v.revision }}</td><td>{{ v.stability }}</td><td>{{ v.history }}</td>\
<td>{% for c in v.checks %}{% if not loop.first %}<br>{% endif %}{{ c }}{% endfor %}</td></tr>
{% endfor %}</table>
{% endif %}{% if module_level %}<h2>Module level</h2><p class='muted'>Generated faults replayed against each \
module the spec can replay, on its frames from a clean run; each finding's fault run live beside unmutated \
twins (module-level only: its live case did not fail).</p><ul>{% for line in module_level %}<li>{{ line }}\
</li>{% endfor %}</ul>
{% endif %}<h2>Plots</h2><div class='plots'>
{% for title, png in plots %}<img alt='{{ title }}' title='{{ title }}' src='data:image/png;base64,{{ png }}'>
{% endfor %}</div></body></html>
"""
_PAGE = jinja2.Environment(autoescape=True, undefined=jinja2.StrictUndefined,
                           keep_trailing_newline=True).from_string(_TEMPLATE, globals={"css": CSS})


def write_report(out: Path) -> Path:
    """Render the campaign in ``out`` into ``out/report.html``; its path.

    InputError when ``out`` holds no campaign; OutputError (before rendering)
    when the folder cannot take the report, or when writing it fails.
    """
    journal = open_existing(out)
    place = Place(out, "the campaign folder (copy it somewhere writable)")
    try:
        ready_dir(place)  # before rendering: OutputError if the report cannot be written there
        page = render(journal, out)
    finally:
        journal.close()
    path = out / REPORT_NAME
    with writing(place):
        write_atomic(path, page)  # never a half-written report
    return path


def _rel(path: object, out: Path) -> str | None:
    """``path`` relative to the campaign folder (as given when it is on another drive)."""
    if not path:
        return None
    try:
        return os.path.relpath(str(path), out.resolve())
    except ValueError:
        return str(path)


@dataclass(frozen=True, kw_only=True)
class _Cases:
    """The journal's cases as the report counts them."""

    done: list[CaseRow]  # finished (done or error)
    mutated: list[CaseRow]  # finished generated cases
    failing: list[CaseRow]  # of those, the ones that failed
    errors: list[CaseRow]  # finished cases that could not run
    clean: int  # finished baseline runs

    @classmethod
    def of(cls, rows: list[CaseRow]) -> _Cases:
        done = [r for r in rows if r.finished]
        mutated = [r for r in done if r.kind == MUTATED]
        return cls(done=done, mutated=mutated,
                   failing=[r for r in mutated if r.verdict not in (Verdict.PASS, "?", None)],
                   errors=[r for r in done if r.status == CaseStatus.ERROR],
                   clean=len([r for r in done if r.kind == BASELINE]))


def render(journal: Journal, out: Path) -> str:
    """The report page of the campaign ``journal`` describes (links relative to ``out``): self-contained HTML.
    Reads the journal only; matplotlib draws the plots (Agg, no display needed).

    The page is the template ``PAGE`` filled with plain values: Jinja2 escapes every value it inserts
    (autoescape), so no journal cell — whatever its declared type, SQLite keeps what was written — reaches
    the page as markup."""
    meta = journal.meta()
    cases = _Cases.of(journal.cases())
    ranked = standings(journal)
    by_bucket = {s.bucket.bucket: s for s in ranked}
    buckets = [s.bucket for s in ranked] + [b for b in journal.buckets() if b.bucket not in by_bucket]  # merged last
    top = most_severe(ranked)
    return _PAGE.render(
        spec_name=Path(str(meta.spec or "?")).stem,
        confirmed=any(s.status == CONFIRMED for s in ranked),
        headline=headline(ranked), mutated=len(cases.mutated), clean=cases.clean,
        most_severe=top.describe() if top is not None else None,
        summary=_summary(meta, cases, buckets),
        buckets=_bucket_table(journal, out, buckets, by_bucket),
        blames=_blames(journal),
        verification=_verification(journal),
        module_level=module_level_status(out, journal),
        plots=_plots(journal, cases.done, buckets))


@dataclass(frozen=True, kw_only=True)
class _VerifiedRow:
    """A bucket's row of the verification table: where it stands now, its history, every check."""

    bucket: str
    status: str
    revision: str
    stability: str
    history: str
    checks: list[str]


def _verification(journal: Journal) -> list[_VerifiedRow]:
    """Each verified bucket's latest check and history (``astaa-deft verify``); none: the section is left out."""
    from astaa_deft.orchestration.journal.history import histories
    from astaa_deft.orchestration.journal.verifications import verifications

    rows = verifications(journal)
    out = []
    for name, seen in histories(rows).items():
        latest = seen.latest
        if latest is None:
            continue
        out.append(_VerifiedRow(bucket=name, status=str(latest.status), revision=latest.revision,
                                stability=latest.stability, history=seen.describe(),
                                checks=[f"{r.revision}: {r.status} ({r.stability})" for r in rows if r.bucket == name]))
    return out


def _summary(meta: CampaignMeta, cases: _Cases, buckets: list[Bucket]) -> list[tuple[str, object]]:
    """The summary table's rows: what the campaign was given and what it ran."""
    live = [b for b in buckets if b.merged_into is None]
    return [("spec", meta.spec), ("strategy", meta.strategy), ("seed", meta.seed),
            ("params", json.dumps(meta.params) if meta.params else "the spec's defaults"),
            ("horizon", f"{meta.horizon} s"),
            ("baseline runs", cases.clean),
            ("generated cases run", len(cases.mutated)), ("failing cases", len(cases.failing)),
            ("cases that could not run", len(cases.errors)),
            ("how runs ended", _end_reasons(cases.done)),
            ("buckets", f"{len(live)} ({sum(1 for b in live if b.without_mutation)} without mutation,"
                        f" {len(buckets) - len(live)} merged)"),
            ("wall time of the cases", f"{_wall(cases.done):.0f} s"),
            ("generated", time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()))]


@dataclass(frozen=True)
class _Link:
    """One of a bucket's files: the failing log, its module tests (with whether they fail on the defect),
    its minimisation."""

    what: str  # "log", "tests" or "minimisation"
    href: str
    tests_kind: str = ""  # for "tests": what the tests are
    tests: ModuleTestsRow | None = None  # for "tests": whether they fail on the defect


@dataclass(frozen=True, kw_only=True)
class _BucketRow:
    """A bucket's row of the buckets table, and its test case's XML (minimal, or the first failing one)."""

    bucket: Bucket
    standing: Standing | None
    confirmed: bool
    colour: str
    family: list[str]  # one part a line
    culprit: str | None  # None: not minimised
    not_minimised: str  # why it was not, when culprit is None
    rate: str
    links: list[_Link]
    xml: str
    minimal: bool


def _bucket_table(journal: Journal, out: Path, buckets: list[Bucket],
                  by_bucket: dict[str, Standing]) -> list[_BucketRow]:
    """The buckets table's rows (ranked, merged ones last); none: the page says there was no failure."""
    minimised = journal.minimisations()
    checked = journal.module_tests()
    minimising = journal.meta().minimise
    rows = []
    for b in buckets:
        fails, runs = journal.rate(b)
        standing = by_bucket.get(b.bucket)
        first, m = journal.case(b.first_case), minimised.get(b.bucket)
        minimal_xml = m.minimal_xml if m is not None else None  # else the first failing test case's XML, if any
        xml = minimal_xml or ((first.testcase_xml or "") if first is not None else "")
        rows.append(_BucketRow(
            bucket=b, standing=standing, confirmed=standing is not None and standing.status == CONFIRMED,
            colour=VERDICT_COLOURS.get(b.verdict, "#a00"),
            family=[] if b.without_mutation else str(b.family).split("+"),
            culprit=(m.culprit or m.status) if m is not None else None,
            not_minimised=not_minimised_why(b, standing, minimising), rate=f"{fails}/{runs}" if runs else "-",
            links=_links(first, m, checked.get(b.bucket), out), xml=str(xml), minimal=bool(minimal_xml)))
    return rows


def not_minimised_why(bucket: Bucket, standing: Standing | None, minimising: bool | None) -> str:
    """Why a bucket has no minimisation: the campaign's setting, the bucket's standing, or the campaign's end."""
    if bucket.merged_into:
        return f"merged into {bucket.merged_into}"
    if minimising is False:
        return "minimisation was off for this campaign (fuzz --no-minimise; the demo's short campaign)"
    if not bucket.is_bug:
        status = standing.status if standing is not None else bucket.kind
        return f"only reproduced buckets are minimised, and this one is {status}"
    return "the campaign ended before its turn (astaa-deft fuzz --resume minimises it)"


def _blames(journal: Journal) -> list[_BlameRow]:
    """Which module is to blame for each confirmed bucket (blame.py: the first whose output departed from the
    unmutated twins'), the chain, and the buckets merged into it as one root cause, each with its culprit."""
    blames = journal.blames()
    if not blames:
        return []
    buckets = journal.buckets()
    rows = []
    for b in buckets:
        row = blames.get(b.bucket)
        if row is None or b.merged_into:
            continue
        rows.append(_BlameRow(
            bucket=b.bucket, module=row.root_cause or "?", chain=row.chain,
            evidence=f"{row.detail} ({row.twins} twin(s))", replay=row.replay or "",
            merged=[f"{m.bucket}: {m.family}" for m in buckets if m.merged_into == b.bucket]))
    return rows


@dataclass(frozen=True, kw_only=True)
class _BlameRow:
    """A confirmed bucket's row of the blame table."""

    bucket: str
    module: str
    chain: str
    evidence: str
    replay: str  # how a module replay confirmed the blame ("" when none did)
    merged: list[str]  # the buckets merged into it, each with its culprit family


def _links(first: CaseRow | None, m: MinimisationRow | None, checked: ModuleTestsRow | None,
           out: Path) -> list[_Link]:
    """A bucket's files: its failing log, its module tests (and whether they fail on the defect), its
    minimisation."""
    links = []
    log = _rel(first.log_path if first is not None else None, out)
    if log:
        links.append(_Link("log", log))
    tests = _rel(m.tests_dir, out) if m is not None else None
    if m is not None and tests:
        kind = ("DeFT replay of the failing run" if str(m.tests_dir).endswith(REPLAY_TESTS_SUFFIX)
                else "fail on the culprit")
        links.append(_Link("tests", tests, kind, checked))
    minimisation = _rel(m.out_dir, out) if m is not None else None
    if minimisation:
        links.append(_Link("minimisation", minimisation))
    return links


def _end_reasons(done: list[CaseRow]) -> str:
    """How the runs ended (the spec's run: reasons, violations, the horizon), most frequent first."""
    counts: dict[str, int] = {}
    for r in done:
        outcome = r.outcome()
        reason = (outcome.reason if outcome is not None else None) or r.status
        counts[reason] = counts.get(reason, 0) + 1
    return ", ".join(f"{reason} {n}" for reason, n in sorted(counts.items(), key=lambda kv: -kv[1])) or "-"


def _wall(done: list[CaseRow]) -> float:
    starts = [r.started_at for r in done if r.started_at]
    ends = [r.finished_at for r in done if r.finished_at]
    return (max(ends) - min(starts)) if starts and ends else 0.0


def _plots(journal: Journal, done: list[CaseRow], buckets: list[Bucket]) -> list[tuple[str, str]]:
    """The report's plots, (title, base64 PNG) each."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    out = []
    ordered = sorted(done, key=lambda r: r.finished_at or 0)
    t0 = min((r.started_at for r in ordered if r.started_at), default=0.0)
    firsts = {b.first_case for b in buckets}
    xs, ts, ys, count = [0], [0.0], [0], 0
    for n, r in enumerate(ordered, start=1):
        if r.case_id in firsts:
            count += 1
        xs.append(n)
        ts.append((r.finished_at or t0) - t0)
        ys.append(count)
    fig, (a, b) = plt.subplots(1, 2, figsize=(5, 3.2))
    a.step(xs, ys, where="post")
    a.set_xlabel("cases finished")
    a.set_ylabel("buckets")
    b.step(ts, ys, where="post", color="tab:orange")
    b.set_xlabel("seconds")
    for axis in (a, b):
        axis.yaxis.set_major_locator(MaxNLocator(integer=True))
    a.xaxis.set_major_locator(MaxNLocator(integer=True))
    fig.suptitle("New buckets over cases and time")
    out.append(("New buckets over cases and time", _png(fig, plt)))

    classes: dict[str, int] = {}
    for r in done:
        label = _label(r.verdict or "?")
        classes[label] = classes.get(label, 0) + 1
    fig, ax = plt.subplots(figsize=(5, 3.2))
    ax.bar(list(classes), list(classes.values()), color=[VERDICT_COLOURS.get(c, "#a00") for c in classes])
    ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_title("Verdict classes (all runs)")
    out.append(("Verdict classes", _png(fig, plt)))

    closest: dict[tuple[str, str], list[tuple[int, float]]] = {}
    for n, r in enumerate(ordered, start=1):
        outcome = r.outcome() if r.kind == MUTATED else None
        if outcome is None:
            continue
        for inv, margin in outcome.margins.items():
            if not math.isfinite(margin) or abs(margin) > PLOTTED_MOST:  # off any useful scale
                continue
            series = closest.setdefault((_label(r.strategy), _label(inv)), [])
            best = min(margin, series[-1][1]) if series else margin
            series.append((n, best))
    fig, ax = plt.subplots(figsize=(5, 3.2))
    last = len(ordered)
    for (strategy, inv), series in sorted(closest.items()):
        # Held to the last case finished, with a mark per case: a series of one case still draws its line.
        xs_, ys_ = [p[0] for p in series], [p[1] for p in series]
        if xs_[-1] < last:
            xs_, ys_ = [*xs_, last], [*ys_, ys_[-1]]
        ax.step(xs_, ys_, where="post", marker="o", markersize=2.5, label=f"{inv} ({strategy})")
    if closest:
        ax.legend(fontsize=6)
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel("cases finished")
    ax.set_ylabel("closest approach (0 = broke)")
    ax.set_title("Closest approach per invariant")
    out.append(("Closest approach per invariant, by strategy", _png(fig, plt)))

    fig, ax = plt.subplots(figsize=(5, 3.2))
    ax.hist([r.seconds for r in done if r.seconds is not None] or [0], bins=20, color="tab:green")
    ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel("seconds per case (wall time of one run)")
    ax.set_ylabel("cases")
    ax.set_title("Time per case")
    out.append(("Time per case", _png(fig, plt)))
    return out


def _label(text: str) -> str:
    """A plot's label, short: a journal cell may hold anything, and laying out a long label takes forever."""
    return text if len(text) <= 40 else text[:39] + "…"


def _png(fig: Figure, plt: ModuleType) -> str:
    """The figure as a base64 PNG (the figure is closed)."""
    buf = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buf, format="png", dpi=80)
    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode()
