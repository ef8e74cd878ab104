"""The spec's `planner:` section: which module plans, on what, and how to replay it.

Validated with located errors like the rest of the spec; the loader calls
``build_planner`` with the section's YAML node.
"""

from __future__ import annotations

import re
from pathlib import Path
from collections.abc import Mapping, Sequence

from astaa_deft.model.errors import did_you_mean
from astaa_deft.model.fields import FieldPath, FieldPathError, type_at
from astaa_deft.model.sut import Channel, MessageType, Module
from astaa_deft.io.yamlsource import Node, Source, describe_value
from astaa_deft.engine.spec.reader import declared_channel
from astaa_deft.engine.spec.replay_module import (
    CollisionOracle,
    FrameMode,
    ReplayModule,
    StepExceptions,
    TrajectoryLayout,
)

FACTORY_RE = re.compile(r"^(?:[A-Za-z_][\w.]*|[^:\n]+\.py):[A-Za-z_]\w*\Z")  # pkg.module:Name, or path.py:Name
PAPER_THRESHOLDS = (0.0, 0.1, 0.23, 1.62, 6.99, 17.15)


KEYS = ("module", "inputs", "trigger", "output", "trajectory", "replay", "threshold", "lookback_ms", "skew_ms",
        "oracle", "provenance")
REPLAY_KEYS = ("factory", "args", "command")
TRAJ_KEYS = ("points", "x", "y", "t", "heading", "time", "stamp")
COLLISION_KEYS = ("ego", "obstacles", "margin")
OBSTACLE_KEYS = ("channel", "array", "length", "width", "id", "trajectory")


def build_planner(src: Source, node: Node | None, types: Mapping[str, MessageType], *,
                  channels: Sequence[Channel], modules: Sequence[Module]) -> ReplayModule | None:
    if node is None or node.value is None:
        return None
    if not node.is_map:
        src.at(node, "'planner' must be a mapping", "see docs/deft.md")
        return None
    for key in node.value:
        if key not in KEYS:
            src.at_key(node, key, f"unknown key '{key}' in 'planner'",
                       did_you_mean(key, KEYS) or f"allowed: {', '.join(KEYS)}")
    for key in ("module", "inputs", "trigger", "output", "replay"):
        if key not in node.value:
            src.at(node, f"'planner' lacks '{key}'", f"add '{key}: …' (see docs/deft.md)")
    v = node.value
    by_name = {c.name: c for c in channels}
    module_names = [m.name for m in modules]

    def text(key: str) -> str:
        n = v.get(key)
        if n is None:
            return ""
        if not isinstance(n.value, str):
            src.at(n, f"'planner.{key}' must be a string", "")
            return ""
        return n.value

    def channel_ref(n: Node, what: str) -> str:
        return declared_channel(src, n, what, by_name)

    module = text("module")
    if module and module not in module_names:
        src.at(v["module"], f"planner module '{module}' is not declared", did_you_mean(module, module_names) or "")
    inputs: list[str] = []
    if "inputs" in v:
        if not v["inputs"].is_list or not v["inputs"].value:
            src.at(v["inputs"], "'planner.inputs' must be a non-empty list of channel names",
                   "e.g. [routing, localization, prediction]")
        else:
            inputs = [channel_ref(n, "planner input") for n in v["inputs"].value]
    trigger = channel_ref(v["trigger"], "planner trigger") if "trigger" in v else ""
    if trigger and inputs and trigger not in inputs:
        src.at(v["trigger"], f"the trigger '{trigger}' is not among the planner's inputs", "add it to 'inputs'")
    output = channel_ref(v["output"], "planner output") if "output" in v else ""
    if module and module_names:
        for name in inputs:
            ch = by_name.get(name)
            if ch is not None and module not in ch.consumers:
                src.at(v["inputs"], f"channel '{name}' does not list '{module}' among its consumers",
                       "add it, or drop the input")
        ch = by_name.get(output)
        if ch is not None and ch.producer != module:
            src.at(v["output"], f"channel '{output}' is produced by '{ch.producer}', not '{module}'",
                   "name the planner's output")

    layout = _trajectory(src, v.get("trajectory"), types, by_name.get(output))
    factory, args, command = _replay(src, v.get("replay"))
    threshold = read_setting(src, v.get("threshold"), "planner.threshold", default=0.0)
    lookback = read_setting(src, v.get("lookback_ms"), "planner.lookback_ms", default=100.0)
    skew = read_setting(src, v.get("skew_ms"), "planner.skew_ms", default=5.0)
    collision = _oracle(src, v.get("oracle"), inputs)
    # The planner is a module that runs alone like any other, with its extras: frames found per recorded
    # output, outputs compared as trajectories; an exception from step() is not judged (unresolved).
    return ReplayModule(module=module, inputs=tuple(inputs), trigger=trigger, output=output, factory=factory,
                        factory_args=args, command=command, frames=FrameMode.PER_OUTPUT,
                        exceptions=StepExceptions.UNRESOLVED, hang_after=0.0, threshold=threshold, lookback_ms=lookback,
                        skew_ms=skew, trajectory=layout, collision=collision, where="planner",
                        provenance=read_provenance(src, v.get("provenance"), "planner.provenance",
                                                   output_type=_declared(types, by_name.get(output)), types=types))


