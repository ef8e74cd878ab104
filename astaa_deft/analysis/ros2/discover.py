"""`spec discover`'s workflow: listen to a running ROS 2 system's liveliness tokens, write a spec skeleton.

Opens a Zenoh client session on the given endpoint (multicast scouting off),
subscribes to ``@ros2_lv/**`` with history (tokens already there are
reported at once) for a few seconds, keeps the tokens still alive at the
end, and turns them into a spec (``skeleton.spec_skeleton``). The spec is
loaded back before it is written: what this writes, ``spec check`` accepts.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import zenoh

from astaa_deft.engine.bus import zenoh_config as zc
from astaa_deft.model.errors import InputError, Problem
from astaa_deft.io.output_place import Place, ready_file, write_atomic, writing
from astaa_deft.engine.spec.loader import load_spec_text
from astaa_deft.io.ros2.types import shared_types
from astaa_deft.analysis.ros2.graph import ADMIN_SPACE, Graph, build_graph, parse_token
from astaa_deft.analysis.ros2.skeleton import spec_skeleton


@dataclass(frozen=True, kw_only=True)
class DiscoverOptions:
    connect: list[str]
    seconds: float = 3.0
    name: str = "discovered"
    domain_id: int | None = None
    include_infrastructure: bool = False


@dataclass(kw_only=True)
class DiscoverReport:
    out: Path
    graph: Graph
    modules: list[str]
    channels: list[str]
    notes: list[str] = field(default_factory=list)


def read_tokens(connect: list[str], seconds: float) -> list[str]:
    """The ``@ros2_lv`` liveliness keys alive on that bus after ``seconds`` of listening."""
    alive: dict[str, None] = {}
    lock = threading.Lock()

    def on_token(sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        with lock:
            if sample.kind == zenoh.SampleKind.DELETE:
                alive.pop(key, None)
            else:
                alive[key] = None

    try:
        session = zc.open_session(zc.config_dict(mode="client", connect=connect))
    except zenoh.ZError as exc:
        raise InputError(Problem("--connect", None, None, f"cannot connect to {', '.join(connect)}: {exc}",
                                 "give the endpoint of the running system's router, e.g. tcp/127.0.0.1:7447")) \
            from None
    try:
        subscriber = session.liveliness().declare_subscriber(f"{ADMIN_SPACE}/**", on_token, history=True)
        time.sleep(seconds)
        subscriber.undeclare()
    finally:
        session.close()
    with lock:
        return list(alive)


def discover_spec(out: Path, options: DiscoverOptions) -> DiscoverReport:
    """Write a spec skeleton of the running system to ``out``; InputError when no ROS 2 node answers.

    OutputError, before listening, when ``out`` cannot be written (a folder,
    a missing or read-only folder, no room), or when the write fails.
    """
    place = Place(out, "-o")
    ready_file(place)
    keys = read_tokens(options.connect, options.seconds)
    entities = [e for e in map(parse_token, keys) if e is not None]
    graph = build_graph(entities, options.domain_id)
    if not graph.nodes:
        where = ", ".join(options.connect)
        domain = f" in domain {options.domain_id}" if options.domain_id is not None else ""
        raise InputError(Problem(
            "--connect", None, None,
            f"no ROS 2 nodes{domain} seen on {where} in {options.seconds:g} s (no {ADMIN_SPACE} liveliness tokens)",
            "start the system first, connect to its Zenoh router (rmw_zenohd), or listen longer with --seconds"))
    skeleton = spec_skeleton(graph, shared_types(), name=options.name, connect=options.connect,
                             include_infrastructure=options.include_infrastructure)
    load_spec_text(skeleton.text, name=str(out), base_dir=out.parent)  # a bug if this raises
    with writing(place):
        write_atomic(out, skeleton.text)
    return DiscoverReport(out=out, graph=graph, modules=skeleton.modules, channels=skeleton.channels,
                          notes=skeleton.notes)
