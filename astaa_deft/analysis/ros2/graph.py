"""The ROS 2 graph as rmw_zenoh announces it: nodes and endpoints from parsed liveliness tokens.

The tokens' format and parser live in ``spec/ros2_tokens.py`` (the star
reads them too). Pure: typed records in, a graph out (no Zenoh).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from astaa_deft.io.ros2.tokens import ADMIN_SPACE, CLIENT, PUBLISHER, SERVICE, SUBSCRIPTION, Entity, parse_token

__all__ = ["ADMIN_SPACE", "Entity", "Graph", "Topic", "build_graph", "parse_token"]


@dataclass(kw_only=True)
class Topic:
    name: str
    dds_type: str
    type_hash: str
    publishers: list[str] = field(default_factory=list)  # node paths, first seen first
    subscribers: list[str] = field(default_factory=list)


@dataclass
class Graph:
    domain_id: int | None
    nodes: list[str]  # node paths ("/teleop"), first seen first
    topics: list[Topic]
    services: list[str]


def build_graph(entities: list[Entity], domain_id: int | None = None) -> Graph:
    """Nodes and topics (with who publishes and who subscribes) of one domain.

    ``domain_id`` None: the domain of the first entity seen.
    """
    if domain_id is None and entities:
        domain_id = entities[0].domain_id
    nodes: list[str] = []
    topics: dict[tuple[str, str], Topic] = {}
    services: list[str] = []
    for entity in entities:
        if entity.domain_id != domain_id:
            continue
        if entity.node_path not in nodes:
            nodes.append(entity.node_path)
        if entity.kind in (PUBLISHER, SUBSCRIPTION):
            assert entity.topic is not None and entity.dds_type is not None and entity.type_hash is not None
            topic = topics.setdefault((entity.topic, entity.dds_type),
                                      Topic(name=entity.topic, dds_type=entity.dds_type, type_hash=entity.type_hash))
            side = topic.publishers if entity.kind == PUBLISHER else topic.subscribers
            if entity.node_path not in side:
                side.append(entity.node_path)
        elif entity.kind in (SERVICE, CLIENT) and entity.topic and entity.topic not in services:
            services.append(entity.topic)
    return Graph(domain_id, nodes, list(topics.values()), services)
