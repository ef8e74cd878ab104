"""`astaa-deft generate --spec SUT.yaml --count N --seed S -o DIR`: write N test cases.

The work is :func:`astaa_deft.engine.intercept.generate.generate_to_directory`; this prints what it wrote.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from astaa_deft.engine.intercept.generate import generate_to_directory
from astaa_deft.engine.spec.loader import load_spec


def run(spec_path: Path, count: int, seed: int, out_dir: Path, duration: float = 30.0,
        include_brittle: bool = False, dictionaries: Sequence[Path] = ()) -> int:
    report = generate_to_directory(load_spec(spec_path), count, seed, out_dir, duration, include_brittle, dictionaries)
    shapes = report.shapes
    print(f"wrote {report.count} test cases to {out_dir} (seed {seed}): {shapes['single']} one field of one "
          f"message, {shapes['multi_field']} several fields of one message, {shapes['repeated']} repeated, "
          f"{shapes['sustained']} sustained, {shapes['stamp']} stamp or sequence faults")
    return 0
