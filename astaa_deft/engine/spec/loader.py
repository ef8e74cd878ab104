"""Load a SUT spec (YAML) into validated ``Spec`` objects.

All problems found are reported together, each with file, line, column and a
fix; the caller gets either a fully cross-checked Spec or an InputError.
"""

from __future__ import annotations

import re
import shlex
import string
from pathlib import Path
from typing import Any

from astaa_deft.model.errors import did_you_mean
from astaa_deft.io.inputfile import SPEC
from astaa_deft.engine.spec.planner import build_planner
from astaa_deft.engine.spec.replay_section import build_replay_section
from astaa_deft.model.fields import FieldPathError, check_brittle_pattern
from astaa_deft.engine.monitor.invariants import build_invariants
from astaa_deft.io.yamlsource import Node, Source, describe_value
from astaa_deft.engine.spec.run_section import build_run_section
from astaa_deft.engine.spec.decictor_section import read_decictor_section
from astaa_deft.engine.spec.ros2_section import read_ros2_section, resolve_cdr_channel
from astaa_deft.model.sut import (
    SCALAR_KINDS,
    Channel,
    FieldType,
    MessageType,
    Module,
    Readiness,
    Ros2Section,
    Spec,
    ZenohSection,
)

NAME_RE = re.compile(r"^[A-Za-z0-9_-]+\Z")
TYPE_NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*\Z")
FIELD_NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*\Z")
KEY_RE = re.compile(r"^[^*$?#\s]+\Z")  # a concrete Zenoh key: no wildcards, no DSL
BUILTIN_PLACEHOLDERS = ("python", "zenoh_config", "module", "run_dir", "spec_dir")
ENCODINGS = ("json", "cbor", "cdr")

ON_CRASH = ("end_run", "keep_running")
TOP_KEYS = ("name", "params", "zenoh", "modules", "channels", "types", "brittle", "invariants", "planner", "run",
            "decictor", "ros2", "replay")
REQUIRED_TOP = ("name", "modules", "channels")


def load_spec(path: Path | str) -> Spec:
    path = Path(path)
    src = Source.from_file(path, SPEC)
    return _SpecBuilder(src, path).build()


def load_spec_text(text: str, name: str = "<spec>", base_dir: Path | None = None) -> Spec:
    fake_path = (base_dir or Path.cwd()) / name
    return _SpecBuilder(Source(text, name), fake_path, from_file=False).build()


