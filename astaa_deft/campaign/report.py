"""The campaign's report: one static, self-contained HTML page built from the journal alone.

Summary, a table of buckets (verdict, invariant, culprit, rate, minimal XML,
links to the log and the module tests), and plots (new buckets over cases
and over time, verdict classes, closest approach per invariant by strategy,
time per case) as embedded base64 PNGs: the page opens from a file, offline.
"""

from __future__ import annotations

import base64
import html
import io
import json
import os
import time
from pathlib import Path

from .journal import Journal, open_existing
from .model import BASELINE, MUTATED

REPORT_NAME = "report.html"

CSS = """
body{font-family:system-ui,sans-serif;margin:2em;max-width:1150px;color:#222}
table{border-collapse:collapse;width:100%;font-size:13px}td,th{border:1px solid #ccc;padding:4px 6px;
vertical-align:top;text-align:left}th{background:#f0f0f0}pre{white-space:pre-wrap;font-size:11px;margin:0;
max-height:14em;overflow:auto;background:#fafafa}.bad{color:#a00;font-weight:bold}.ok{color:#070}
.plots img{width:48%;margin:1%}.muted{color:#777}
"""


def write_report(out: Path) -> Path:
    journal = open_existing(out)
    try:
        page = render(journal, out)
    finally:
        journal.close()
    path = out / REPORT_NAME
    tmp = path.with_suffix(".html.tmp")
    tmp.write_text(page)
    os.replace(tmp, path)  # never a half-written report
    return path


def _rel(path: str | None, out: Path) -> str | None:
    if not path:
        return None
    try:
        return os.path.relpath(path, out.resolve())
    except ValueError:
        return path


def render(journal: Journal, out: Path) -> str:
    meta = journal.meta()
    rows = journal.cases()
    done = [r for r in rows if r["status"] in ("done", "error")]
    mutated = [r for r in done if r["kind"] == MUTATED]
    failing = [r for r in mutated if r["verdict"] not in ("Pass", "?", None)]
    errors = [r for r in done if r["status"] == "error"]
    buckets = journal.buckets()
    minimised = journal.minimisations()
    live = [b for b in buckets if b.merged_into is None]
    e = html.escape
    parts = [f"<!doctype html><html><head><meta charset='utf-8'><title>astaa-deft campaign</title>"
             f"<style>{CSS}</style></head><body>",
             "<h1>astaa-deft campaign</h1>",
             "<h2>Summary</h2><table>"]
    summary = [("spec", meta.get("spec")), ("strategy", meta.get("strategy")), ("seed", meta.get("seed")),
               ("params", json.dumps(meta.get("params"))), ("horizon", f"{meta.get('horizon')} s"),
               ("baseline runs", len([r for r in done if r["kind"] == BASELINE])),
               ("generated cases run", len(mutated)), ("failing cases", len(failing)),
               ("cases that could not run", len(errors)),
               ("buckets", f"{len(live)} ({sum(1 for b in live if b.without_mutation)} without mutation,"
                           f" {len(buckets) - len(live)} merged)"),
               ("wall time", f"{_wall(done):.0f} s"), ("generated", time.strftime("%Y-%m-%d %H:%M:%S UTC",
                                                                                  time.gmtime()))]
    parts += [f"<tr><th>{e(k)}</th><td>{e(str(v))}</td></tr>" for k, v in summary]
    parts.append("</table><h2>Buckets</h2>")
    if not buckets:
        parts.append("<p class='ok'>No failures found.</p>")
    else:
        parts.append("<table><tr><th>bucket</th><th>verdict</th><th>invariant</th><th>module</th>"
                     "<th>mutation family</th><th>culprit (minimised)</th><th>cases</th><th>rate</th>"
                     "<th>minimal test case</th><th>files</th></tr>")
        for b in buckets:
            first = journal.case(b.first_case)
            m = minimised.get(b.bucket)
            fails, runs = journal.rate(b)
            rate = f"{fails}/{runs}" if runs else "-"
            links = []
            log = _rel(first["log_path"] if first is not None else None, out)
            if log:
                links.append(f"<a href='{e(log)}'>log (MCAP, opens in Foxglove)</a>")
            if m is not None and m["tests_dir"]:
                links.append(f"<a href='{e(_rel(m['tests_dir'], out))}'>module tests</a>")
            if m is not None and m["out_dir"]:
                links.append(f"<a href='{e(_rel(m['out_dir'], out))}'>minimisation</a>")
            xml = m["minimal_xml"] if m is not None and m["minimal_xml"] else (first["testcase_xml"] or "") \
                if first is not None else ""
            label = "" if m is not None and m["minimal_xml"] else "<span class='muted'>(not minimised)</span>"
            family = "without mutation" if b.without_mutation else b.family
            merged = f"<br><span class='muted'>merged into {e(b.merged_into)}</span>" if b.merged_into else ""
            culprit = e(m["culprit"] or m["status"]) if m is not None else "-"
            parts.append(f"<tr><td>{e(b.bucket)}{merged}</td><td class='bad'>{e(b.verdict)}</td>"
                         f"<td>{e(b.invariant)}</td><td>{e(b.module or '-')}</td><td>{e(family)}</td>"
                         f"<td>{culprit}</td><td>{b.cases}</td><td>{rate}</td>"
                         f"<td>{label}<pre>{e(xml)}</pre></td><td>{'<br>'.join(links)}</td></tr>")
        parts.append("</table>")
    parts.append("<h2>Plots</h2><div class='plots'>")
    for title, png in _plots(journal, done, buckets):
        parts.append(f"<img alt='{e(title)}' title='{e(title)}' src='data:image/png;base64,{png}'>")
    parts.append("</div></body></html>")
    return "\n".join(parts)


