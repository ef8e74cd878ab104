"""The spec's ``modules:`` section: each module's command, environment, directory, readiness, crash policy,
and whether it is the plant (the world a simulator models, not a module under test).

Commands and environment values may hold ``{placeholders}``: the built-in ones
and the declared params; an unknown one is reported here, not at launch.
"""

from __future__ import annotations

import shlex
import string
from dataclasses import dataclass

from astaa_deft.engine.spec.params_section import BUILTIN_PLACEHOLDERS
from astaa_deft.engine.spec.reader import MAX_WAIT_S, SpecReader, scalar_text
from astaa_deft.io.yamlsource import Node
from astaa_deft.model.errors import did_you_mean
from astaa_deft.model.patterns import PatternError, compile_user_pattern
from astaa_deft.model.sut import Module, Readiness

ON_CRASH = ("end_run", "keep_running")
MODULE_KEYS = ("name", "command", "env", "cwd", "ready", "on_crash", "plant")


@dataclass(frozen=True)
class ReadyChannelRef:
    """A ``ready: {channel: …}`` of a module, checked once the channels are known."""

    channel: str
    node: Node


@dataclass(frozen=True)
class ModulesSection:
    modules: tuple[Module, ...]
    ready_channels: tuple[ReadyChannelRef, ...]


def read_modules_section(reader: SpecReader, node: Node | None, params: dict[str, str]) -> ModulesSection:
    """The ``modules:`` section (required, non-empty); a module with bad keys is left out, reported."""
    out: list[Module] = []
    ready_channels: list[ReadyChannelRef] = []
    seen: set[str] = set()
    for item in reader.list_of_maps(node, "modules", required=True):
        if not reader.keys(item, MODULE_KEYS, ("name", "command"), "a module"):
            continue
        v = item.value
        name = reader.name_of(v["name"], "module name") if "name" in v else "?"
        if "name" in v and name in seen:
            reader.src.at(v["name"], f"module '{name}' is declared twice", "give each module a unique name")
        seen.add(name)
        command = _command(reader, v.get("command"), name, params)
        env = _env(reader, v.get("env"), params)
        cwd = None
        if "cwd" in v and reader.expect(v["cwd"], (str,), "'cwd'", "a directory path"):
            cwd = reader.base_dir / v["cwd"].value
            if reader.from_file and not cwd.is_dir():
                reader.src.at(v["cwd"], f"directory '{cwd}' does not exist", "give a path relative to the spec file")
        ready = _ready(reader, v.get("ready"))
        if ready.channel is not None:
            ready_channels.append(ReadyChannelRef(ready.channel, v["ready"].value["channel"]))
        on_crash = "end_run"
        if "on_crash" in v and reader.expect(v["on_crash"], (str,), "'on_crash'", "end_run or keep_running"):
            on_crash = v["on_crash"].value
            if on_crash not in ON_CRASH:
                reader.src.at(v["on_crash"], f"'on_crash' must be end_run or keep_running, not '{on_crash}'",
                              did_you_mean(on_crash, ON_CRASH) or "write end_run or keep_running")
        plant = False
        if "plant" in v and reader.expect(v["plant"], (bool,), "'plant'", "true or false"):
            plant = bool(v["plant"].value)
        out.append(Module(name=name, command=command, env=env, cwd=cwd, ready=ready, on_crash=on_crash,
                          plant=plant))
    return ModulesSection(tuple(out), tuple(ready_channels))


def check_ready_channels(reader: SpecReader, refs: tuple[ReadyChannelRef, ...], channel_names: set[str]) -> None:
    """Report each readiness channel that is not a declared channel."""
    for ref in refs:
        if ref.channel not in channel_names:
            hint = did_you_mean(ref.channel, channel_names) or "name a channel declared under 'channels'"
            reader.src.at(ref.node, f"readiness channel '{ref.channel}' is not declared", hint)


