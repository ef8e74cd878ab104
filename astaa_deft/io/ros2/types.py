"""ROS 2 message types for a spec: the standard definitions, custom ``.msg`` files, names and hashes.

A channel with ``encoding: cdr`` names a ROS 2 type (``geometry_msgs/msg/Twist``);
its fields come from the message definitions, so the spec does not restate
them. The definitions are `rosbags`' typestore for ROS 2 Jazzy (offline, no
ROS install needed) plus the custom ``.msg`` files a spec names under
``ros2.messages``. One typestore is shared by the process: the spec loader
registers into it and the CDR codec (``astaa_deft.io.codecs.cdr``) reads it.

Also here, because they follow from a type's definition alone: the RIHS01
type hash (REP-2011, computed by rosbags), the DDS type name and the data key
``<domain>/<topic>/<dds type>/<hash>`` rmw_zenoh publishes on, and the
``ros2msg`` text MCAP stores as a channel schema.

Pure: no Zenoh, no files except the ``.msg`` files a caller passes.
"""

from __future__ import annotations

import re
import threading
from pathlib import Path

from rosbags.typesys import Stores, get_typestore, get_types_from_msg
from rosbags.typesys.base import Nodetype, TypesysError

from astaa_deft.model.errors import AstaaDeftError, InputError
from astaa_deft.io.inputfile import MESSAGE_TYPE, read_input
from astaa_deft.model.sut import FieldType, MessageType

ROS_TYPE_RE = re.compile(r"^[A-Za-z][A-Za-z0-9_]*/msg/[A-Za-z][A-Za-z0-9_]*\Z")
_MSGDEF_SEPARATOR = "=" * 80 + "\n"
TOPIC_RE = re.compile(r"^/?[A-Za-z_~{][A-Za-z0-9_/{}~]*\Z")

# ROS 2 primitive names -> the spec's scalar kinds. byte/char/octet are one
# unsigned byte each on the wire (REP-2011's type descriptions say the same).
PRIMITIVE_KINDS = {
    "bool": "bool", "byte": "uint8", "char": "uint8", "octet": "uint8",
    "int8": "int8", "uint8": "uint8", "int16": "int16", "uint16": "uint16",
    "int32": "int32", "uint32": "uint32", "int64": "int64", "uint64": "uint64",
    "float32": "float32", "float64": "float64", "string": "string", "wstring": "string",
}
# Arrays of these travel as one ``bytes`` value (images, point clouds): a
# list of 100 000 Python ints would cost milliseconds per message.
BYTE_PRIMITIVES = frozenset({"byte", "char", "octet", "uint8"})


class Ros2TypeError(AstaaDeftError, ValueError):
    """A ROS 2 type name or definition the tool cannot use; the message says why."""


class Ros2Types:
    """A typestore: Jazzy's standard messages plus registered custom ones."""

    def __init__(self) -> None:
        self.store = get_typestore(Stores.ROS2_JAZZY)
        self._lock = threading.Lock()
        self._custom: dict[str, str] = {}  # type name -> definition text it was registered from

    # -- what exists ---------------------------------------------------------
    def has(self, type_name: str) -> bool:
        return type_name in self.store.fielddefs

    def names(self) -> list[str]:
        return sorted(name for name in self.store.fielddefs if "/msg/" in name)

    def check_name(self, type_name: str) -> None:
        """Raise Ros2TypeError (with close names) unless ``type_name`` is a known message type."""
        if not ROS_TYPE_RE.match(type_name):
            raise Ros2TypeError(f"'{type_name}' is not a ROS 2 message type name (write package/msg/Name)")
        if not self.has(type_name):
            close = _close_names(type_name, self.names())
            hint = f"; did you mean '{close}'?" if close else ""
            raise Ros2TypeError(f"unknown ROS 2 message type '{type_name}'{hint}")

    # -- custom definitions ------------------------------------------------
    def register_msg(self, type_name: str, text: str) -> None:
        """Add a ``.msg`` definition under ``type_name``; the same text twice is fine, a different one is not."""
        if not ROS_TYPE_RE.match(type_name):
            raise Ros2TypeError(f"'{type_name}' is not a ROS 2 message type name (write package/msg/Name)")
        with self._lock:
            if self._custom.get(type_name) == text:
                return
            try:
                parsed = get_types_from_msg(text, type_name)
            except TypesysError as exc:
                raise Ros2TypeError(f"cannot parse the definition of '{type_name}': {_first_line(exc)}") from None
            for name, (_consts, fields) in parsed.items():
                for field_name, desc in fields:
                    ref = _referenced_name(desc)
                    if ref is not None and ref not in parsed and not self.has(ref):
                        short = ref.rsplit("/", 1)[-1]
                        raise Ros2TypeError(
                            f"line {_line_of(text, short, field_name)}: "
                            f"field '{field_name}' of '{name}' has unknown type '{short}' ({ref}); "
                            "use a primitive (float64, int32, string…) or a known message type")
            try:
                self.store.register(parsed)
            except TypesysError as exc:
                raise Ros2TypeError(str(exc)) from None
            self._custom[type_name] = text

    def register_msg_file(self, type_name: str, path: Path) -> None:
        try:
            text = read_input(path, MESSAGE_TYPE).decode("utf-8")
        except InputError as exc:
            raise Ros2TypeError("; ".join(p.message + (f" ({p.fix})" if p.fix else "") for p in exc.problems)) from None
        except UnicodeDecodeError as exc:
            raise Ros2TypeError(f"cannot read '{path}': {exc}") from None
        self.register_msg(type_name, text)

    # -- derived ---------------------------------------------------------------
    def rihs01(self, type_name: str) -> str:
        """The REP-2011 type hash, ``RIHS01_<64 hex>``."""
        return self.store.hash_rihs01(type_name)

    def msgdef(self, type_name: str) -> str:
        """The ``ros2msg`` schema text (the type, then each dependency after a ``MSG:`` separator)."""
        text, _md5 = self.store.generate_msgdef(type_name, ros_version=2)
        return text

    def definitions(self, type_name: str) -> dict[str, str]:
        """``.msg`` text of ``type_name`` and of every type it uses, by full type name.

        What a ROS 2 client without a ROS install (zenoh-ros2-sdk) needs to be
        given locally; its RIHS01 hashes of these texts equal ``rihs01``.
        """
        first, *rest = self.msgdef(type_name).split(_MSGDEF_SEPARATOR)
        out = {type_name: first}
        for part in rest:
            head, _, body = part.partition("\n")
            package, name = head.removeprefix("MSG: ").split("/")
            out[f"{package}/msg/{name}"] = body
        return out

    def write_definitions(self, type_names: list[str], directory: Path) -> list[Path]:
        """Write ``<package>/msg/<Name>.msg`` files (a ROS 2 share layout) for these types and their fields."""
        written = []
        for type_name in type_names:
            for name, text in self.definitions(type_name).items():
                package, _, short = name.split("/")
                path = Path(directory) / package / "msg" / f"{short}.msg"
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_text(text)
                written.append(path)
        return written

    def spec_types(self, type_name: str) -> dict[str, MessageType]:
        """``type_name`` and every type it contains, as spec message types (same names)."""
        out: dict[str, MessageType] = {}
        pending = [type_name]
        while pending:
            name = pending.pop()
            if name in out:
                continue
            fields: dict[str, FieldType] = {}
            for field_name, desc in self.store.fielddefs[name][1]:
                fields[field_name] = _field_type(desc)
                ref = _referenced_name(desc)
                if ref is not None and ref not in out:
                    pending.append(ref)
            out[name] = MessageType(name, fields)
        return out


