"""The demo's campaign step: a short `fuzz` of the demo stack that finds seeded defects on its own."""

from __future__ import annotations

from pathlib import Path
from collections.abc import Callable

from astaa_deft.orchestration.campaign.campaign import Campaign, CampaignConfig
from astaa_deft.orchestration.journal.journal import Journal
from astaa_deft.orchestration.campaign.report import write_report
from astaa_deft.orchestration.campaign.standing import headline, standings
from astaa_deft.model.sut import Spec

# A seed whose first five generated cases reorder localization (seeded defect 4), empty trajectory.points
# (defect 3) and set routing.speed_limit non-finite (defect 1): a short campaign that shows finds without
# minutes of search. Any seed finds the four robustness defects given a round or two of cases
# (benchmarks/bench_campaign.py).
DEMO_SEED = 1153
DEMO_CASES = 5
DEMO_HORIZON = 6.0


def campaign_step(spec_path: Path, out_dir: Path, say: Callable[[str], None] = print,
                  cases: int = DEMO_CASES, *, seed: int = DEMO_SEED, spec: Spec | None = None) -> int:
    """Run the short campaign into ``out_dir``; the number of buckets it found (its report is written).

    Prints the headline — confirmed bugs by severity, apart from buckets where the fault alone breaks the
    invariant (no module under test involved) and the unconfirmed and flaky ones — and each bucket's line.
    ``spec``: ``spec_path``'s spec as the calling command loaded it (None: the campaign loads it)."""
    config = CampaignConfig(spec_path=spec_path, out=out_dir, cases=cases, seed=seed, horizon=DEMO_HORIZON,
                            baseline_runs=1, reruns=1, minimise=False)
    journal = Journal(out_dir)
    try:
        result = Campaign(config, journal, say=say, spec=spec).run()
        ranked = standings(journal)
    finally:
        journal.close()
    report = write_report(out_dir)
    say(f"{result.cases_done} runs in {result.seconds:.0f} s: {result.buckets} bucket(s): {headline(ranked)}")
    for standing in ranked:
        say(f"  {standing.describe()}")
    say(f"report: {report}")
    say(f"state: astaa-deft fuzz --status -o {out_dir}")
    return result.buckets