MAX_FIELD_PATH_CHARS = 1000  # a field path a spec names: far above real ones


def read_provenance(src: Source, node: Node | None, what: str, *,
                    output_type: MessageType | None = None, types: Mapping[str, MessageType] | None = None
                    ) -> str | None:
    """The ``provenance:`` field path (where the output names the inputs it used), or None. With the output's
    declared type (``output_type``, its field types in ``types``), a path naming no field of it is a problem."""
    if node is None:
        return None
    if not isinstance(node.value, str) or not node.value:
        src.at(node, f"'{what}' must be a field path of the output, not {describe_value(node.value)}",
               "e.g. provenance: debug.inputs (a mapping {input channel: its header.seq or header.stamp})")
        return None
    if len(node.value) > MAX_FIELD_PATH_CHARS:
        src.at(node, f"'{what}' is {len(node.value):,} characters long (at most {MAX_FIELD_PATH_CHARS:,})",
               "e.g. provenance: debug.inputs")
        return None
    try:
        path = FieldPath.parse(node.value)
    except FieldPathError as exc:
        src.at(node, f"'{what}' is not a field path: {exc}", "e.g. provenance: debug.inputs")
        return None
    missing = missing_field(path, output_type, types or {})
    if missing is not None:
        src.at(node, f"'{what}' names {node.value!r}, but {missing}", "name a field of the output's type")
        return None
    return node.value


def _declared(types: Mapping[str, MessageType], channel: Channel | None) -> MessageType | None:
    """The channel's message type when the spec's ``types:`` declares it (None: not declared there)."""
    return types.get(channel.type) if channel is not None else None


def missing_field(path: FieldPath, message: MessageType | None, types: Mapping[str, MessageType]) -> str | None:
    """Why ``path`` names no field of ``message`` (None: it does, or its type is not declared to check)."""
    if message is None:
        return None
    try:
        type_at(types, message.name, path)
    except FieldPathError as exc:
        return exc.reason or str(exc)
    return None