def dds_type_name(type_name: str) -> str:
    """``geometry_msgs/msg/Twist`` -> ``geometry_msgs::msg::dds_::Twist_`` (as rmw_zenoh writes keys)."""
    package, kind, name = type_name.split("/")
    return f"{package}::{kind}::dds_::{name}_"


def ros_type_name(dds_name: str) -> str | None:
    """The inverse of ``dds_type_name``; None if ``dds_name`` is not one."""
    parts = dds_name.split("::")
    if len(parts) != 4 or parts[2] != "dds_" or not parts[3].endswith("_"):
        return None
    return f"{parts[0]}/{parts[1]}/{parts[3][:-1]}"


def topic_key(domain_id: int, topic: str, type_name: str, type_hash: str) -> str:
    """The Zenoh key rmw_zenoh publishes a topic's data on."""
    return f"{domain_id}/{topic.strip('/')}/{dds_type_name(type_name)}/{type_hash}"


_SHARED: Ros2Types | None = None
_SHARED_LOCK = threading.Lock()


def shared_types() -> Ros2Types:
    """The process's typestore (built on first use: loading the store takes ~0.2 s)."""
    global _SHARED
    with _SHARED_LOCK:
        if _SHARED is None:
            _SHARED = Ros2Types()
        return _SHARED


# ---------------------------------------------------------------- helpers

def _referenced_name(desc: tuple) -> str | None:
    node, arg = desc
    if node == Nodetype.NAME:
        return arg
    if node in (Nodetype.ARRAY, Nodetype.SEQUENCE):
        return _referenced_name(arg[0])
    return None


def _field_type(desc: tuple) -> FieldType:
    node, arg = desc
    if node == Nodetype.BASE:
        return FieldType(kind=PRIMITIVE_KINDS[arg[0]])
    if node == Nodetype.NAME:
        return FieldType(kind="struct", ref=arg)
    (item_node, item_arg), size = arg
    fixed = node == Nodetype.ARRAY
    if item_node == Nodetype.BASE and item_arg[0] in BYTE_PRIMITIVES:
        return FieldType(kind="bytes")
    return FieldType(kind="array", items=_field_type((item_node, item_arg)),
                     min_length=size if fixed else None, max_length=size if (fixed or size) else None)


def _close_names(word: str, names: list[str]) -> str:
    import difflib

    close = difflib.get_close_matches(word, names, n=1, cutoff=0.75)
    if close:
        return close[0]
    tail = word.rsplit("/", 1)[-1]
    same_tail = [n for n in names if n.rsplit("/", 1)[-1] == tail]
    return same_tail[0] if same_tail else ""


def _line_of(text: str, type_word: str, field_name: str) -> int | str:
    """The 1-based line of a ``.msg`` text declaring ``field_name`` with ``type_word`` ('?' if not found)."""
    pattern = re.compile(rf"^\s*(\S*/)?{re.escape(type_word)}(\[[^\]]*\])?\s+{re.escape(field_name)}\b")
    for number, line in enumerate(text.splitlines(), 1):
        if pattern.match(line):
            return number
    return "?"


def _first_line(exc: Exception) -> str:
    return " ".join(str(exc).split())[:200]
