"""The ROS 2 graph as rmw_zenoh announces it: liveliness tokens parsed into nodes and endpoints.

Every rmw_zenoh entity holds a liveliness token while it exists (rmw_zenoh's
docs/design.md, "Graph Cache"; zenoh-ros2-sdk writes the same)::

    @ros2_lv/<domain>/<zid>/<node id>/<entity id>/<kind>/<enclave>/<namespace>/<node name>
            [/<topic>/<dds type>/<type hash>/<qos>]          (for MP, MS, SS, SC)

``kind`` is NN (node), MP (publisher), MS (subscription), SS (service
server) or SC (service client). Names are mangled: every ``/`` becomes
``%`` and an empty namespace is ``%``.

Pure: strings in, typed records out (no Zenoh).
"""

from __future__ import annotations

from dataclasses import dataclass, field

ADMIN_SPACE = "@ros2_lv"
NODE, PUBLISHER, SUBSCRIPTION, SERVICE, CLIENT = "NN", "MP", "MS", "SS", "SC"
ENDPOINT_KINDS = (PUBLISHER, SUBSCRIPTION, SERVICE, CLIENT)


@dataclass(frozen=True)
class Entity:
    """One liveliness token, parsed."""

    domain_id: int
    zid: str
    kind: str
    namespace: str  # "/" or "/robot1"
    node: str
    topic: str | None = None  # "/cmd_vel" (endpoints only)
    dds_type: str | None = None
    type_hash: str | None = None
    qos: str | None = None

    @property
    def node_path(self) -> str:
        return (self.namespace.rstrip("/") + "/" + self.node) if self.namespace != "/" else "/" + self.node


@dataclass
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


def demangle(text: str) -> str:
    return "/" if text in ("", "%") else text.replace("%", "/")


def parse_token(key: str) -> Entity | None:
    """The entity a liveliness key announces; None for anything else (another tool's tokens)."""
    parts = key.split("/")
    if len(parts) < 9 or parts[0] != ADMIN_SPACE or not parts[1].isdigit():
        return None
    domain, zid, _node_id, _entity_id, kind, _enclave, namespace, node = parts[1:9]
    namespace = demangle(namespace)
    if not namespace.startswith("/"):
        namespace = "/" + namespace
    if kind == NODE:
        return Entity(int(domain), zid, kind, namespace, demangle(node).strip("/"))
    if kind not in ENDPOINT_KINDS or len(parts) < 13:
        return None
    topic = demangle(parts[9])
    if not topic.startswith("/"):
        topic = "/" + topic
    return Entity(int(domain), zid, kind, namespace, demangle(node).strip("/"), topic, parts[10], parts[11],
                  "/".join(parts[12:]))


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
                                      Topic(entity.topic, entity.dds_type, entity.type_hash))
            side = topic.publishers if entity.kind == PUBLISHER else topic.subscribers
            if entity.node_path not in side:
                side.append(entity.node_path)
        elif entity.kind in (SERVICE, CLIENT) and entity.topic and entity.topic not in services:
            services.append(entity.topic)
    return Graph(domain_id, nodes, list(topics.values()), services)
