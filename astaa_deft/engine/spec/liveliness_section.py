"""The spec's ``liveliness:`` section: the Zenoh liveliness tokens modules hold, wired like channels.

    liveliness:
      - {key: ompl_stack/alive/planning, producer: planning, consumers: [simulator]}
      - {key: stack/alive/control, producer: control}     # consumers left out: every other module sees it

A token is no message (nothing to record or judge), but the star carries it
from its holder to the modules wired to see it (``topology.token_destinations``):
the ``consumers`` listed, or every other module. A declared token is not
reported as an undeclared key.
"""

from __future__ import annotations

from astaa_deft.engine.spec.channels_section import KEY_FIX, concrete_key_problem
from astaa_deft.engine.spec.reader import SpecReader
from astaa_deft.io.yamlsource import Node
from astaa_deft.model.sut import LivelinessToken, Module

TOKEN_KEYS = ("key", "producer", "consumers")


def read_liveliness_section(reader: SpecReader, node: Node | None, modules: tuple[Module, ...]
                            ) -> tuple[LivelinessToken, ...]:
    """The declared tokens (none when the section is absent); problems reported on the reader's source."""
    if node is None:
        return ()
    names = [m.name for m in modules]
    out = []
    for item in reader.list_of_maps(node, "liveliness", required=False):
        v = item.value
        if not reader.keys(item, TOKEN_KEYS, ("key", "producer"), "a liveliness token") or not \
                ("key" in v and "producer" in v):  # a missing one is reported by keys()
            continue
        key = v["key"].value if reader.expect(v["key"], (str,), "'key'", "a Zenoh key") else None
        problem = concrete_key_problem(key) if key is not None else None
        if problem is not None:
            reader.src.at(v["key"], f"liveliness key {problem}", KEY_FIX)
        if key is None or problem is not None:
            key = ""
        producer = v["producer"].value if reader.expect(v["producer"], (str,), "'producer'", "a module name") else ""
        if producer:
            reader.module_ref(v["producer"], producer, names)
        consumers: tuple[str, ...] | None = None
        if "consumers" in v:
            cnode = v["consumers"]
            if not cnode.is_list:
                reader.src.at(cnode, "'consumers' must be a list of module names", "e.g. [simulator]")
            else:
                for c in cnode.value:
                    if reader.expect(c, (str,), "a consumer", "a module name"):
                        reader.module_ref(c, c.value, names)
                consumers = tuple(c.value for c in cnode.value if isinstance(c.value, str))
        out.append(LivelinessToken(key, producer, consumers))
    return tuple(out)
