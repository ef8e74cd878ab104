"""Typed, validated objects a SUT spec loads into (see docs/spec.md).

Pure data: no I/O, no Zenoh. The loader in ``astaa_deft.engine.spec.loader`` builds
these and guarantees every cross reference in them resolves.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol
from collections.abc import Mapping

from astaa_deft.model.decictor import DecictorSection
from astaa_deft.model.replay_module import ReplayModule
from astaa_deft.model.run_section import RunSection

FLOAT_KINDS = ("float32", "float64")
INT_KINDS = ("int8", "int16", "int32", "int64", "uint8", "uint16", "uint32", "uint64")
# time: seconds as a float (a header stamp); bytes: raw bytes (base64 in JSON).
SCALAR_KINDS = FLOAT_KINDS + INT_KINDS + ("bool", "string", "time", "bytes")

INT_RANGES: dict[str, tuple[int, int]] = {
    kind: ((-(2 ** (bits - 1)), 2 ** (bits - 1) - 1) if kind[0] == "i" else (0, 2**bits - 1))
    for kind, bits in (
        ("int8", 8), ("int16", 16), ("int32", 32), ("int64", 64),
        ("uint8", 8), ("uint16", 16), ("uint32", 32), ("uint64", 64),
    )
}


@dataclass(frozen=True, kw_only=True)
class FieldType:
    """The declared type of one field.

    ``kind`` is a scalar kind, ``"enum"``, ``"struct"`` (``ref`` names the
    message type) or ``"array"`` (``items`` is the element type).
    """

    kind: str
    ref: str | None = None
    values: tuple[object, ...] = ()  # an enum's declared values, as the spec writes them (YAML scalars)
    items: FieldType | None = None
    min_length: int | None = None
    max_length: int | None = None
    minimum: float | None = None
    maximum: float | None = None

    @property
    def is_leaf(self) -> bool:
        return self.kind not in ("struct", "array")

    def describe(self) -> str:
        if self.kind == "struct":
            return str(self.ref)
        if self.kind == "array":
            assert self.items is not None
            return f"{self.items.describe()}[]"
        if self.kind == "enum":
            return "enum(" + ", ".join(map(str, self.values)) + ")"
        return self.kind


class DeclaredInvariant(Protocol):
    """What every invariant kind declares (``engine.monitor.base.Invariant``; a monitor narrows to its kind)."""

    @property
    def name(self) -> str: ...

    @property
    def kind(self) -> str: ...

    @property
    def severity(self) -> str: ...


@dataclass(frozen=True)
class MessageType:
    name: str
    fields: Mapping[str, FieldType]


@dataclass(frozen=True)
class ZenohSection:
    # Endpoints the tool listens on; port 0 means "pick a free port at start".
    endpoints: tuple[str, ...] = ("tcp/127.0.0.1:0",)
    # Where an already running SUT can be reached (`proxy --no-launch`); empty: nowhere.
    connect: tuple[str, ...] = ()
    config_file: Path | None = None


@dataclass(frozen=True)
class Readiness:
    channel: str | None = None  # ready once this channel carried a message
    log: str | None = None  # or once the module printed a line matching this regex
    delay: float | None = None  # or simply after this many seconds
    timeout: float = 20.0


@dataclass(frozen=True, kw_only=True)
class Module:
    name: str
    command: tuple[str, ...]
    env: Mapping[str, str] = field(default_factory=dict)
    cwd: Path | None = None
    ready: Readiness = Readiness(delay=0.0)
    # What an abnormal exit of this module mid-run does: "end_run" (default: the run stops at once with
    # its verdict) or "keep_running" (the others go on until the run's own end, e.g. to see what follows).
    on_crash: str = "end_run"
    # The plant: the world or vehicle model the software under test drives (a simulator), not a module under
    # test. A campaign never blames it: it applies what it is sent, so its departure shows the value it got.
    plant: bool = False


@dataclass(frozen=True, kw_only=True)
class Channel:
    name: str
    key: str
    producer: str
    consumers: tuple[str, ...]
    type: str
    encoding: str = "json"  # a codec name: json, cbor, or cdr:<ROS 2 type> for `encoding: cdr`
    topic: str | None = None  # the ROS 2 topic of a CDR channel, when the spec names one
    time: str | None = None  # the field holding the message's own time (seconds), e.g. a simulator's clock
    pair_by: str | None = None  # the field whose equal values mark messages of several channels as one tick


@dataclass(frozen=True)
class LivelinessToken:
    """A Zenoh liveliness token a module holds (the spec's ``liveliness:`` section), wired like a channel."""

    key: str
    producer: str  # the module holding it
    consumers: tuple[str, ...] | None = None  # the modules that see it; None: every other module


@dataclass(frozen=True)
class Ros2Section:
    """The spec's ``ros2:`` section (see astaa_deft.engine.spec.ros2_section)."""

    domain_id: int = 0
    messages: Mapping[str, Path] = field(default_factory=dict)  # custom type name -> .msg file


@dataclass(frozen=True, kw_only=True)
class Spec:
    name: str
    path: Path | None
    zenoh: ZenohSection
    modules: tuple[Module, ...]
    channels: tuple[Channel, ...]
    types: Mapping[str, MessageType]
    brittle: tuple[str, ...] = ()
    params: Mapping[str, str] = field(default_factory=dict)  # every param's default value
    param_choices: Mapping[str, tuple[str, ...]] = field(default_factory=dict)  # declared choices (some params)
    # Typed by the spec loader: invariants are astaa_deft.engine.monitor's Invariant objects (each kind's own
    # class; the spec layer sits below monitor, so it names them by what every kind has), the planner section
    # its record.
    invariants: tuple[DeclaredInvariant, ...] = ()
    planner: ReplayModule | None = None  # the 'planner:' section (frames per output, trajectories)
    replay: tuple[ReplayModule, ...] = ()  # the 'replay:' section's modules that can run alone
    run: RunSection | None = None  # how a run ends (None: no 'run:' section)
    decictor: DecictorSection | None = None  # the 'decictor:' section (None: the spec has none)
    source_text: str = ""
    ros2: Ros2Section = Ros2Section()
    liveliness: tuple[LivelinessToken, ...] = ()  # the tokens modules hold ('liveliness:')
    source: Path | None = None  # the 'source:' folder: the stack's git checkout (verify's revision, bisect)

    def module(self, name: str) -> Module:
        return next(m for m in self.modules if m.name == name)

    def is_plant(self, name: str | None) -> bool:
        """Whether ``name`` is a module the spec marks ``plant: true`` (the world, not a module under test)."""
        return any(m.plant for m in self.modules if m.name == name)

    def channel(self, name: str) -> Channel:
        return next(c for c in self.channels if c.name == name)

    def channel_for_key(self, key: str) -> Channel | None:
        return next((c for c in self.channels if c.key == key), None)

    def message_type(self, channel: str) -> MessageType:
        return self.types[self.channel(channel).type]
