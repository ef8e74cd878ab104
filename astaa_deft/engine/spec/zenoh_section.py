"""The spec's ``zenoh:`` section: the proxy's listen endpoints, routers to connect to, a config file."""

from __future__ import annotations

import re

from astaa_deft.engine.spec.reader import SpecReader
from astaa_deft.io.yamlsource import Node
from astaa_deft.model.sut import ZenohSection

LOCATOR_RE = re.compile(r"^(tcp|udp|tls|quic|ws|unixsock-stream)/(.+)\Z")


def read_zenoh_section(reader: SpecReader, node: Node | None) -> ZenohSection:
    """The ``zenoh:`` section (the defaults when absent or not a mapping); problems reported on the source."""
    if node is None:
        return ZenohSection()
    if not reader.keys(node, ("endpoints", "connect", "config"), (), "'zenoh'"):
        return ZenohSection()
    endpoints = ZenohSection().endpoints
    if "endpoints" in node.value:
        ep_node = node.value["endpoints"]
        if not ep_node.is_list or not ep_node.value:
            reader.src.at(ep_node, "'zenoh.endpoints' must be a non-empty list", 'e.g. ["tcp/127.0.0.1:0"]')
        else:
            endpoints = tuple(_endpoint(reader, item) for item in ep_node.value)
    connect: tuple[str, ...] = ()
    if "connect" in node.value:
        cn = node.value["connect"]
        if not cn.is_list:
            reader.src.at(cn, "'zenoh.connect' must be a list", 'e.g. ["tcp/127.0.0.1:7447"]')
        else:
            connect = tuple(_endpoint(reader, item) for item in cn.value)
    config = None
    if "config" in node.value:
        cnode = node.value["config"]
        if reader.expect(cnode, (str,), "'zenoh.config'", "a path to a JSON5 file"):
            config = (reader.base_dir / cnode.value)
            if reader.from_file and not config.is_file():
                reader.src.at(cnode, f"Zenoh config file '{config}' does not exist",
                              "give a path relative to the spec file")
    return ZenohSection(endpoints=endpoints, connect=connect, config_file=config)


def _endpoint(reader: SpecReader, node: Node) -> str:
    if not reader.expect(node, (str,), "an endpoint", 'a string like "tcp/127.0.0.1:0"'):
        return ""
    if not LOCATOR_RE.match(node.value):
        reader.src.at(node, f"endpoint '{node.value}' is not a Zenoh locator",
                      'write it as "tcp/HOST:PORT" (port 0 picks a free port)')
    text: str = node.value
    return text
