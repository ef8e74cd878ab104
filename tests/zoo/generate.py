"""Write a zoo member into a directory as a small runnable stack: its spec, its processes, its replay factory.

    stack = write_member(member, directory)      # directory/spec.yaml, member.json, zoo_module.py, zoo_producer.py

The spec declares two modules — ``module`` (the member: ``zoo_module.py``,
a real subprocess on the bus) and ``producer`` (channels a, b, c) — a run
that ends when the producer exits (after the member's bus time), and a
``replay:`` entry for ``module``: inputs a, b, c, trigger a, output out,
factory ``zoo_module:Step`` (beside the spec) with the member's args,
``frames`` per the member, ``ignore: [debug]`` (the outputs' evaluation
record, ``debug.inputs``, is no provenance unless a spec names it).
``replay_extra`` adds keys to that entry (e.g. a provenance declaration
once the spec knows one).
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from zoo.member import INPUTS, OUTPUT, Member

RUNTIME = Path(__file__).resolve().parent / "runtime"
MODULE = "module"  # the module under test, as the spec names it
FACTORY = "zoo_module:Step"


@dataclass(frozen=True)
class Stack:
    """A generated stack on disk."""

    member: Member
    directory: Path

    @property
    def spec_path(self) -> Path:
        return self.directory / "spec.yaml"

    @property
    def module(self) -> str:
        return MODULE

    def factory_args(self) -> dict[str, str]:
        return self.member.factory_args()


def keys(member: Member) -> dict[str, str]:
    return {name: f"zoo/{member.name}/{name}" for name in (*INPUTS, OUTPUT)}


def spec_text(member: Member, replay_extra: Mapping[str, Any] | None = None) -> str:
    """The member's spec (YAML)."""
    key = keys(member)
    entry: dict[str, Any] = {
        "module": MODULE, "inputs": list(INPUTS), "trigger": INPUTS[0], "outputs": [OUTPUT], "factory": FACTORY,
        "args": member.factory_args(), "frames": member.frames_mode, "hang_after": member.hang_after,
        "threshold": 0.0, "ignore": ["debug"],
        **({"exceptions": "crash"} if member.defect != "none" else {}), **(replay_extra or {})}
    lines = [
        f"# Zoo member '{member.name}' (tests/zoo): {json.dumps(member.axes())}",
        f"# cost {member.cost_ms[0]:g}-{member.cost_ms[1]:g} ms a step; {member.note}".rstrip("; "),
        f"name: zoo_{member.name}",
        "run:",
        f"  time_limit: {member.seconds + 30:g}",
        "  end_when:",
        "    - {module: producer, reason: inputs over, exit_codes: [{code: 0, outcome: pass}]}",
        "modules:",
        f"  - name: {MODULE}",
        '    command: ["{python}", "zoo_module.py", "member.json"]',
        "    cwd: .",
        '    ready: {log: "zoo module ready", timeout: 30}',
        "  - name: producer",
        '    command: ["{python}", "zoo_producer.py", "member.json"]',
        "    cwd: .",
        "channels:",
        *(f"  - {{name: {name}, key: {key[name]}, producer: producer, consumers: [{MODULE}], type: In}}"
          for name in INPUTS),
        f"  - {{name: {OUTPUT}, key: {key[OUTPUT]}, producer: {MODULE}, consumers: [], type: Out}}",
        "types:",
        "  Header: {seq: uint64, stamp: time}",
        "  In: {header: Header, v: {array: float64}}",
        "  Used: {a: int64, b: int64, c: int64}",
        "  Debug: {inputs: Used}",
        "  Out: {header: Header, x: {array: float64}, count: int64, absent: int64, part: int64, debug: Debug}",
        "brittle: [Header.stamp, Header.seq]",
        "replay:",
        "  modules:",
        f"    - {json.dumps(entry)}",
    ]
    return "\n".join(lines) + "\n"


def write_member(member: Member, directory: Path, *, replay_extra: Mapping[str, Any] | None = None) -> Stack:
    """The member's stack in ``directory`` (created; files there of the same names are replaced)."""
    directory.mkdir(parents=True, exist_ok=True)
    for name in ("zoo_module.py", "zoo_producer.py"):
        shutil.copyfile(RUNTIME / name, directory / name)
    (directory / "member.json").write_text(json.dumps(
        {"member": member.describe(), "args": member.factory_args(), "keys": keys(member)}, indent=1) + "\n")
    (directory / "spec.yaml").write_text(spec_text(member, replay_extra))
    return Stack(member, directory)
