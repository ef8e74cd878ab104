"""What a Decictor campaign leaves behind: per non-optimal bucket, module tests and a path plot.

For each ``path_consistency`` bucket: DeFT extracts the planner frames of
its first case's run (``out/tests/<bucket>``), a path-consistency test is
added to them (``decictor.module_test``) and run once with the recorded
params (it must fail: the defect is in the frames' replay); the journal
records it where ASTAA buckets record their minimisation, so the campaign
report links the tests. ``out/decictor.html`` shows, per bucket, the seed
run's ego path against the mutated run's, with the participants.
"""

from __future__ import annotations

import base64
import html
import io
import json
import shutil
import time
from pathlib import Path
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

from astaa_deft.io.codecs import get_codec
from astaa_deft.analysis.decictor.module_test import check_suite, end_points, write_consistency_test
from astaa_deft.analysis.decictor.observe import observe_log
from astaa_deft.analysis.deft.planner_section import planner_of
from astaa_deft.analysis.deft.workflow import extract_module_tests
from astaa_deft.model.errors import InputError
from astaa_deft.io.log.reader import read_log
from astaa_deft.analysis.decictor.search import Scene
from astaa_deft.engine.intercept.actions.participant import Participant
from astaa_deft.orchestration.journal.journal import Journal
from astaa_deft.orchestration.journal.rows import CaseRow, Minimisation
from astaa_deft.orchestration.campaign.payload import read_testcase
from astaa_deft.orchestration.campaign.strategies.decictor import INVARIANT, scene_of

if TYPE_CHECKING:
    from astaa_deft.orchestration.campaign.strategies.decictor import DecictorStrategy

PAGE = "decictor.html"


def seed_plan_ends(strategy: DecictorStrategy, log_path: Path) -> list[tuple[float, float]]:
    spec = strategy.spec
    cfg = planner_of(spec)
    channel = spec.channel(cfg.output)
    codec = get_codec(channel.encoding)
    log = read_log(log_path)
    messages = [codec.decode(m.data) for m in sorted(log.on(channel.key), key=lambda m: m.log_time)]
    return end_points(messages, cfg.trajectory)


def export_findings(strategy: DecictorStrategy, journal: Journal, out: Path, *, say: Callable[[str], None]) -> None:
    """Each path-consistency bucket of ``journal`` as DeFT module tests under ``out/tests`` (journalled as the
    bucket's minimisation), and ``out/decictor.html``: seed vs mutated paths. Nothing without a seed run."""
    buckets = [b for b in journal.buckets(include_merged=False) if b.invariant == INVARIANT]
    if not buckets or strategy.seed_log is None:
        return
    seed_ends = seed_plan_ends(strategy, Path(strategy.seed_log))
    sections = []
    for bucket in buckets:
        row = journal.case(bucket.first_case)
        if row is None or not row.log_path or not Path(row.log_path).is_file() or row.testcase_xml is None:
            continue
        log = Path(row.log_path)
        started = time.monotonic()
        tests_dir = out / "tests" / bucket.bucket
        if tests_dir.exists():
            shutil.rmtree(tests_dir)
        say(f"decictor: module tests for {bucket.bucket} ({bucket.first_case}) …")
        try:
            report = extract_module_tests(log, strategy.spec, tests_dir)  # the campaign's spec, loaded once
            write_consistency_test(tests_dir, seed_ends, strategy.lanes, note=f"seed: {strategy.seed_log}")
            problem = check_suite(tests_dir, overrides="")
            status = "module tests (fail)" if problem else "module tests (pass: not reproduced)"
            detail = problem or "the replayed plans keep to the seed's lanes"
            detail = f"{report.accepted} frames; {detail}"
        except InputError as exc:
            status, detail = "error", "; ".join(map(str, exc.problems))
        testcase = read_testcase(row.testcase_xml, f"{journal.path}: {row.case_id}", strategy.spec)
        assert testcase is not None  # skipped above when the row holds none
        scene = scene_of(testcase)
        culprit = ", ".join(f"{p.kind} {p.id}" for p in scene.participants)
        journal.minimised(Minimisation(bucket=bucket.bucket, status=status,
                                       exit_code=1 if status.endswith("(fail)") else 0, minimal_xml=row.testcase_xml,
                                       culprit=culprit, out_dir=None, tests_dir=str(tests_dir),
                                       seconds=time.monotonic() - started, detail=detail))
        say(f"  {status}: {detail[:160]}")
        sections.append(_section(strategy, bucket.bucket, row, log, scene=scene))
    page = out / PAGE
    page.write_text("<!doctype html><meta charset='utf-8'><title>Decictor findings</title>"
                    "<style>body{font-family:system-ui,sans-serif;margin:2em;max-width:1100px}"
                    "img{width:100%}</style><h1>Decictor: non-optimal decisions</h1>"
                    f"<p>Seed run: {html.escape(str(strategy.seed_log))}</p>" + "".join(sections))
    say(f"decictor: seed vs mutated paths in {page}")


def _section(strategy: DecictorStrategy, bucket: str, row: CaseRow, log: Path, *, scene: Scene) -> str:
    """A bucket's part of decictor.html: its oracle's reason and figures, the paths plotted, its test case."""
    record_path = log.parent / "decictor.json"
    record = json.loads(record_path.read_text()) if record_path.is_file() else {}
    png = plot_paths(strategy, log, scene.participants,
                     f"{bucket} ({row.case_id}): {record.get('reason', '')}")
    return (f"<h2>{html.escape(bucket)}: {html.escape(row.case_id)}</h2>"
            f"<p>{html.escape(record.get('reason', ''))}; path distance {record.get('path_distance', 0):.2f} m, "
            f"behaviour MMD {record.get('behaviour_mmd', 0):.3f}</p>"
            f"<img src='data:image/png;base64,{png}'><pre>{html.escape(row.testcase_xml or '')}</pre>")


def plot_paths(strategy: DecictorStrategy, mutated_log: Path, participants: Sequence[Participant], title: str) -> str:
    """Seed vs mutated ego path, lanes and participants, as a base64 PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    seed = observe_log(Path(strategy.seed_log), strategy.spec, strategy.config).observation  # type: ignore[arg-type]
    mutated = observe_log(mutated_log, strategy.spec, strategy.config).observation
    fig, ax = plt.subplots(figsize=(11, 3.2))
    for lane in strategy.lanes:
        xs = [p[0] for p in lane.centre]
        ys = [p[1] for p in lane.centre]
        ax.plot(xs, [y - lane.width / 2 for y in ys], color="#bbb", lw=0.8)
        ax.plot(xs, [y + lane.width / 2 for y in ys], color="#bbb", lw=0.8)
    ax.plot([s.x for s in seed.ego.states], [s.y for s in seed.ego.states], color="#070", lw=2, label="seed (optimal)")
    ax.plot([s.x for s in mutated.ego.states], [s.y for s in mutated.ego.states], color="#a00", lw=2, ls="--",
            label="mutated")
    for p in participants:
        points = p.waypoints()
        ax.plot([w.x for w in points], [w.y for w in points], marker="s", ms=4, color="#e80", lw=1)
        ax.annotate(f"{p.kind} {p.id}", (p.x, p.y), fontsize=7)
    xs = [s.x for s in seed.ego.states + mutated.ego.states]
    ax.set_xlim(min(xs) - 10, max(xs) + 10)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=8, loc="upper left")
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    return base64.b64encode(buffer.getvalue()).decode()
