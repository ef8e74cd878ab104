"""Where the demo's spec and example policies ship inside the package (no tool imports: data paths only).

Used by ``astaa-deft demo``, the tests and the benchmarks alike, so none of
them has to reach into ``commands/`` for a path.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

DEMO_POLICY = "demo_nan_speed_limit.xml"


def demo_spec_path() -> Path:
    return Path(str(resources.files("astaa_deft") / "data" / "specs" / "demo_av.yaml"))


def demo_policy_path(name: str = DEMO_POLICY) -> Path:
    return Path(str(resources.files("astaa_deft") / "data" / "policies" / "examples" / name))


def demo_noise_policies() -> str:
    """The <policy> elements of demo_noise.xml: benign mutations to hide a culprit among."""
    text = demo_policy_path("demo_noise.xml").read_text()
    return text[text.index("</description>") + len("</description>"):text.index("</testcase>")]
