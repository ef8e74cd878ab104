"""The spec's ``params:`` section: each param's default and, where declared, its choices.

``name: value``, or ``name: {default: value, choices: [value, …]}`` (default:
the first choice). Problems are reported on the reader's source.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

from astaa_deft.engine.spec.reader import FIELD_NAME_RE, SpecReader, scalar_text
from astaa_deft.io.yamlsource import Node

BUILTIN_PLACEHOLDERS = ("python", "zenoh_config", "module", "run_dir", "spec_dir")
MAX_CHOICES = 1000  # a param's choices: a campaign's grid runs every one (engine/spec/params.py: MAX_GRID)


@dataclass(frozen=True)
class ParamsSection:
    """Each declared param's default (as text), and the choices of those that declare some."""

    defaults: dict[str, str] = field(default_factory=dict)
    choices: dict[str, tuple[str, ...]] = field(default_factory=dict)


def read_params_section(reader: SpecReader, node: Node | None) -> ParamsSection:
    """The ``params:`` section (empty when absent); a param with a problem is still declared, as ""."""
    if node is None:
        return ParamsSection()
    if not node.is_map:
        reader.src.at(node, "'params' must be a mapping", "write 'params:' then 'key: value' lines")
        return ParamsSection()
    out: dict[str, str] = {}
    choices: dict[str, tuple[str, ...]] = {}
    for key, value in node.items():
        if not FIELD_NAME_RE.match(key):
            reader.src.at_key(node, key, f"param name '{key}' is not an identifier", "use letters, digits and '_'")
        if key in BUILTIN_PLACEHOLDERS:
            reader.src.at_key(node, key, f"param '{key}' shadows a built-in placeholder", "rename it")
        out[key] = ""  # declared, even if badly: its placeholders are not unknown as well
        if value.is_map:
            declared = _param_with_choices(reader, key, value)
            if declared is not None:
                out[key], choices[key] = declared
            continue
        if value.is_list or value.value is None:
            reader.src.at(value, f"param '{key}' must be a scalar or {{default: …, choices: […]}}",
                          "give a string or number, or e.g. {default: oracle, choices: [oracle, cv]}")
            continue
        out[key] = _param_text(value)
    return ParamsSection(out, choices)


def _param_with_choices(reader: SpecReader, key: str, node: Node) -> tuple[str, tuple[str, ...]] | None:
    """``{default: value, choices: [value, …]}``: (the default, the choices); None after a problem."""
    example = f"{key}: {{default: oracle, choices: [oracle, cv]}}"
    if not reader.keys(node, ("default", "choices"), ("choices",), f"param '{key}'") or "choices" not in node.value:
        return None
    listed = node.value["choices"]
    if listed.is_list and len(listed.value) > MAX_CHOICES:
        reader.src.at(listed, f"param '{key}' lists {len(listed.value):,} choices (at most {MAX_CHOICES:,})",
                      "list fewer values: a campaign runs every choice (docs/spec.md, params)")
        return None
    if not listed.is_list or not listed.value or any(c.is_map or c.is_list or c.value is None
                                                     for c in listed.value):
        reader.src.at(listed, f"param '{key}': 'choices' must be a non-empty list of values", f"e.g. {example}")
        return None
    choices = tuple(_param_text(c) for c in listed.value)
    repeated = sorted(c for c, n in Counter(choices).items() if n > 1)  # linear: 100,000 choices in no time
    if repeated:
        reader.src.at(listed, f"param '{key}': choice '{repeated[0]}' is listed twice", "list each value once")
        return None
    default_node = node.value.get("default")
    if default_node is None:
        return choices[0], choices
    if default_node.is_map or default_node.is_list or default_node.value is None:
        reader.src.at(default_node, f"param '{key}': 'default' must be a value", f"e.g. {example}")
        return None
    default = _param_text(default_node)
    if default not in choices:
        reader.src.at(default_node, f"param '{key}': default '{default}' is not one of its choices "
                      f"({', '.join(choices)})", "add it to 'choices' or pick one of them")
        return None
    return default, choices


def _param_text(node: Node) -> str:
    return node.value if isinstance(node.value, str) else scalar_text(node.value)