class _SpecBuilder:
    def __init__(self, src: Source, path: Path, from_file: bool = True):
        self.src = src
        self.path = path
        self.from_file = from_file
        self.base_dir = path.parent
        # (channel name, node) of every readiness channel, checked once channels are known
        self._ready_channels: list[tuple[str | None, Node | None]] = []
        self.ros2 = Ros2Section()

    # -- entry -------------------------------------------------------------
    def build(self) -> Spec:
        root = self.src.parse()
        if not root.is_map:
            self.src.at(root, "the spec must be a mapping of sections", "start with 'name:', 'modules:', 'channels:'")
            self.src.raise_if_problems()
        self.keys(root, TOP_KEYS, REQUIRED_TOP, "the spec")
        v = root.value
        name = self.name_of(v["name"], "spec name") if "name" in v else "spec"
        params, param_choices = self.params(v.get("params"))
        zenoh = self.zenoh(v.get("zenoh"))
        types = self.types(v.get("types"))
        self.ros2 = read_ros2_section(self.src, v.get("ros2"), self.base_dir, self.from_file)
        modules = self.modules(v.get("modules"), params)
        channels = self.channels(v.get("channels"), modules, types)
        brittle = self.brittle(v.get("brittle"), types)
        invariants = build_invariants(self.src, v.get("invariants"), types, channels, [m.name for m in modules])
        planner = build_planner(self.src, v.get("planner"), types, channels, modules)
        replay = build_replay_section(self.src, v.get("replay"), channels, modules)
        run = build_run_section(self.src, v.get("run"), types, channels, [m.name for m in modules])
        decictor = read_decictor_section(self.src, v.get("decictor"), tuple(c.name for c in channels), self.base_dir)
        self.src.raise_if_problems()
        return Spec(
            name=name,
            path=self.path if self.from_file else None,
            zenoh=zenoh,
            modules=tuple(modules),
            channels=tuple(channels),
            types=types,
            brittle=tuple(brittle),
            params=params,
            param_choices=param_choices,
            invariants=tuple(invariants),
            planner=planner,
            replay=replay,
            run=run,
            decictor=decictor,
            source_text=self.src.text,
            ros2=self.ros2,
        )

    # -- generic checks ----------------------------------------------------
    def keys(self, node: Node, allowed: tuple[str, ...], required: tuple[str, ...], what: str) -> bool:
        """Report unknown and missing keys of a mapping; False if it is not a mapping."""
        if not node.is_map:
            self.src.at(node, f"{what} must be a mapping", f"write it as 'key: value' lines ({', '.join(allowed)})")
            return False
        for key in node.value:
            if key not in allowed:
                hint = did_you_mean(key, allowed) or f"allowed keys: {', '.join(allowed)}"
                self.src.at_key(node, key, f"unknown key '{key}' in {what}", hint)
        for key in required:
            if key not in node.value:
                self.src.at(node, f"{what} lacks '{key}'", f"add '{key}: …'")
        return True

    def expect(self, node: Node, kinds: tuple[type, ...], what: str, fix: str) -> bool:
        ok = isinstance(node.value, kinds) and not (bool not in kinds and isinstance(node.value, bool))
        if not ok:
            self.src.at(node, f"{what} must be {fix}, not {describe_value(node.value)}", f"write {what} as {fix}")
        return ok

    def name_of(self, node: Node, what: str) -> str:
        if not self.expect(node, (str,), what, "a string"):
            return "?"
        if not NAME_RE.match(node.value):
            self.src.at(node, f"{what} '{node.value}' has characters other than letters, digits, '_' and '-'",
                        "rename it (it becomes part of Zenoh keys and file names)")
        return node.value

    def list_of_maps(self, node: Node | None, what: str, required: bool) -> list[Node]:
        if node is None:
            return []
        if not node.is_list:
            self.src.at(node, f"'{what}' must be a list", f"write each entry as '- name: …' under '{what}:'")
            return []
        if required and not node.value:
            self.src.at(node, f"'{what}' is empty", f"declare at least one entry under '{what}'")
        return node.value

    # -- sections ----------------------------------------------------------
    def params(self, node: Node | None) -> tuple[dict[str, str], dict[str, tuple[str, ...]]]:
        """(each param's default, the declared choices of those that have some): ``name: value``, or
        ``name: {default: value, choices: [value, …]}`` (default: the first choice)."""
        if node is None:
            return {}, {}
        if not node.is_map:
            self.src.at(node, "'params' must be a mapping", "write 'params:' then 'key: value' lines")
            return {}, {}
        out: dict[str, str] = {}
        choices: dict[str, tuple[str, ...]] = {}
        for key, value in node.items():
            if not FIELD_NAME_RE.match(key):
                self.src.at_key(node, key, f"param name '{key}' is not an identifier", "use letters, digits and '_'")
            if key in BUILTIN_PLACEHOLDERS:
                self.src.at_key(node, key, f"param '{key}' shadows a built-in placeholder", "rename it")
            out[key] = ""  # declared, even if badly: its placeholders are not unknown as well
            if value.is_map:
                declared = self.param_with_choices(key, value)
                if declared is not None:
                    out[key], choices[key] = declared
                continue
            if value.is_list or value.value is None:
                self.src.at(value, f"param '{key}' must be a scalar or {{default: …, choices: […]}}",
                            "give a string or number, or e.g. {default: oracle, choices: [oracle, cv]}")
                continue
            out[key] = self.param_text(value)
        return out, choices

    def param_with_choices(self, key: str, node: Node) -> tuple[str, tuple[str, ...]] | None:
        """``{default: value, choices: [value, …]}``: (the default, the choices); None after a problem."""
        example = f"{key}: {{default: oracle, choices: [oracle, cv]}}"
        if not self.keys(node, ("default", "choices"), ("choices",), f"param '{key}'") or "choices" not in node.value:
            return None
        listed = node.value["choices"]
        if not listed.is_list or not listed.value or any(c.is_map or c.is_list or c.value is None
                                                         for c in listed.value):
            self.src.at(listed, f"param '{key}': 'choices' must be a non-empty list of values", f"e.g. {example}")
            return None
        choices = tuple(self.param_text(c) for c in listed.value)
        repeated = sorted({c for c in choices if choices.count(c) > 1})
        if repeated:
            self.src.at(listed, f"param '{key}': choice '{repeated[0]}' is listed twice", "list each value once")
            return None
        default_node = node.value.get("default")
        if default_node is None:
            return choices[0], choices
        if default_node.is_map or default_node.is_list or default_node.value is None:
            self.src.at(default_node, f"param '{key}': 'default' must be a value", f"e.g. {example}")
            return None
        default = self.param_text(default_node)
        if default not in choices:
            self.src.at(default_node, f"param '{key}': default '{default}' is not one of its choices "
                        f"({', '.join(choices)})", "add it to 'choices' or pick one of them")
            return None
        return default, choices

    @staticmethod
    def param_text(node: Node) -> str:
        return node.value if isinstance(node.value, str) else _scalar_text(node.value)

    def zenoh(self, node: Node | None) -> ZenohSection:
        if node is None:
            return ZenohSection()
        if not self.keys(node, ("endpoints", "connect", "config"), (), "'zenoh'"):
            return ZenohSection()
        endpoints = ZenohSection().endpoints
        if "endpoints" in node.value:
            ep_node = node.value["endpoints"]
            if not ep_node.is_list or not ep_node.value:
                self.src.at(ep_node, "'zenoh.endpoints' must be a non-empty list", 'e.g. ["tcp/127.0.0.1:0"]')
            else:
                endpoints = tuple(self.endpoint(item) for item in ep_node.value)
        connect: tuple[str, ...] = ()
        if "connect" in node.value:
            cn = node.value["connect"]
            if not cn.is_list:
                self.src.at(cn, "'zenoh.connect' must be a list", 'e.g. ["tcp/127.0.0.1:7447"]')
            else:
                connect = tuple(self.endpoint(item) for item in cn.value)
        config = None
        if "config" in node.value:
            cnode = node.value["config"]
            if self.expect(cnode, (str,), "'zenoh.config'", "a path to a JSON5 file"):
                config = (self.base_dir / cnode.value)
                if self.from_file and not config.is_file():
                    self.src.at(cnode, f"Zenoh config file '{config}' does not exist",
                                "give a path relative to the spec file")
        return ZenohSection(endpoints=endpoints, connect=connect, config_file=config)

    def endpoint(self, node: Node) -> str:
        if not self.expect(node, (str,), "an endpoint", 'a string like "tcp/127.0.0.1:0"'):
            return ""
        m = re.match(r"^(tcp|udp|tls|quic|ws|unixsock-stream)/(.+)\Z", node.value)
        if not m:
            self.src.at(node, f"endpoint '{node.value}' is not a Zenoh locator",
                        'write it as "tcp/HOST:PORT" (port 0 picks a free port)')
        return node.value

    def modules(self, node: Node | None, params: dict[str, str]) -> list[Module]:
        out: list[Module] = []
        seen: set[str] = set()
        for item in self.list_of_maps(node, "modules", required=True):
            if not self.keys(item, ("name", "command", "env", "cwd", "ready", "on_crash"), ("name", "command"),
                             "a module"):
                continue
            v = item.value
            name = self.name_of(v["name"], "module name") if "name" in v else "?"
            if "name" in v and name in seen:
                self.src.at(v["name"], f"module '{name}' is declared twice", "give each module a unique name")
            seen.add(name)
            command = self.command(v.get("command"), name, params)
            env = self.env(v.get("env"), params)
            cwd = None
            if "cwd" in v and self.expect(v["cwd"], (str,), "'cwd'", "a directory path"):
                cwd = self.base_dir / v["cwd"].value
                if self.from_file and not cwd.is_dir():
                    self.src.at(v["cwd"], f"directory '{cwd}' does not exist", "give a path relative to the spec file")
            ready = self.ready(v.get("ready"))
            on_crash = "end_run"
            if "on_crash" in v and self.expect(v["on_crash"], (str,), "'on_crash'", "end_run or keep_running"):
                on_crash = v["on_crash"].value
                if on_crash not in ON_CRASH:
                    self.src.at(v["on_crash"], f"'on_crash' must be end_run or keep_running, not '{on_crash}'",
                                did_you_mean(on_crash, ON_CRASH) or "write end_run or keep_running")
            out.append(Module(name=name, command=command, env=env, cwd=cwd, ready=ready, on_crash=on_crash))
        return out

    def command(self, node: Node | None, module: str, params: dict[str, str]) -> tuple[str, ...]:
        if node is None:
            return ()
        if isinstance(node.value, str):
            try:
                parts = shlex.split(node.value)
            except ValueError as exc:
                self.src.at(node, f"command of '{module}' cannot be split: {exc}", "balance the quotes")
                return ()
            part_nodes = [node] * len(parts)
        elif node.is_list:
            part_nodes = node.value
            parts = []
            for p in part_nodes:
                if p.is_map or p.is_list or p.value is None:
                    self.src.at(p, "a command argument must be a string", "quote it")
                    parts.append("")
                else:
                    parts.append(p.value if isinstance(p.value, str) else _scalar_text(p.value))
        else:
            self.src.at(node, f"command of '{module}' must be a list or a string", 'e.g. ["{python}", "-m", "pkg.mod"]')
            return ()
        if not parts:
            self.src.at(node, f"command of '{module}' is empty", "name the program to run")
        for part, pnode in zip(parts, part_nodes, strict=False):
            self.placeholders(part, pnode, params)
        return tuple(parts)

    def env(self, node: Node | None, params: dict[str, str]) -> dict[str, str]:
        if node is None:
            return {}
        if not node.is_map:
            self.src.at(node, "'env' must be a mapping", "write 'NAME: value' lines")
            return {}
        out = {}
        for key, value in node.items():
            if value.is_map or value.is_list or value.value is None:
                self.src.at(value, f"env value '{key}' must be a scalar", "quote it")
                continue
            text = value.value if isinstance(value.value, str) else _scalar_text(value.value)
            self.placeholders(text, value, params)
            out[key] = text
        return out

    def placeholders(self, text: str, node: Node, params: dict[str, str]) -> None:
        known = BUILTIN_PLACEHOLDERS + tuple(params)
        try:
            fields = [f for _, f, _, _ in string.Formatter().parse(text) if f is not None]
        except ValueError as exc:
            self.src.at(node, f"bad placeholder in '{text}': {exc}", "write a literal brace as '{{' or '}}'")
            return
        for f in fields:
            if f not in known:
                hint = did_you_mean(f, known) or f"known placeholders: {', '.join(known)}"
                self.src.at(node, f"unknown placeholder '{{{f}}}'", hint + " (or declare it under 'params')")

    def ready(self, node: Node | None) -> Readiness:
        if node is None:
            return Readiness(delay=0.0)
        if not self.keys(node, ("channel", "log", "delay", "timeout"), (), "'ready'"):
            return Readiness(delay=0.0)
        v = node.value
        if sum(k in v for k in ("channel", "log", "delay")) != 1:
            self.src.at(node, "'ready' needs exactly one of 'channel', 'log' or 'delay'",
                        "e.g. 'ready: {channel: pose}', 'ready: {log: \"listening\"}' or 'ready: {delay: 0.5}'")
        channel = None
        if "channel" in v and self.expect(v["channel"], (str,), "'ready.channel'", "a channel name"):
            channel = v["channel"].value
            self._ready_channels.append((channel, v["channel"]))
        log = None
        if "log" in v and self.expect(v["log"], (str,), "'ready.log'", "a regular expression"):
            log = v["log"].value
            try:
                re.compile(log)
            except re.error as exc:
                self.src.at(v["log"], f"'ready.log' is not a valid regular expression: {exc}", "fix or quote it")
        delay = self.number(v.get("delay"), "'ready.delay'", minimum=0.0, maximum=MAX_WAIT_S)
        timeout = self.number(v.get("timeout"), "'ready.timeout'", minimum=0.0, strictly=True, maximum=MAX_WAIT_S)
        if delay is None:
            delay = None if channel or log else 0.0
        return Readiness(channel=channel, log=log, delay=delay, timeout=timeout if timeout is not None else 20.0)

    def number(self, node: Node | None, what: str, minimum: float | None = None, strictly: bool = False,
               maximum: float | None = None) -> float | None:
        if node is None:
            return None
        if not self.expect(node, (int, float), what, "a number"):
            return None
        value = float(node.value)
        if value != value or value in (float("inf"), float("-inf")):
            self.src.at(node, f"{what} must be finite", "give a finite number")
            return None
        if minimum is not None and (value < minimum or (strictly and value == minimum)):
            self.src.at(node, f"{what} must be {'>' if strictly else '≥'} {minimum:g}", "give a larger value")
            return None
        if maximum is not None and value > maximum:
            self.src.at(node, f"{what} must be ≤ {maximum:g}", "give a smaller value")
            return None
        return value

    def channels(self, node: Node | None, modules: list[Module], types: dict[str, MessageType]) -> list[Channel]:
        out: list[Channel] = []
        names: set[str] = set()
        keys: dict[str, str] = {}
        module_names = [m.name for m in modules]
        for item in self.list_of_maps(node, "channels", required=True):
            allowed = ("name", "key", "topic", "producer", "consumers", "type", "encoding")
            if not self.keys(item, allowed, ("name", "producer", "type"), "a channel"):
                continue
            v = item.value
            # A CDR channel's type is a ROS 2 message type (its fields join `types`);
            # its key may come from its ROS 2 topic.
            cdr = None
            if "encoding" in v and v["encoding"].value == "cdr":
                cdr = resolve_cdr_channel(self.src, v, self.ros2, types)
            elif "topic" in v:
                self.src.at_key(item, "topic", "'topic' needs 'encoding: cdr' (a ROS 2 channel)",
                                "add 'encoding: cdr', or give a Zenoh 'key' instead")
            if "key" not in v and "topic" not in v:
                self.src.at(item, "a channel lacks 'key'",
                            "add 'key: …' (or, for ROS 2, 'topic:' and 'encoding: cdr')")
            name = self.name_of(v["name"], "channel name") if "name" in v else "?"
            if "name" in v and name in names:
                self.src.at(v["name"], f"channel '{name}' is declared twice", "give each channel a unique name")
            names.add(name)
            key = cdr[1] if cdr else ""
            if key and key in keys:
                self.src.at(v["topic"], f"topic '{v['topic'].value}' is already used by channel '{keys[key]}'",
                            "give each channel its own topic")
            elif key:
                keys[key] = name
            if "key" in v and self.expect(v["key"], (str,), "'key'", "a Zenoh key"):
                key = v["key"].value
                if not key:
                    self.src.at(v["key"], f"channel '{name}' has an empty key", "give a Zenoh key, e.g. 'demo/data'")
                elif not KEY_RE.match(key) or key.startswith("/") or key.endswith("/") or "//" in key:
                    self.src.at(v["key"], f"key {key!r} is not a concrete Zenoh key",
                                "use '/'-separated chunks without wildcards (*, **), '$', '?', '#' or spaces")
                elif key in keys:
                    self.src.at(v["key"], f"key '{key}' is already used by channel '{keys[key]}'",
                                "give each channel its own key")
                else:
                    keys[key] = name
            producer = ""
            if "producer" in v and self.expect(v["producer"], (str,), "'producer'", "a module name"):
                producer = v["producer"].value
                self.module_ref(v["producer"], producer, module_names)
            consumers: list[str] = []
            if "consumers" in v:
                cnode = v["consumers"]
                if not cnode.is_list:
                    self.src.at(cnode, "'consumers' must be a list of module names", "e.g. [planning, control]")
                else:
                    for c in cnode.value:
                        if self.expect(c, (str,), "a consumer", "a module name"):
                            self.module_ref(c, c.value, module_names)
                            if c.value == producer:
                                self.src.at(c, f"module '{producer}' consumes its own channel '{name}'",
                                            "remove it from consumers (a module hears its own messages anyway)")
                            consumers.append(c.value)
            type_name = ""
            if "type" in v and self.expect(v["type"], (str,), "'type'", "a type name"):
                type_name = v["type"].value
                if cdr is None and "encoding" in v and v["encoding"].value == "cdr":
                    pass  # reported by resolve_cdr_channel
                elif type_name not in types:
                    hint = did_you_mean(type_name, types) or "declare it under 'types'"
                    self.src.at(v["type"], f"unknown message type '{type_name}'", hint)
            encoding = "json"
            if "encoding" in v and self.expect(v["encoding"], (str,), "'encoding'", "an encoding name"):
                encoding = v["encoding"].value
                if encoding not in ENCODINGS:
                    hint = did_you_mean(encoding, ENCODINGS) or f"supported: {', '.join(ENCODINGS)}"
                    self.src.at(v["encoding"], f"unknown encoding '{encoding}'", hint)
            if encoding == "cdr":
                encoding = cdr[0] if cdr else "cdr"
            topic = v["topic"].value if "topic" in v and isinstance(v["topic"].value, str) else None
            out.append(Channel(name, key, producer, tuple(consumers), type_name, encoding, topic))
        for channel, cnode in self._ready_channels:
            if channel is not None and cnode is not None and channel not in names:
                hint = did_you_mean(channel, names) or "name a channel declared under 'channels'"
                self.src.at(cnode, f"readiness channel '{channel}' is not declared", hint)
        return out

    def module_ref(self, node: Node, name: str, module_names: list[str]) -> None:
        if name not in module_names:
            hint = did_you_mean(name, module_names) or f"modules: {', '.join(module_names)}"
            self.src.at(node, f"unknown module '{name}'", hint)

    # -- types -------------------------------------------------------------
    def types(self, node: Node | None) -> dict[str, MessageType]:
        if node is None:
            return {}
        if not node.is_map:
            self.src.at(node, "'types' must be a mapping of type names to fields", "see docs/spec.md")
            return {}
        names = list(node.value)
        out: dict[str, MessageType] = {}
        for tname, tnode in node.items():
            if not TYPE_NAME_RE.match(tname):
                self.src.at_key(node, tname, f"type name '{tname}' is not an identifier", "use letters, digits and '_'")
            if tname in SCALAR_KINDS or tname in ("enum", "array", "struct"):
                self.src.at_key(node, tname, f"type name '{tname}' is a built-in kind", "rename it")
            if not tnode.is_map or not tnode.value:
                self.src.at(tnode, f"type '{tname}' must map field names to field types", "e.g. 'x: float64'")
                out[tname] = MessageType(tname, {})  # keep the name known: later references are not errors too
                continue
            fields = {}
            for fname, fnode in tnode.items():
                if not FIELD_NAME_RE.match(fname):
                    self.src.at_key(tnode, fname, f"field name '{fname}' is not an identifier",
                                    "use letters, digits and '_' (field paths use '.' and '[]')")
                fields[fname] = self.field_type(fnode, names, f"{tname}.{fname}")
            out[tname] = MessageType(tname, fields)
        self.check_recursion(out, node)
        return out

    def field_type(self, node: Node, type_names: list[str], where: str) -> FieldType:
        if isinstance(node.value, str):
            return self.type_expr(node.value, node, type_names, where)
        if not node.is_map:
            self.src.at(node, f"field '{where}' has no type", "write a type name, 'T[]', {enum: […]} or {array: T}")
            return FieldType("string")
        v = node.value
        forms = [k for k in ("type", "enum", "array") if k in v]
        allowed = ("type", "enum", "array", "min", "max", "min_length", "max_length")
        self.keys(node, allowed, (), f"field '{where}'")
        if len(forms) != 1:
            self.src.at(node, f"field '{where}' needs exactly one of 'type', 'enum', 'array'",
                        "e.g. {type: float64, min: 0} or {enum: [a, b]} or {array: Point}")
            return FieldType("string")
        minimum = self.number(v.get("min"), f"'{where}.min'")
        maximum = self.number(v.get("max"), f"'{where}.max'")
        min_len = self.length(v.get("min_length"), where)
        max_len = self.length(v.get("max_length"), where)
        if minimum is not None and maximum is not None and minimum > maximum:
            self.src.at(v["min"], f"'{where}': min {minimum:g} > max {maximum:g}", "swap them")
        if min_len is not None and max_len is not None and min_len > max_len:
            self.src.at(v["min_length"], f"'{where}': min_length > max_length", "swap them")
        form = forms[0]
        if form == "enum":
            enode = v["enum"]
            if not enode.is_list or not enode.value:
                self.src.at(enode, f"enum of '{where}' must be a non-empty list", "e.g. {enum: [red, yellow, green]}")
                return FieldType("string")
            values = tuple(e.plain() for e in enode.value)
            if len(set(map(repr, values))) != len(values):
                self.src.at(enode, f"enum of '{where}' repeats a value", "list each value once")
            return FieldType("enum", values=values)
        if form == "array":
            anode = v["array"]
            items = self.field_type(anode, type_names, f"{where}[]")
            return FieldType("array", items=items, min_length=min_len, max_length=max_len)
        tnode = v["type"]
        if not isinstance(tnode.value, str):
            self.src.at(tnode, f"'type' of '{where}' must be a type name", "e.g. float64")
            return FieldType("string")
        base = self.type_expr(tnode.value, tnode, type_names, where)
        if (minimum is not None or maximum is not None) and base.kind not in SCALAR_KINDS[:10] + ("time",):
            self.src.at(node, f"'min'/'max' on '{where}' need a numeric type, not {base.describe()}", "remove them")
        if base.kind == "array":
            return FieldType("array", items=base.items, min_length=min_len, max_length=max_len)
        if min_len is not None or max_len is not None:
            self.src.at(node, f"'min_length'/'max_length' on '{where}' need an array type", "use {array: T, …}")
        return FieldType(base.kind, ref=base.ref, values=base.values, items=base.items,
                         minimum=minimum, maximum=maximum)

    def type_expr(self, text: str, node: Node, type_names: list[str], where: str) -> FieldType:
        text = text.strip()
        if text.endswith("[]"):
            return FieldType("array", items=self.type_expr(text[:-2], node, type_names, where + "[]"))
        if text in SCALAR_KINDS:
            return FieldType(text)
        if text in type_names:
            return FieldType("struct", ref=text)
        hint = did_you_mean(text, list(SCALAR_KINDS) + type_names) or (
            "use a scalar kind (" + ", ".join(SCALAR_KINDS) + ") or a declared type")
        self.src.at(node, f"field '{where}' has unknown type '{text}'", hint)
        return FieldType("string")

    def length(self, node: Node | None, where: str) -> int | None:
        if node is None:
            return None
        if not isinstance(node.value, int) or isinstance(node.value, bool) or node.value < 0:
            self.src.at(node, f"length bound of '{where}' must be a whole number ≥ 0", "e.g. max_length: 64")
            return None
        return node.value

    def check_recursion(self, types: dict[str, MessageType], node: Node) -> None:
        # A struct that contains itself without an array in between can never
        # be a finite message.
        def refs(ft: FieldType) -> list[str]:
            return [ft.ref] if ft.kind == "struct" and ft.ref else []

        for start in types:
            stack, seen = [start], set()
            while stack:
                cur = stack.pop()
                for ft in types.get(cur, MessageType(cur, {})).fields.values():
                    for r in refs(ft):
                        if r == start:
                            self.src.at_key(node, start, f"type '{start}' contains itself",
                                            "break the cycle with an array")
                            stack = []
                            break
                        if r not in seen:
                            seen.add(r)
                            stack.append(r)

    # -- brittle and reserved sections ------------------------------------
    def brittle(self, node: Node | None, types: dict[str, MessageType]) -> list[str]:
        if node is None:
            return []
        if not node.is_list:
            self.src.at(node, "'brittle' must be a list of 'Type.field' entries", "e.g. [Header.stamp, Header.seq]")
            return []
        out = []
        for item in node.value:
            if not self.expect(item, (str,), "a brittle entry", "'Type.field.path'"):
                continue
            try:
                check_brittle_pattern(types, item.value)
            except FieldPathError as exc:
                self.src.report(item.line, item.column + (exc.position or 0), str(exc),
                                "write 'TypeName.field.path' with a type and fields declared under 'types'")
                continue
            out.append(item.value)
        return out


MAX_WAIT_S = 86_400.0  # a day: beyond it a wait is a typo, and timers overflow near 1e308


def _scalar_text(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


