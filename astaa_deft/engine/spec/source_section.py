"""The spec's ``source:`` section: where the stack's own source checkout is.

    source: ../mystack          # a folder (relative to the spec): the stack's git checkout

``astaa-deft verify`` labels its results with ``git describe`` of that
folder, and ``verify --bisect`` checks revisions out there. Optional; pure
parsing (the folder is not required to exist when the spec is read).
"""

from __future__ import annotations

from pathlib import Path

from astaa_deft.engine.spec.reader import SpecReader
from astaa_deft.io.yamlsource import Node


def read_source_section(reader: SpecReader, node: Node | None) -> Path | None:
    """The ``source:`` folder, resolved against the spec's folder (None when absent or after a problem)."""
    if node is None:
        return None
    if node.is_map or node.is_list or not isinstance(node.value, str) or not node.value.strip():
        reader.src.at(node, "'source' must be a folder path", "write e.g. 'source: ../mystack' (the stack's git "
                                                               "checkout, relative to the spec)")
        return None
    path = Path(node.value.strip()).expanduser()
    return path if path.is_absolute() else reader.base_dir / path
