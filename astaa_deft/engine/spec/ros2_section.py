"""The spec's ROS 2 parts: the ``ros2:`` section and ``encoding: cdr`` channels.

```yaml
ros2:
  domain_id: 0                                  # ROS_DOMAIN_ID of the system (default 0)
  messages:                                     # custom message definitions, type: file
    my_robot/msg/WheelSpeeds: msg/WheelSpeeds.msg
channels:
  - {name: cmd_vel, topic: /cmd_vel, type: geometry_msgs/msg/Twist, encoding: cdr,
     producer: teleop, consumers: [base]}
```

A CDR channel's ``type`` is a ROS 2 message type; its fields (and those of
every type inside it) join the spec's ``types`` under their ROS names, so
field paths, brittle patterns (``std_msgs/msg/Header.stamp``), invariants and
test case generation work as for any channel. ``topic`` derives the key
rmw_zenoh publishes on (``<domain>/<topic>/<dds type>/<RIHS01 hash>``);
an explicit ``key`` is taken as written.

Problems are reported through the loader's ``Source`` (file, line, fix).
"""

from __future__ import annotations

from pathlib import Path

from astaa_deft.model.errors import did_you_mean
from astaa_deft.io.yamlsource import Node, Source
from astaa_deft.model.sut import MessageType, Ros2Section
from astaa_deft.io.ros2.types import TOPIC_RE, Ros2TypeError, shared_types, topic_key

ROS2_KEYS = ("domain_id", "messages")


def read_ros2_section(src: Source, node: Node | None, base_dir: Path, from_file: bool) -> Ros2Section:
    """The ``ros2:`` section; custom message files are registered in the process's typestore."""
    if node is None:
        return Ros2Section()
    if not node.is_map:
        src.at(node, "'ros2' must be a mapping", "write 'ros2:' then 'domain_id: 0' and/or 'messages:'")
        return Ros2Section()
    for key in node.value:
        if key not in ROS2_KEYS:
            src.at_key(node, key, f"unknown key '{key}' in 'ros2'", did_you_mean(key, ROS2_KEYS)
                       or f"allowed keys: {', '.join(ROS2_KEYS)}")
    domain_id = 0
    if "domain_id" in node.value:
        dnode = node.value["domain_id"]
        if type(dnode.value) is not int or not 0 <= dnode.value <= 232:
            src.at(dnode, "'ros2.domain_id' must be a whole number from 0 to 232", "e.g. domain_id: 0")
        else:
            domain_id = dnode.value
    messages: dict[str, Path] = {}
    mnode = node.value.get("messages")
    if mnode is not None:
        if not mnode.is_map:
            src.at(mnode, "'ros2.messages' must map message types to .msg files",
                   "e.g. 'my_pkg/msg/Status: msg/Status.msg'")
        else:
            types = shared_types()
            for type_name, fnode in mnode.items():
                if not isinstance(fnode.value, str):
                    src.at(fnode, f"the file of '{type_name}' must be a path", "give a path relative to the spec")
                    continue
                path = base_dir / fnode.value
                if not path.exists():  # a directory or a special file is refused by its kind when read
                    if from_file:
                        src.at(fnode, f"message file '{path}' does not exist", "give a path relative to the spec file")
                    continue
                try:
                    types.register_msg_file(type_name, path)
                except Ros2TypeError as exc:
                    src.at(fnode, f"{path}: {exc}", "fix the definition (ROS 2 .msg syntax)")
                    continue
                messages[type_name] = path
    return Ros2Section(domain_id=domain_id, messages=messages)


def resolve_cdr_channel(src: Source, channel: dict[str, Node], ros2: Ros2Section,
                        types: dict[str, MessageType]) -> tuple[str, str] | None:
    """For a CDR channel: (codec name, derived key or ""), with its types added to ``types``; None on a problem."""
    tnode = channel.get("type")
    if tnode is None or not isinstance(tnode.value, str):
        return None
    store = shared_types()
    type_name = tnode.value
    try:
        store.check_name(type_name)
    except Ros2TypeError as exc:
        src.at(tnode, str(exc), "name a ROS 2 message type (package/msg/Name) or declare it under 'ros2.messages'")
        return None
    for name, mtype in store.spec_types(type_name).items():
        types.setdefault(name, mtype)
    key = ""
    topic_node = channel.get("topic")
    if topic_node is not None:
        topic = topic_node.value
        if not isinstance(topic, str) or not TOPIC_RE.match(topic) or "//" in topic or topic.strip("/") == "":
            src.at(topic_node, f"'{topic}' is not a ROS 2 topic name", "e.g. topic: /cmd_vel")
            return None
        key = topic_key(ros2.domain_id, topic, type_name, store.rihs01(type_name))
    return "cdr:" + type_name, key
