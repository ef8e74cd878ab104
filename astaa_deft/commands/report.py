"""`astaa-deft report CAMPAIGN`: regenerate the campaign's report.html from its journal."""

from __future__ import annotations

from pathlib import Path

from ..campaign.journal import open_existing
from ..campaign.report import write_report
from .console import say


def run(out: Path) -> int:
    open_existing(out).close()
    say(f"report: {write_report(out)}")
    return 0
