"""`astaa-deft spec check FILE`."""

from __future__ import annotations

from pathlib import Path

from ..spec.loader import load_spec


def run(path: Path) -> int:
    spec = load_spec(path)
    print(f"{path}: ok — spec '{spec.name}': {len(spec.modules)} modules, {len(spec.channels)} channels, "
          f"{len(spec.types)} types")
    return 0
