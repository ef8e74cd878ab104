"""A spec skeleton (YAML text) from a discovered ROS 2 graph.

Modules are the ROS 2 nodes, channels the topics (one producer each: the
first publisher; others are named in a comment), with their types and
consumers; headers' stamps are brittle; each module that publishes is ready
once its first channel carries a message. Commands are placeholders that say
what to edit, and ``zenoh.connect`` names the endpoint discovery used, so
``astaa-deft proxy --spec … --no-launch --passive`` records the running
system straight away.

Pure: a Graph and a typestore in, text and notes out.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from typing import Any

from astaa_deft.io.ros2.types import Ros2Types, ros_type_name
from astaa_deft.analysis.ros2.graph import Graph

# Every rmw node publishes these; they are rarely what a test is about.
INFRASTRUCTURE_TOPICS = ("/rosout", "/parameter_events")
HEADER = "std_msgs/msg/Header"


@dataclass
class Skeleton:
    text: str
    modules: list[str]
    channels: list[str]
    notes: list[str] = field(default_factory=list)  # what was left out or needs a look, one line each


def spec_skeleton(graph: Graph, types: Ros2Types, *, name: str, connect: list[str],
                  include_infrastructure: bool = False) -> Skeleton:
    notes: list[str] = []
    module_of: dict[str, str] = {}
    for node_path in graph.nodes:
        module_of[node_path] = _unique(_module_name(node_path), set(module_of.values()))
    channels: list[dict] = []
    produced: dict[str, str] = {}  # module -> its first channel
    brittle = False
    for topic in graph.topics:
        if topic.name in INFRASTRUCTURE_TOPICS and not include_infrastructure:
            continue
        type_name = ros_type_name(topic.dds_type)
        if type_name is None or not types.has(type_name):
            notes.append(f"topic {topic.name}: type {topic.dds_type} is not a known message type — "
                         "add its .msg file under ros2.messages and a channel for it")
            continue
        if not topic.publishers:
            notes.append(f"topic {topic.name}: subscribed to ({', '.join(topic.subscribers)}) but nobody "
                         "publishes it — no channel")
            continue
        producer = module_of[topic.publishers[0]]
        channel: dict[str, Any] = {
            "name": _unique(_channel_name(topic.name), {c["name"] for c in channels}),
            "topic": topic.name, "type": type_name, "encoding": "cdr", "producer": producer,
            "consumers": [module_of[n] for n in topic.subscribers if module_of[n] != producer],
        }
        expected_hash = types.rihs01(type_name)
        if topic.type_hash != expected_hash:
            # The node's definition differs from ours: the derived key would miss its messages.
            channel["key"] = f"{graph.domain_id}/{topic.name.strip('/')}/{topic.dds_type}/{topic.type_hash}"
            channel["#"] = (f"type hash {topic.type_hash} differs from the Jazzy definition's "
                            f"{expected_hash}: give the node's own .msg under ros2.messages")
            notes.append(f"topic {topic.name}: type hash mismatch for {type_name} (the node publishes "
                         f"{topic.type_hash}, the known definition hashes to {expected_hash})")
        if len(topic.publishers) > 1:
            channel.setdefault("#", f"also published by {', '.join(topic.publishers[1:])}")
        channels.append(channel)
        produced.setdefault(producer, channel["name"])
        brittle = brittle or HEADER in types.spec_types(type_name)
    for service in graph.services:
        notes.append(f"service {service}: services are not channels — left out")

    lines = [
        f"# Discovered from a running ROS 2 system ({', '.join(connect)}): {len(module_of)} nodes, "
        f"{len(channels)} topics.",
        "# Edit each module's command (how to start that node), then add invariants.",
        f"name: {name}",
        "zenoh:",
        f"  connect: {json.dumps(connect)}   # the running system (proxy --no-launch --passive)",
    ]
    if graph.domain_id:
        lines += ["ros2:", f"  domain_id: {graph.domain_id}"]
    lines.append("modules:")
    for node_path, module in module_of.items():
        ready = f"{{channel: {produced[module]}}}" if module in produced else "{delay: 1.0}"
        lines += [
            f"  - name: {module}   # ROS 2 node {node_path}",
            f"    command: [\"{{python}}\", \"-c\", \"raise SystemExit('edit the command of {module}')\"]",
            f"    ready: {ready}",
        ]
    lines.append("channels:" if channels else "channels: []")
    for channel in channels:
        comment = channel.pop("#", None)
        fields = ", ".join(f"{k}: {_yaml_scalar(v)}" for k, v in channel.items())
        lines.append(f"  - {{{fields}}}" + (f"   # {comment}" if comment else ""))
    if brittle:
        lines.append(f"brittle: [{HEADER}.stamp]")
    return Skeleton("\n".join(lines) + "\n", list(module_of.values()), [c["name"] for c in channels], notes)


def _module_name(node_path: str) -> str:
    return re.sub(r"[^A-Za-z0-9_-]", "_", node_path.strip("/")) or "node"


def _channel_name(topic: str) -> str:
    return re.sub(r"[^A-Za-z0-9_-]", "_", topic.strip("/")) or "topic"


def _unique(name: str, taken: set[str]) -> str:
    candidate, n = name, 2
    while candidate in taken:
        candidate, n = f"{name}_{n}", n + 1
    return candidate


def _yaml_scalar(value: object) -> str:
    if isinstance(value, list):
        return "[" + ", ".join(map(str, value)) + "]"
    return json.dumps(value) if isinstance(value, str) and (":" in value or value.startswith("/")) else str(value)
