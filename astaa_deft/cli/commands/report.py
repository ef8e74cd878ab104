"""`astaa-deft report CAMPAIGN`: regenerate the campaign's report.html from its journal."""

from __future__ import annotations

from pathlib import Path

from astaa_deft.orchestration.journal.journal import open_existing
from astaa_deft.orchestration.campaign.report import write_report
from astaa_deft.cli.commands.console import say


def run(out: Path) -> int:
    open_existing(out).close()
    say(f"report: {write_report(out)}")
    return 0
