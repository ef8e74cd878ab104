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


def demo_scenario_names() -> list[str]:
    """The bundled scenarios' names (``demo --scenario NAME``), without loading any."""
    return sorted(p.stem for p in (Path(__file__).resolve().parent / "scenarios").glob("*.yaml"))


# What `astaa-deft examples DIR` copies: the folders the README's examples name, relative to the package's data.
EXAMPLE_FOLDERS = ("specs", "policies", "dictionaries")


def example_files() -> list[tuple[Path, Path]]:
    """Every bundled spec, test case, schema and dictionary: (its file in the package, its path under a copy)."""
    data = Path(str(resources.files("astaa_deft") / "data"))
    return [(path, path.relative_to(data)) for folder in EXAMPLE_FOLDERS
            for path in sorted((data / folder).rglob("*")) if path.is_file()]