def _oracle(src: Source, node: Node | None, inputs: list[str]) -> CollisionOracle | None:
    if node is None:
        return None
    if not node.is_map or set(node.value) - {"collision"}:
        src.at(node, "'planner.oracle' takes one key, 'collision'", "see docs/deft.md")
        return None
    c = node.value.get("collision")
    if c is None or not c.is_map:
        src.at(node, "'planner.oracle.collision' must be a mapping", "{ego: {length, width}, obstacles: {channel, …}}")
        return None
    for key in c.value:
        if key not in COLLISION_KEYS:
            src.at_key(c, key, f"unknown key '{key}' in the collision oracle", did_you_mean(key, COLLISION_KEYS) or "")
    ego, obstacles = c.value.get("ego"), c.value.get("obstacles")
    if ego is None or obstacles is None or not ego.is_map or not obstacles.is_map:
        src.at(c, "the collision oracle needs 'ego: {length, width}' and 'obstacles: {channel, …}'", "")
        return None
    length = read_setting(src, ego.value.get("length"), "oracle ego length", default=0.0)
    width = read_setting(src, ego.value.get("width"), "oracle ego width", default=0.0)
    if length <= 0 or width <= 0:
        src.at(ego, "the ego's 'length' and 'width' must be positive numbers (m)", "e.g. {length: 4.6, width: 1.9}")
    fields = {}
    for key, n in obstacles.items():
        if key not in OBSTACLE_KEYS:
            src.at_key(obstacles, key, f"unknown key '{key}' in the oracle's obstacles",
                       did_you_mean(key, OBSTACLE_KEYS) or "")
        elif isinstance(n.value, str) and n.value:
            fields[key] = n.value
        else:
            src.at(n, f"the oracle's obstacles '{key}' must be a field path, not {describe_value(n.value)}",
                   f"e.g. {key}: {key}")
    channel = fields.pop("channel", "")
    if channel not in inputs:
        src.at(obstacles, f"the oracle's obstacle channel '{channel}' is not a planner input",
               "name the input that carries predicted obstacles")
    margin = read_setting(src, c.value.get("margin"), "oracle margin", default=0.0)
    return CollisionOracle(ego_length=length, ego_width=width, channel=channel, margin=margin, **fields)


def _trajectory(src: Source, node: Node | None, types: Mapping[str, MessageType],
                output: Channel | None) -> TrajectoryLayout:
    if node is None:
        layout = TrajectoryLayout()
    elif not node.is_map:
        src.at(node, "'planner.trajectory' must be a mapping", "e.g. {points: points, x: x, y: y, t: t}")
        return TrajectoryLayout()
    else:
        for key in node.value:
            if key not in TRAJ_KEYS:
                src.at_key(node, key, f"unknown key '{key}' in 'planner.trajectory'",
                           did_you_mean(key, TRAJ_KEYS) or "")
        values = {k: n.value for k, n in node.items() if k in TRAJ_KEYS and isinstance(n.value, str)}
        layout = TrajectoryLayout(**values)
        if layout.time not in ("absolute", "relative"):
            src.at(node.value["time"], f"'time' must be 'absolute' or 'relative', not '{layout.time}'", "")
    if output is None or output.type not in types:
        return layout
    where = node if node is not None else None
    try:
        points = type_at(types, output.type, layout.points)
        if points.kind != "array" or points.items is None or points.items.kind != "struct":
            raise FieldPathError(f"'{layout.points}' is not an array of points", text=layout.points, position=0)
        for sub in (layout.x, layout.y, layout.t):
            type_at(types, points.items.ref or "", sub)
        if layout.time == "relative":
            type_at(types, output.type, layout.stamp)
    except FieldPathError as exc:
        line, col = (where.line, where.column) if where is not None else (1, 1)
        src.report(line, col, f"planner trajectory layout does not fit type '{output.type}': {exc}",
                   "set 'planner.trajectory' {points, x, y, t} to the output's field paths")
    return layout


def _replay(src: Source, node: Node | None) -> tuple[str | None, dict[str, str], tuple[str, ...]]:
    if node is None:
        return None, {}, ()
    if not node.is_map:
        src.at(node, "'planner.replay' must be a mapping", "{factory: pkg.mod:Name} or {command: [...]}")
        return None, {}, ()
    for key in node.value:
        if key not in REPLAY_KEYS:
            src.at_key(node, key, f"unknown key '{key}' in 'planner.replay'", did_you_mean(key, REPLAY_KEYS) or "")
    v = node.value
    if "factory" not in v and "command" not in v:
        src.at(node, "'planner.replay' needs 'factory', 'command' or both",
               "factory: in-process (pkg.module:Name); command: the planner's own process, fed over Zenoh")
    return read_runner(src, v, "planner.replay", factory_example="mystack.planner:Planner",
                       command_example='["{python}", "-m", "mystack.planner"]')