def _wall(done) -> float:
    starts = [r["started_at"] for r in done if r["started_at"]]
    ends = [r["finished_at"] for r in done if r["finished_at"]]
    return (max(ends) - min(starts)) if starts and ends else 0.0


def _plots(journal: Journal, done, buckets) -> list[tuple[str, str]]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = []
    ordered = sorted(done, key=lambda r: r["finished_at"] or 0)
    t0 = min((r["started_at"] for r in ordered if r["started_at"]), default=0.0)
    firsts = {b.first_case for b in buckets}
    xs, ts, ys, count = [0], [0.0], [0], 0
    for n, r in enumerate(ordered, start=1):
        if r["case_id"] in firsts:
            count += 1
        xs.append(n)
        ts.append((r["finished_at"] or t0) - t0)
        ys.append(count)
    fig, (a, b) = plt.subplots(1, 2, figsize=(8, 3.2))
    a.step(xs, ys, where="post")
    a.set_xlabel("cases finished")
    a.set_ylabel("buckets")
    b.step(ts, ys, where="post", color="tab:orange")
    b.set_xlabel("seconds")
    fig.suptitle("New buckets over cases and time")
    out.append(("New buckets over cases and time", _png(fig, plt)))

    classes: dict[str, int] = {}
    for r in done:
        classes[r["verdict"] or "?"] = classes.get(r["verdict"] or "?", 0) + 1
    fig, ax = plt.subplots(figsize=(5, 3.2))
    ax.bar(list(classes), list(classes.values()), color="tab:red")
    ax.set_title("Verdict classes (all runs)")
    out.append(("Verdict classes", _png(fig, plt)))

    closest: dict[tuple[str, str], list[tuple[int, float]]] = {}
    for n, r in enumerate(ordered, start=1):
        if r["kind"] != MUTATED or not r["outcome"]:
            continue
        for inv, margin in json.loads(r["outcome"]).get("margins", {}).items():
            series = closest.setdefault((r["strategy"], inv), [])
            best = min(margin, series[-1][1]) if series else margin
            series.append((n, best))
    fig, ax = plt.subplots(figsize=(5, 3.2))
    for (strategy, inv), series in sorted(closest.items()):
        ax.step([p[0] for p in series], [p[1] for p in series], where="post", label=f"{inv} ({strategy})")
    if closest:
        ax.legend(fontsize=6)
    ax.set_xlabel("cases finished")
    ax.set_ylabel("closest approach (0 = broke)")
    ax.set_title("Closest approach per invariant")
    out.append(("Closest approach per invariant, by strategy", _png(fig, plt)))

    fig, ax = plt.subplots(figsize=(5, 3.2))
    ax.hist([r["seconds"] for r in done if r["seconds"] is not None] or [0], bins=20, color="tab:green")
    ax.set_xlabel("seconds per case")
    ax.set_title("Time per case")
    out.append(("Time per case", _png(fig, plt)))
    return out


def _png(fig, plt) -> str:
    buf = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buf, format="png", dpi=80)
    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode()
