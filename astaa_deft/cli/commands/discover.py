"""`astaa-deft spec discover --connect ENDPOINT [--seconds S] -o spec.yaml`."""

from __future__ import annotations

from pathlib import Path

from astaa_deft.analysis.ros2.discover import DiscoverOptions, discover_spec


def run(out: Path, connect: list[str], seconds: float, name: str, domain_id: int | None,
        include_infrastructure: bool) -> int:
    report = discover_spec(out, DiscoverOptions(connect, seconds, name, domain_id, include_infrastructure))
    print(f"{out}: {len(report.modules)} modules ({', '.join(report.modules)}), "
          f"{len(report.channels)} channels ({', '.join(report.channels) or 'none'}) from ROS 2 domain "
          f"{report.graph.domain_id}")
    for note in report.notes:
        print(f"  note: {note}")
    print(f"next: edit the commands in {out}, then `astaa-deft spec check {out}`")
    return 0
