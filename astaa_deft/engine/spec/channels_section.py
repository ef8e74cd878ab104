"""The spec's ``channels:`` section: each channel's Zenoh key (or ROS 2 topic), producer, consumers, type, encoding.

A channel's key is unique, its producer and consumers are declared modules,
its type is declared under ``types`` (or, for ``encoding: cdr``, is a ROS 2
message type resolved through the ``ros2:`` section). Problems are reported on
the reader's source; a channel is kept with stand-in values so that later
sections referring to it are checked too.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from astaa_deft.engine.spec.reader import SpecReader
from astaa_deft.engine.spec.ros2_section import resolve_cdr_channel
from astaa_deft.io.codecs import encoding_names
from astaa_deft.io.yamlsource import Node
from astaa_deft.model.errors import did_you_mean
from astaa_deft.model.fields import FieldPath, FieldPathError, type_at
from astaa_deft.model.sut import Channel, MessageType, Module, Ros2Section

KEY_RE = re.compile(r"^[^*$?#\s\x00-\x1f\x7f]+\Z")  # a concrete Zenoh key: no wildcards, no DSL, no control
MAX_KEY_CHARS = 1000  # a Zenoh key the spec declares: far above real ones (a namespace and a topic)
KEY_FIX = "use '/'-separated chunks without wildcards (*, **), '$', '?', '#', spaces or control characters"


def concrete_key_problem(key: str) -> str | None:
    """Why ``key`` is not a concrete Zenoh key a spec may declare (None: it is one)."""
    if not key:
        return "is empty"
    if len(key) > MAX_KEY_CHARS:
        return f"is {len(key):,} characters long (at most {MAX_KEY_CHARS:,})"
    if not KEY_RE.match(key) or key.startswith("/") or key.endswith("/") or "//" in key:
        return f"{key[:80]!r} is not a concrete Zenoh key"
    return None
CHANNEL_KEYS = ("name", "key", "topic", "producer", "consumers", "type", "encoding", "time", "pair_by")
NUMBER_KINDS = ("float32", "float64", "int8", "int16", "int32", "int64", "uint8", "uint16", "uint32", "uint64",
                "time")


def read_channels_section(reader: SpecReader, node: Node | None, modules: tuple[Module, ...],
                          types: dict[str, MessageType], *, ros2: Ros2Section) -> list[Channel]:
    """The ``channels:`` section (required, non-empty). ``types`` gains the ROS 2 types of CDR channels."""
    channels = _ChannelsReader(reader=reader, module_names=[m.name for m in modules], types=types, ros2=ros2)
    out: list[Channel] = []
    for item in reader.list_of_maps(node, "channels", required=True):
        if reader.keys(item, CHANNEL_KEYS, ("name", "producer", "type"), "a channel"):
            out.append(channels.channel(item))
    return out


@dataclass(kw_only=True)
class _ChannelsReader:
    """One pass over the channel list: the names and keys seen so far, to report duplicates."""

    reader: SpecReader
    module_names: list[str]
    types: dict[str, MessageType]
    ros2: Ros2Section
    names: set[str] = field(default_factory=set)
    keys: dict[str, str] = field(default_factory=dict)  # key → the channel that uses it

    def channel(self, item: Node) -> Channel:
        src, v = self.reader.src, item.value
        is_cdr = "encoding" in v and v["encoding"].value == "cdr"
        # A CDR channel's type is a ROS 2 message type (its fields join `types`);
        # its key may come from its ROS 2 topic.
        cdr = resolve_cdr_channel(src, v, self.ros2, self.types) if is_cdr else None
        if not is_cdr and "topic" in v:
            src.at_key(item, "topic", "'topic' needs 'encoding: cdr' (a ROS 2 channel)",
                       "add 'encoding: cdr', or give a Zenoh 'key' instead")
        if "key" not in v and "topic" not in v:
            src.at(item, "a channel lacks 'key'", "add 'key: …' (or, for ROS 2, 'topic:' and 'encoding: cdr')")
        name = self.reader.name_of(v["name"], "channel name") if "name" in v else "?"
        if "name" in v and name in self.names:
            src.at(v["name"], f"channel '{name}' is declared twice", "give each channel a unique name")
        self.names.add(name)
        key = self._key(v, name, cdr[1] if cdr else "")
        producer, consumers = self._modules(v, name)
        type_name = self._type(v, cdr_resolved=cdr is not None)
        encoding = self._encoding(v)
        if encoding == "cdr":
            encoding = cdr[0] if cdr else "cdr"
        topic = v["topic"].value if "topic" in v and isinstance(v["topic"].value, str) else None
        own_time = self._field(v, "time", type_name, NUMBER_KINDS, want="a number of seconds (or a 'time' field)")
        pair_by = self._field(v, "pair_by", type_name, (*NUMBER_KINDS, "string", "enum", "bool"),
                              want="a number or a string (a tick's sequence number, its time)")
        return Channel(name=name, key=key, producer=producer, consumers=tuple(consumers), type=type_name,
                       encoding=encoding, topic=topic, time=own_time, pair_by=pair_by)

    def _field(self, v: dict[str, Node], key: str, type_name: str, kinds: tuple[str, ...], *, want: str) -> str | None:
        """``time:`` or ``pair_by:``: a field path of the channel's type holding one value of ``kinds``."""
        if key not in v or not self.reader.expect(v[key], (str,), f"'{key}'", "a field path, e.g. header.seq"):
            return None
        text: str = v[key].value
        if type_name not in self.types:
            return text  # the unknown type is reported already
        try:
            declared = type_at(self.types, type_name, FieldPath.parse(text))
        except FieldPathError as exc:
            self.reader.src.at(v[key], f"'{key}': {exc.reason}", f"name a field of {type_name}, e.g. header.seq")
            return None
        if declared.kind not in kinds:
            self.reader.src.at(v[key], f"'{key}' field '{text}' is {declared.describe()}; it must be {want}",
                               "pick a field of that type")
            return None
        return text

    def _key(self, v: dict[str, Node], name: str, topic_key: str) -> str:
        """The channel's Zenoh key: ``key:`` if given, else the one its ROS 2 topic maps to."""
        src = self.reader.src
        key = topic_key
        if key and key in self.keys:
            src.at(v["topic"], f"topic '{v['topic'].value}' is already used by channel '{self.keys[key]}'",
                   "give each channel its own topic")
        elif key:
            self.keys[key] = name
        if "key" in v and self.reader.expect(v["key"], (str,), "'key'", "a Zenoh key"):
            key = v["key"].value
            problem = concrete_key_problem(key)
            if not key:
                src.at(v["key"], f"channel '{name}' has an empty key", "give a Zenoh key, e.g. 'demo/data'")
            elif problem is not None:
                src.at(v["key"], f"key {problem}", KEY_FIX)
            elif key in self.keys:
                src.at(v["key"], f"key '{key}' is already used by channel '{self.keys[key]}'",
                       "give each channel its own key")
            else:
                self.keys[key] = name
        return key

    def _modules(self, v: dict[str, Node], name: str) -> tuple[str, list[str]]:
        """(the producer, the consumers): declared modules, none consuming its own channel."""
        reader = self.reader
        producer = ""
        if "producer" in v and reader.expect(v["producer"], (str,), "'producer'", "a module name"):
            producer = v["producer"].value
            reader.module_ref(v["producer"], producer, self.module_names)
        consumers: list[str] = []
        if "consumers" not in v:
            return producer, consumers
        cnode = v["consumers"]
        if not cnode.is_list:
            reader.src.at(cnode, "'consumers' must be a list of module names", "e.g. [planning, control]")
            return producer, consumers
        for c in cnode.value:
            if reader.expect(c, (str,), "a consumer", "a module name"):
                reader.module_ref(c, c.value, self.module_names)
                if c.value == producer:
                    reader.src.at(c, f"module '{producer}' consumes its own channel '{name}'",
                                  "remove it from consumers (a module hears its own messages anyway)")
                consumers.append(c.value)
        return producer, consumers

    def _type(self, v: dict[str, Node], *, cdr_resolved: bool) -> str:
        """The message type's name: declared under ``types`` (a CDR type is checked by resolve_cdr_channel)."""
        if "type" not in v or not self.reader.expect(v["type"], (str,), "'type'", "a type name"):
            return ""
        type_name: str = v["type"].value
        if not cdr_resolved and "encoding" in v and v["encoding"].value == "cdr":
            pass  # reported by resolve_cdr_channel
        elif type_name not in self.types:
            hint = did_you_mean(type_name, self.types) or "declare it under 'types'"
            self.reader.src.at(v["type"], f"unknown message type '{type_name}'", hint)
        return type_name

    def _encoding(self, v: dict[str, Node]) -> str:
        """``encoding:`` as written (default json); an unknown one is reported."""
        if "encoding" not in v or not self.reader.expect(v["encoding"], (str,), "'encoding'", "an encoding name"):
            return "json"
        encoding: str = v["encoding"].value
        encodings = encoding_names()  # the registered codecs and codec families (io/codecs)
        if encoding not in encodings:
            hint = did_you_mean(encoding, encodings) or f"supported: {', '.join(encodings)}"
            self.reader.src.at(v["encoding"], f"unknown encoding '{encoding}'", hint)
        return encoding
