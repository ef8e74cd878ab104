"""rmw_zenoh's liveliness tokens, parsed: which entity a key announces and the data key it uses.

Every rmw_zenoh entity holds a liveliness token while it exists (rmw_zenoh's
docs/design.md, "Graph Cache"; zenoh-ros2-sdk writes the same)::

    @ros2_lv/<domain>/<zid>/<node id>/<entity id>/<kind>/<enclave>/<namespace>/<node name>
            [/<topic>/<dds type>/<type hash>/<qos>]          (for MP, MS, SS, SC)

``kind`` is NN (node), MP (publisher), MS (subscription), SS (service
server) or SC (service client). Names are mangled: every ``/`` becomes
``%`` and an empty namespace is ``%``.

One parser for both readers of the graph: ``spec discover`` (ros2/graph.py)
and the star, which wires tokens by their data key (bus/star_requests.py).
Pure: strings in, typed records out (no Zenoh).
"""

from __future__ import annotations

from dataclasses import dataclass

ADMIN_SPACE = "@ros2_lv"
NODE, PUBLISHER, SUBSCRIPTION, SERVICE, CLIENT = "NN", "MP", "MS", "SS", "SC"
ENDPOINT_KINDS = (PUBLISHER, SUBSCRIPTION, SERVICE, CLIENT)


@dataclass(frozen=True, kw_only=True)
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
    def data_key(self) -> str | None:
        """``<domain>/<topic>/<dds type>/<type hash>``, the key rmw_zenoh puts or queries on; None for a node."""
        if self.topic is None:
            return None
        return f"{self.domain_id}/{self.topic.strip('/')}/{self.dds_type}/{self.type_hash}"

    @property
    def node_path(self) -> str:
        return (self.namespace.rstrip("/") + "/" + self.node) if self.namespace != "/" else "/" + self.node


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
        return Entity(domain_id=int(domain), zid=zid, kind=kind, namespace=namespace, node=demangle(node).strip("/"))
    if kind not in ENDPOINT_KINDS or len(parts) < 13:
        return None
    topic = demangle(parts[9])
    if not topic.strip("/"):
        return None  # an endpoint names its topic or service; without one it is not rmw_zenoh's
    if not topic.startswith("/"):
        topic = "/" + topic
    return Entity(domain_id=int(domain), zid=zid, kind=kind, namespace=namespace, node=demangle(node).strip("/"),
                  topic=topic, dds_type=parts[10], type_hash=parts[11], qos="/".join(parts[12:]))
