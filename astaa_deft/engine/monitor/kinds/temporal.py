"""``temporal``: a signal temporal logic formula over signals from several channels.

    - name: stop_at_red
      kind: temporal
      period: 0.1                       # sampling period in seconds (default 0.1)
      signals:                          # name: {channel, field} or {channel, expr}
        red:    {channel: traffic_lights, expr: "len(lights) > 0 and lights[0].state == 'red'"}
        stop_x: {channel: traffic_lights, expr: "lights[0].stop_line_x"}
        ego_x:  {channel: localization, field: x}
        speed:  {channel: localization, field: speed}
      formula: "always((red and stop_x - ego_x >= 0 and stop_x - ego_x <= 5) implies eventually[0:2](speed < 0.5))"

Signals are sampled as ``monitor/sampling.py`` says (zero-order hold on a
fixed grid); a boolean signal is +1 when true and -1 when false, so it is a
proposition by itself (``red and near``). The formula must hold at every
sample; rtamt evaluates it (``monitor/stl.py``). A sample whose verdict
needs the future (``eventually[0:2]``) is judged 2 s of samples later; the
samples of the run's last 2 s are never judged (the run ended before their
future did).
"""

from __future__ import annotations

import re
from collections import deque
from dataclasses import dataclass
from fractions import Fraction
from typing import Any, ClassVar
from collections.abc import Callable

from astaa_deft.io.yamlsource import Node
from astaa_deft.engine.monitor.base import NO_VIOLATIONS, EpisodeGate, Invariant, Monitor, MonitorContext
from astaa_deft.engine.monitor.expression import RUNTIME_ERRORS, follow
from astaa_deft.engine.monitor.sampling import GridSampler
from astaa_deft.engine.monitor.pairing import Join
from astaa_deft.engine.monitor.spec_reader import InvariantReader
from astaa_deft.engine.monitor.stl import SIGNAL_NAME, StlError, StlFormula, check_formula
from astaa_deft.engine.monitor.violation import Violation
from astaa_deft.engine.monitor.kinds import Kind

KEYS = ("signals", "formula", "period")
REQUIRED = ("signals", "formula")
DEFAULT_PERIOD = Fraction(1, 10)
MIN_PERIOD, MAX_PERIOD = 0.001, 60.0


@dataclass(frozen=True, kw_only=True)
class Signal:
    name: str
    channel: str
    source: str  # the field path or expression, as written
    is_bool: bool
    read: Callable[[dict], object]  # message -> raw value; raises one of RUNTIME_ERRORS when it is not there


@dataclass(frozen=True, kw_only=True)
class TemporalInvariant(Invariant):
    kind: ClassVar[str] = "temporal"

    signals: tuple[Signal, ...]
    formula: StlFormula


def parse(reader: InvariantReader, node: Node, common: dict) -> TemporalInvariant | None:
    v = node.value
    period = _period(reader, v.get("period"))
    signals = _signals(reader, v.get("signals"))
    formula_node = v.get("formula")
    text = reader.text(formula_node, "'formula'", '"always(speed < 30)"')
    if period is None or signals is None or text is None or formula_node is None:
        return None
    try:
        formula = check_formula(text, [s.name for s in signals], period)
    except StlError as exc:
        reader.problem_inside(formula_node, exc.position, f"'formula': {exc.message}", exc.fix)
        return None
    unused = [s.name for s in signals if s.name not in _words(text)]
    if unused:
        reader.problem(v["signals"], f"signal{'s' if len(unused) > 1 else ''} {', '.join(unused)} "
                                     f"not used in the formula", "remove them or use them")
        return None
    return TemporalInvariant(signals=tuple(signals), formula=formula, **common)


def _period(reader: InvariantReader, node: Node | None) -> Fraction | None:
    """The sampling period in seconds, exact to the microsecond (rtamt compares bounds with it exactly)."""
    if node is None:
        return DEFAULT_PERIOD
    period = reader.number(node, "'period'", positive=True)
    if period is None:
        return None
    if not MIN_PERIOD <= period <= MAX_PERIOD:
        reader.problem(node, f"'period' must lie between {MIN_PERIOD:g} and {MAX_PERIOD:g} s", "e.g. period: 0.1")
        return None
    return Fraction(round(period * 1e6), 1_000_000)


def _words(text: str) -> set[str]:
    return set(re.findall(r"[A-Za-z_][A-Za-z0-9_]*", text))


def _signals(reader: InvariantReader, node: Node | None) -> list[Signal] | None:
    if node is None:
        return None
    if not node.is_map or not node.value:
        reader.problem(node, "'signals' must map signal names to {channel, field} or {channel, expr}",
                       'e.g. signals: {speed: {channel: localization, field: speed}}')
        return None
    out: list[Signal] = []
    ok = True
    for name, snode in node.items():
        if not SIGNAL_NAME.match(name):
            reader.src.at_key(node, name, f"signal name '{name}' must start with a lowercase letter and hold "
                                          "only lowercase letters, digits and '_'", "rename it, e.g. ego_speed")
            ok = False
            continue
        signal = _signal(reader, name, snode)
        ok = ok and signal is not None
        if signal is not None:
            out.append(signal)
    return out if ok else None


