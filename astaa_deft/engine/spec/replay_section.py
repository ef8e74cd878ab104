"""The spec's ``replay:`` section: modules that can run alone, for DeFT frames, module tests and minimisation.

```yaml
replay:
  modules:
    - module: control                       # a declared module
      inputs: [trajectory, localization]    # channels it consumes (the trigger among them)
      trigger: localization                 # each message of it starts one execution
      outputs: [command]                    # the channel it answers on (one per entry)
      factory: mystack.control:Replay       # in-process: Replay(**args).step(frame) -> message or None
      args: {defects: "{defects}"}
      frames: per_trigger                   # one frame per trigger message (default) | per_output
      exceptions: crash                     # an exception from step() is the module's crash | unresolved
      hang_after: 1.0                       # s: a step that has not returned by then is a hang
      threshold: 0.0                        # accept a replayed output this far from the recorded one
      ignore: [header.stamp]                # output fields the comparison skips
      provenance: debug.inputs              # optional: where the output names its inputs' header.seq/stamp
```

The ``planner:`` section loads into the same record (``spec/replay_module.py``):
its frames are found per recorded output by DeFT's candidate search and its
outputs compared as trajectories. Every consumer of replayable modules goes
through :class:`ReplayModule`; the loader calls :func:`build_replay_section`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from astaa_deft.model.errors import did_you_mean
from astaa_deft.model.fields import FieldPath, FieldPathError
from astaa_deft.model.sut import Channel, MessageType, Module
from astaa_deft.engine.spec.planner import read_provenance, read_runner, read_setting
from astaa_deft.engine.spec.replay_module import EXCEPTIONS, FRAME_MODES, FrameMode, ReplayModule, StepExceptions
from astaa_deft.io.yamlsource import Node, Source, describe_value
from astaa_deft.engine.spec.reader import declared_channel

__all__ = ["ReplayModule", "build_replay_section"]

DOCS = "see docs/spec.md (replay:)"

ENTRY_KEYS = ("module", "inputs", "trigger", "outputs", "factory", "args", "command", "frames", "exceptions",
              "hang_after", "threshold", "lookback_ms", "skew_ms", "ignore", "provenance")
REQUIRED = ("module", "inputs", "trigger", "outputs")


def build_replay_section(src: Source, node: Node | None, channels: Sequence[Channel],
                         modules: Sequence[Module], *, types: Mapping[str, MessageType] | None = None
                         ) -> tuple[ReplayModule, ...]:
    """The entries of ``replay.modules`` (problems reported on ``src`` with line, column and a fix)."""
    if node is None or node.value is None:
        return ()
    if not node.is_map:
        src.at(node, "'replay' must be a mapping with 'modules: [...]'", DOCS)
        return ()
    for key in node.value:
        if key != "modules":
            src.at_key(node, key, f"unknown key '{key}' in 'replay'", did_you_mean(key, ("modules",)) or
                       "'replay' takes one key, 'modules'")
    entries = node.value.get("modules")
    if entries is None:
        src.at(node, "'replay' lacks 'modules'", "add 'modules:' with one entry per module that can run alone")
        return ()
    if not entries.is_list or not entries.value:
        src.at(entries, "'replay.modules' must be a non-empty list of entries",
               "e.g. '- {module: control, inputs: [...], trigger: ..., outputs: [...], factory: pkg.mod:Name}'")
        return ()
    out: list[ReplayModule] = []
    seen: set[tuple[str, str]] = set()
    for n, item in enumerate(entries.value):
        entry = _entry(src, item, f"replay.modules[{n}]", by_name={c.name: c for c in channels}, types=types or {},
                       module_names=[m.name for m in modules])
        if entry is None:
            continue
        if (entry.module, entry.output) in seen:
            src.at(item, f"module '{entry.module}' with output '{entry.output}' has two replay entries",
                   "keep one entry per module and output")
        seen.add((entry.module, entry.output))
        out.append(entry)
    return tuple(out)


def _entry(src: Source, node: Node, where: str, *, by_name: Mapping[str, Channel], types: Mapping[str, MessageType],
           module_names: list[str]) -> ReplayModule | None:
    if not node.is_map:
        src.at(node, f"'{where}' must be a mapping", "e.g. {module: control, inputs: [...], trigger: ..., "
               "outputs: [...], factory: pkg.mod:Name}")
        return None
    v = node.value
    for key in v:
        if key not in ENTRY_KEYS:
            src.at_key(node, key, f"unknown key '{key}' in '{where}'",
                       did_you_mean(key, ENTRY_KEYS) or f"allowed: {', '.join(ENTRY_KEYS)}")
    missing = [key for key in REQUIRED if key not in v]
    for key in missing:
        src.at(node, f"'{where}' lacks '{key}'", f"add '{key}: …' ({DOCS})")
    if "factory" not in v and "command" not in v:
        src.at(node, f"'{where}' needs 'factory', 'command' or both",
               "factory: in-process (pkg.module:Name, step(frame) -> message); command: its own process")
    if missing:
        return None
    module = _text(src, v["module"], f"{where}.module")
    if module and module not in module_names:
        src.at(v["module"], f"replay module '{module}' is not declared",
               did_you_mean(module, module_names) or "declare it under 'modules'")

    def channel_ref(n: Node, what: str) -> str:
        return declared_channel(src, n, what, by_name)

    inputs: list[str] = []
    if not v["inputs"].is_list or not v["inputs"].value:
        src.at(v["inputs"], f"'{where}.inputs' must be a non-empty list of channel names",
               "e.g. [trajectory, localization]")
    else:
        inputs = [channel_ref(n, "replay input") for n in v["inputs"].value]
        for n, name in zip(v["inputs"].value, inputs, strict=True):
            ch = by_name.get(name)
            if ch is not None and module in module_names and module not in ch.consumers:
                src.at(n, f"channel '{name}' does not list '{module}' among its consumers", "add it, or drop the input")
    trigger = channel_ref(v["trigger"], "replay trigger")
    if trigger and inputs and trigger not in inputs:
        src.at(v["trigger"], f"the trigger '{trigger}' is not among the inputs of '{where}'", "add it to 'inputs'")
    output = ""
    outs = v["outputs"]
    if not outs.is_list or len(outs.value) != 1:
        src.at(outs, f"'{where}.outputs' must list exactly one channel",
               "give one output per entry (a module with two outputs gets two entries)")
    else:
        output = channel_ref(outs.value[0], "replay output")
        ch = by_name.get(output)
        if ch is not None and module in module_names and ch.producer != module:
            src.at(outs.value[0], f"channel '{output}' is produced by '{ch.producer}', not '{module}'",
                   "name a channel the module produces")
    factory, args, command = read_runner(src, v, where, factory_example="mystack.control:Replay",
                                         command_example='["{python}", "-m", "mystack.control"]')
    frames = FrameMode(_choice(src, v.get("frames"), f"{where}.frames", FRAME_MODES))
    exceptions = StepExceptions(_choice(src, v.get("exceptions"), f"{where}.exceptions", EXCEPTIONS))
    hang_after = read_setting(src, v.get("hang_after"), f"{where}.hang_after", default=1.0, positive=True)
    threshold = read_setting(src, v.get("threshold"), f"{where}.threshold", default=0.0)
    lookback = read_setting(src, v.get("lookback_ms"), f"{where}.lookback_ms", default=100.0)
    skew = read_setting(src, v.get("skew_ms"), f"{where}.skew_ms", default=5.0)
    ignore: tuple[str, ...] = ()
    if "ignore" in v:
        n = v["ignore"]
        if n.is_list and all(isinstance(i.value, str) and i.value for i in n.value):
            ignore = tuple(i.value for i in n.value)
            for item in n.value:
                _check_ignored_path(src, item, where)
        else:
            src.at(n, f"'{where}.ignore' must be a list of output field paths", "e.g. [header.stamp]")
    return ReplayModule(module=module, inputs=tuple(inputs), trigger=trigger, output=output, factory=factory,
                        factory_args=args, command=command, frames=frames, exceptions=exceptions, hang_after=hang_after,
                        threshold=threshold, lookback_ms=lookback, skew_ms=skew, ignore=ignore, where=where,
                        provenance=read_provenance(src, v.get("provenance"), f"{where}.provenance",
                                                   output_type=types.get(by_name[output].type)
                                                   if output in by_name else None, types=types))


def _check_ignored_path(src: Source, node: Node, where: str) -> None:
    """An ``ignore:`` entry is a field path (a leaf, a whole struct, an array; ``[*]``: every element)."""
    try:
        FieldPath.parse(node.value)
    except FieldPathError as exc:
        src.at(node, f"'{where}.ignore' entry '{node.value}' is no output field path: {exc.reason}",
               "e.g. header.stamp, a whole struct (header) or a field of every element (points[*].t)")


def _text(src: Source, node: Node, what: str) -> str:
    if not isinstance(node.value, str):
        src.at(node, f"'{what}' must be a string, not {describe_value(node.value)}", "give a module name")
        return ""
    return node.value


def _choice(src: Source, node: Node | None, what: str, allowed: tuple[str, ...]) -> str:
    if node is None:
        return allowed[0]
    if node.value not in allowed:
        src.at(node, f"'{what}' must be one of {', '.join(allowed)}, not {describe_value(node.value)}",
               did_you_mean(str(node.value), allowed) or f"write {allowed[0]}")
        return allowed[0]
    return str(node.value)