def read_runner(src: Source, v: Mapping[str, Node], where: str, *, factory_example: str,
                command_example: str) -> tuple[str | None, dict[str, str], tuple[str, ...]]:
    """A replayable module's ``factory`` (in-process), ``args`` and ``command`` (its own process).

    Shared by the planner section and each entry of the ``replay:`` section.
    """
    factory = None
    if "factory" in v:
        factory = v["factory"].value
        if not isinstance(factory, str) or not FACTORY_RE.match(factory):
            message = (f"factory '{factory}' is not 'package.module:Name' (or 'path/to/file.py:Name', relative to"
                       " the spec)" if isinstance(factory, str)
                       else f"'factory' must be text 'package.module:Name', not {describe_value(factory)}")
            src.at(v["factory"], message, f"e.g. {factory_example}")
            factory = None
        elif not _module_found(factory.rpartition(":")[0], src.name):
            src.at(v["factory"], f"factory module '{factory.rpartition(':')[0]}' is neither on the Python path nor in "
                   "the spec's directory", "install the package that provides it, put it in the spec's directory, "
                   "add its directory to PYTHONPATH, or fix the name")
    args: dict[str, str] = {}
    if "args" in v:
        if not v["args"].is_map:
            src.at(v["args"], f"'{where}.args' must be a mapping of keyword arguments", "e.g. {defects: '{defects}'}")
        else:
            for k, n in v["args"].items():
                if n.is_map or n.is_list:
                    src.at(n, f"'{where}.args.{k}' must be a single value, not {describe_value(n.value)}",
                           "give a string, a number or a '{param}' placeholder")
                else:
                    args[k] = str(n.value)
    command: tuple[str, ...] = ()
    if "command" in v:
        c = v["command"]
        if c.is_list and c.value and all(isinstance(n.value, str) for n in c.value):
            command = tuple(n.value for n in c.value)
        else:
            src.at(c, f"'{where}.command' must be a non-empty list of strings", f"e.g. {command_example}")
    return factory, args, command


MAX_SETTING = 1e9  # beyond any sensible metres, milliseconds or seconds; keeps `x * 1e6` an int64


def read_setting(src: Source, node: Node | None, what: str, *, default: float, positive: bool = False) -> float:
    """A finite number in [0, MAX_SETTING] (> 0 when ``positive``), ``default`` when absent or reported."""
    if node is None:
        return default
    value = node.value
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value <= MAX_SETTING \
            or (positive and value == 0):
        src.at(node, f"'{what}' must be a finite number {'> 0' if positive else '≥ 0'} and at most {MAX_SETTING:g}, "
               f"not {describe_value(value)}", f"e.g. {default:g}")
        return default
    return float(value)


def resolve_args(args: Mapping[str, str], params: Mapping[str, str]) -> dict[str, str | bool]:
    """Placeholders filled from the run's params; 'true'/'on' style words become booleans."""
    out: dict[str, str | bool] = {}
    for key, value in args.items():
        text = value.format_map(dict(params))
        low = text.lower()
        out[key] = True if low in ("true", "on", "yes") else False if low in ("false", "off", "no") else text
    return out


def _module_found(module: str, spec_name: str) -> bool:
    """Whether replay would find the factory's module, without running it: on the path or next to the spec.

    A spec that is not a file (the copy stored in a log, read on another
    machine) is not held to it: replay says so clearly if it comes to that.
    """
    import importlib.util

    spec_file = Path(spec_name)
    if not spec_file.is_file():
        return True
    if module.endswith(".py"):  # a file, relative to the spec
        return (spec_file.resolve().parent / module).is_file()
    top = module.split(".")[0]
    beside = spec_file.resolve().parent
    if (beside / f"{top}.py").is_file() or (beside / top).is_dir():
        return True
    try:
        return importlib.util.find_spec(module) is not None
    except Exception:  # a parent package is missing or broken (any error its import raises)
        return False