def _command(reader: SpecReader, node: Node | None, module: str, params: dict[str, str]) -> tuple[str, ...]:
    if node is None:
        return ()
    if isinstance(node.value, str):
        try:
            parts = shlex.split(node.value)
        except ValueError as exc:
            reader.src.at(node, f"command of '{module}' cannot be split: {exc}", "balance the quotes")
            return ()
        part_nodes = [node] * len(parts)
    elif node.is_list:
        part_nodes = node.value
        parts = []
        for p in part_nodes:
            if p.is_map or p.is_list or p.value is None:
                reader.src.at(p, "a command argument must be a string", "quote it")
                parts.append("")
            else:
                parts.append(p.value if isinstance(p.value, str) else scalar_text(p.value))
    else:
        reader.src.at(node, f"command of '{module}' must be a list or a string", 'e.g. ["{python}", "-m", "pkg.mod"]')
        return ()
    if not parts:
        reader.src.at(node, f"command of '{module}' is empty", "name the program to run")
    for part, pnode in zip(parts, part_nodes, strict=False):
        _placeholders(reader, part, pnode, params)
    return tuple(parts)


def _env(reader: SpecReader, node: Node | None, params: dict[str, str]) -> dict[str, str]:
    if node is None:
        return {}
    if not node.is_map:
        reader.src.at(node, "'env' must be a mapping", "write 'NAME: value' lines")
        return {}
    out = {}
    for key, value in node.items():
        if value.is_map or value.is_list or value.value is None:
            reader.src.at(value, f"env value '{key}' must be a scalar", "quote it")
            continue
        text = value.value if isinstance(value.value, str) else scalar_text(value.value)
        _placeholders(reader, text, value, params)
        out[key] = text
    return out


def _placeholders(reader: SpecReader, text: str, node: Node, params: dict[str, str]) -> None:
    known = BUILTIN_PLACEHOLDERS + tuple(params)
    try:
        fields = [f for _, f, _, _ in string.Formatter().parse(text) if f is not None]
    except ValueError as exc:
        reader.src.at(node, f"bad placeholder in '{text}': {exc}", "write a literal brace as '{{' or '}}'")
        return
    for f in fields:
        if f not in known:
            hint = did_you_mean(f, known) or f"known placeholders: {', '.join(known)}"
            reader.src.at(node, f"unknown placeholder '{{{f}}}'", hint + " (or declare it under 'params')")


def _ready(reader: SpecReader, node: Node | None) -> Readiness:
    if node is None:
        return Readiness(delay=0.0)
    if not reader.keys(node, ("channel", "log", "delay", "timeout"), (), "'ready'"):
        return Readiness(delay=0.0)
    v = node.value
    if sum(k in v for k in ("channel", "log", "delay")) != 1:
        reader.src.at(node, "'ready' needs exactly one of 'channel', 'log' or 'delay'",
                      "e.g. 'ready: {channel: pose}', 'ready: {log: \"listening\"}' or 'ready: {delay: 0.5}'")
    channel = None
    if "channel" in v and reader.expect(v["channel"], (str,), "'ready.channel'", "a channel name"):
        channel = v["channel"].value
    log = None
    if "log" in v and reader.expect(v["log"], (str,), "'ready.log'", "a regular expression"):
        log = v["log"].value
        if not log:
            reader.src.at(v["log"], "'ready.log' is empty: it matches any line, so the module would count as ready "
                          "at its first output", "give a pattern of the line the module prints when ready, e.g. "
                          "'ready: {log: \"listening\"}'")
        try:
            compile_user_pattern(log)
        except PatternError as exc:
            reader.src.at(v["log"], f"'ready.log' {exc.reason}", exc.fix)
    delay = reader.number(v.get("delay"), "'ready.delay'", minimum=0.0, maximum=MAX_WAIT_S)
    timeout = reader.number(v.get("timeout"), "'ready.timeout'", minimum=0.0, strictly=True, maximum=MAX_WAIT_S)
    if delay is None:
        delay = None if channel or log else 0.0
    return Readiness(channel=channel, log=log, delay=delay, timeout=timeout if timeout is not None else 20.0)
