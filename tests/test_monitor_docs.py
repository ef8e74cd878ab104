"""The complete example in docs/monitors.md is a valid invariants section."""

from __future__ import annotations

import re
from pathlib import Path

from astaa_deft.engine.monitor import with_typed_invariants
from astaa_deft.engine.spec.loader import load_spec_text

DOCS = Path(__file__).parent.parent / "docs" / "monitors.md"

SPEC = (Path(__file__).parent / "data" / "driving_stack.yaml").read_text()  # shared with the monitor tests


def test_the_documented_example_loads():
    text = DOCS.read_text()
    example = re.search(r"## A complete example\n\n```yaml\n(invariants:\n.*?)```", text, re.DOTALL).group(1)
    spec = with_typed_invariants(load_spec_text(SPEC + example, name="docs/monitors.md"))
    assert [i.kind for i in spec.invariants].count("temporal") == 2
    assert len(spec.invariants) == 15