def _signal(reader: InvariantReader, name: str, node: Node) -> Signal | None:
    what = f"signal '{name}'"
    if not reader.keys(node, ("channel", "field", "expr"), ("channel",), what):
        return None
    v = node.value
    if ("field" in v) == ("expr" in v):
        reader.problem(node, f"{what} needs exactly one of 'field' or 'expr'",
                       "e.g. {channel: localization, field: speed}")
        return None
    channel = reader.channel(v["channel"])
    if channel is None:
        return None
    if "field" in v:
        found = reader.field(v["field"], channel.type, f"the field of {what}", kinds=("number", "bool"))
        if found is None:
            return None
        path, declared = found
        if not all(type(s) in (str, int) for s in path.segments):
            reader.problem(v["field"], f"{what} reads one value; [*] is not allowed", "use an index, e.g. [0]")
            return None
        segments = path.segments
        return Signal(name=name, channel=channel.name, source=str(path), is_bool=declared.kind == "bool",
                      read=lambda message: follow(message, segments))
    compiled = reader.expression(v["expr"], channel.type, f"the expr of {what}", want=("number", "bool"))
    if compiled is None:
        return None
    return Signal(name=name, channel=channel.name, source=compiled.text, is_bool=compiled.type.kind == "bool",
                  read=compiled.evaluate)


def _signal_value(raw: Any, is_bool: bool) -> float | None:
    """The sampled value of a raw reading, or None to keep holding the previous one."""
    if is_bool:
        return 1.0 if raw is True else -1.0 if raw is False else None
    if type(raw) is float:
        return raw if raw - raw == 0.0 else None  # finite (NaN and ±inf fail x - x == 0)
    if type(raw) is int:
        return float(raw)
    return None


class TemporalMonitor(Monitor):
    def __init__(self, invariant: TemporalInvariant, context: MonitorContext):
        super().__init__(invariant, context)
        self.inv = invariant
        formula = invariant.formula
        self._stl = formula.online_monitor()
        self._sampler = GridSampler(context.start_ns, round(float(formula.period) * 1e9),
                                    [s.name for s in invariant.signals])
        self._by_channel: dict[str, list[Signal]] = {}
        for signal in invariant.signals:
            self._by_channel.setdefault(signal.channel, []).append(signal)
        self._bools = {s.name for s in invariant.signals if s.is_bool}
        # samples awaiting their verdict: (grid time, values, last message (channel, seq) before it)
        self._pending: deque[tuple[int, list[tuple[str, float]], tuple[str, int] | None]] = deque(
            maxlen=formula.horizon_samples + 1)
        self._last_message: tuple[str, int] | None = None
        self._gate = EpisodeGate()
        # channels declaring pair_by (or time): a tick's later message joins its first, not the sample between
        self._join = Join(context.spec, self._by_channel, own_time=False)

    def channels(self) -> set[str]:
        return set(self._by_channel)

    def on_message(self, channel: str, time_ns: int, value: dict | None, seq: int) -> list[Violation]:
        at = self._join.at(channel, time_ns, value) if value is not None else None
        # The second message of a pair completes its tick: no grid point is read between the two.
        out = self._read_grid(time_ns, inclusive=False) if at is None or at >= time_ns else NO_VIOLATIONS
        if value is not None:
            for signal in self._by_channel.get(channel, ()):
                try:
                    sampled = _signal_value(signal.read(value), signal.is_bool)
                except RUNTIME_ERRORS:
                    continue
                if sampled is not None:
                    self._sampler.hold(signal.name, sampled)
        self._last_message = (channel, seq)
        return out

    def finish(self, time_ns: int) -> list[Violation]:
        return self._read_grid(time_ns, inclusive=True)

    def _read_grid(self, time_ns: int, inclusive: bool) -> list[Violation]:
        out: list[Violation] = NO_VIOLATIONS  # shared and empty; replaced by a new list on a violation
        sampler = self._sampler
        for grid_ns in sampler.due(time_ns, inclusive):
            if not sampler.complete:
                continue
            values = sampler.sample()
            self._pending.append((grid_ns, values, self._last_message))
            robustness = self._stl.update(values)
            if robustness is None:
                continue
            found = self._judge(robustness)
            if found is not None:
                out = [*out, found]
        return out

    def _judge(self, robustness: float) -> Violation | None:
        """Judge the oldest pending sample: the one this robustness is about."""
        grid_ns, values, source = self._pending[0]
        self.evaluations += 1
        if not robustness < 0:  # NaN (e.g. inf - inf) cannot be judged: not a violation
            self._gate.held()
            return None
        self.violating += 1
        if not self._gate.broke():
            return None
        shown = {name: (value > 0 if name in self._bools else value) for name, value in values}
        text = ", ".join(f"{k}={str(v).lower() if isinstance(v, bool) else f'{v:g}'}" for k, v in shown.items())
        delay = self.inv.formula.horizon_samples * float(self.inv.formula.period)
        decided = f" (decided {delay:g} s later)" if delay else ""
        detail = f"formula false at this sample, robustness {robustness:.4g}{decided}; {text}"
        channel, seq = source if source else (None, None)
        return self.violation(grid_ns, detail, channel=channel, seq=seq, infer_module=False,
                              message={"signals": shown, "robustness": robustness})


def monitor(invariant: TemporalInvariant, context: MonitorContext) -> TemporalMonitor:
    return TemporalMonitor(invariant, context)


Kind.register(TemporalInvariant, KEYS, REQUIRED, parse=parse, monitor=monitor)
