"""`astaa-deft spec discover --connect ENDPOINT [--seconds S] -o spec.yaml`: a spec skeleton from a running system.

The work is :func:`astaa_deft.analysis.ros2.discover.discover_spec`; this prints its report. Exit 0 when
the skeleton was written.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from astaa_deft.cli.arguments import DOMAIN_ID, LISTEN_SECONDS, bounded

if TYPE_CHECKING:
    from astaa_deft.analysis.ros2.discover import DiscoverOptions
    from astaa_deft.cli.arguments import SubParsers


def add_parser(subparsers: SubParsers) -> None:
    """Declare `spec discover` under the `spec` command's actions."""
    disc = subparsers.add_parser("discover", help="write a spec skeleton from a running ROS 2 system (rmw_zenoh)",
                                 epilog="example:\n  astaa-deft spec discover --connect tcp/127.0.0.1:7447 -o sut.yaml")
    disc.add_argument("--connect", action="append", required=True, metavar="ENDPOINT",
                      help="the running system's Zenoh router, e.g. tcp/127.0.0.1:7447")
    bounded(disc, "--seconds", LISTEN_SECONDS, default=3.0, help="how long to listen (default 3)")
    disc.add_argument("-o", "--out", type=Path, required=True, help="the spec file to write")
    disc.add_argument("--name", default="discovered", help="the spec's name")
    bounded(disc, "--domain", DOMAIN_ID, help="ROS_DOMAIN_ID to keep (default: the first one seen)")
    disc.add_argument("--all-topics", action="store_true", help="keep /rosout and /parameter_events too "
                                                                "(default: left out)")
    disc.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """The parsed `spec discover` arguments as DiscoverOptions, to :func:`discover`."""
    from astaa_deft.analysis.ros2.discover import DiscoverOptions

    return discover(args.out, DiscoverOptions(connect=args.connect, seconds=args.seconds, name=args.name,
                                              domain_id=args.domain, include_infrastructure=args.all_topics))


def discover(out: Path, options: DiscoverOptions) -> int:
    """Listen to the running system, write the spec skeleton to ``out`` and print what it holds: 0.

    Raises InputError when nothing can be discovered (no router, no ROS 2 node) and OutputError when
    ``out`` cannot be written.
    """
    from astaa_deft.analysis.ros2.discover import discover_spec

    report = discover_spec(out, options)
    print(f"{out}: {len(report.modules)} modules ({', '.join(report.modules)}), "
          f"{len(report.channels)} channels ({', '.join(report.channels) or 'none'}) from ROS 2 domain "
          f"{report.graph.domain_id}")
    for note in report.notes:
        print(f"  note: {note}")
    print(f"next: edit the commands in {out}, then `astaa-deft spec check {out}`")
    return 0
