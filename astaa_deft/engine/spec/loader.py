"""Load a SUT spec (YAML) into a validated, cross-checked ``Spec``.

Each top-level section is read by its own module of this package
(``modules_section``, ``channels_section``, ``types_section``, ``run_section``
…, the ``invariants:`` by the monitor kinds); this module reads the file,
calls them in dependency order and assembles the ``Spec``. All problems found
are reported together, each with file, line, column and a fix: the caller gets
either a fully cross-checked Spec or an InputError.
"""

from __future__ import annotations

from pathlib import Path

from astaa_deft.engine.monitor.invariants import build_invariants
from astaa_deft.engine.spec.channels_section import read_channels_section
from astaa_deft.engine.spec.decictor_section import read_decictor_section
from astaa_deft.engine.spec.liveliness_section import read_liveliness_section
from astaa_deft.engine.spec.modules_section import check_ready_channels, read_modules_section
from astaa_deft.engine.spec.params_section import read_params_section
from astaa_deft.engine.spec.planner import build_planner
from astaa_deft.engine.spec.reader import SpecReader
from astaa_deft.engine.spec.replay_section import build_replay_section
from astaa_deft.engine.spec.ros2_section import read_ros2_section
from astaa_deft.engine.spec.run_section import build_run_section
from astaa_deft.engine.spec.source_section import read_source_section
from astaa_deft.engine.spec.types_section import read_brittle_section, read_types_section
from astaa_deft.engine.spec.zenoh_section import read_zenoh_section
from astaa_deft.io.inputfile import SPEC
from astaa_deft.io.yamlsource import Source
from astaa_deft.model.sut import Spec

TOP_KEYS = ("name", "params", "zenoh", "modules", "channels", "types", "brittle", "invariants", "planner", "run",
            "decictor", "ros2", "replay", "liveliness", "source")
REQUIRED_TOP = ("name", "modules", "channels")


def load_spec(path: Path | str) -> Spec:
    """The spec in the file at ``path``. Raises InputError listing every problem (a missing, unreadable,
    oversized or special file included)."""
    path = Path(path)
    src = Source.from_file(path, SPEC)
    return _build(SpecReader(src, path.parent), path)


def load_spec_text(text: str, name: str = "<spec>", base_dir: Path | None = None) -> Spec:
    """The spec in ``text``, named ``name`` in messages; relative paths start at ``base_dir`` (default: the
    working directory) and the files they name are not required to exist. Raises InputError."""
    fake_path = (base_dir or Path.cwd()) / name
    return _build(SpecReader(Source(text, name), fake_path.parent, from_file=False), fake_path)


def _build(reader: SpecReader, path: Path) -> Spec:
    src = reader.src
    root = src.parse()
    if not root.is_map:
        src.at(root, "the spec must be a mapping of sections", "start with 'name:', 'modules:', 'channels:'")
        src.raise_if_problems()
    reader.keys(root, TOP_KEYS, REQUIRED_TOP, "the spec")
    v = root.value
    name = reader.name_of(v["name"], "spec name") if "name" in v else "spec"
    params = read_params_section(reader, v.get("params"))
    zenoh = read_zenoh_section(reader, v.get("zenoh"))
    types = read_types_section(reader, v.get("types"))
    ros2 = read_ros2_section(src, v.get("ros2"), reader.base_dir, reader.from_file)
    modules_section = read_modules_section(reader, v.get("modules"), params.defaults)
    modules = modules_section.modules
    channels = read_channels_section(reader, v.get("channels"), modules, types, ros2=ros2)
    check_ready_channels(reader, modules_section.ready_channels, {c.name for c in channels})
    brittle = read_brittle_section(reader, v.get("brittle"), types)
    module_names = [m.name for m in modules]
    invariants = build_invariants(src, v.get("invariants"), types, channels, modules=module_names)
    planner = build_planner(src, v.get("planner"), types, channels=channels, modules=list(modules))
    replay = build_replay_section(src, v.get("replay"), channels, list(modules), types=types)
    run = build_run_section(src, v.get("run"), types, channels, modules=module_names)
    decictor = read_decictor_section(src, v.get("decictor"), tuple(c.name for c in channels), reader.base_dir)
    liveliness = read_liveliness_section(reader, v.get("liveliness"), modules)
    source = read_source_section(reader, v.get("source"))
    src.raise_if_problems()
    return Spec(
        name=name,
        path=path if reader.from_file else None,
        zenoh=zenoh,
        modules=modules,
        channels=tuple(channels),
        types=types,
        brittle=tuple(brittle),
        params=params.defaults,
        param_choices=params.choices,
        invariants=tuple(invariants),
        planner=planner,
        replay=replay,
        run=run,
        decictor=decictor,
        source_text=src.text,
        ros2=ros2,
        liveliness=liveliness,
        source=source,
    )
