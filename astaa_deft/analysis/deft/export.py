"""Write extracted frames as a self-contained module test suite.

DIR/frames.mcap holds each input message used by any frame (once) and each
expected output; DIR/deft.json (the manifest) names, per frame, which
messages form it, plus everything replay needs: the spec text, the planner
factory and the run's params. `pytest DIR` runs the suite through the
plugin in `astaa_deft.analysis.deft.pytest_plugin`; the original log is not needed.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path

from astaa_deft.io.log.reader import LoggedMessage
from astaa_deft.io.log.writer import LogWriter
from astaa_deft.io.output_place import write_atomic
from astaa_deft.model.json import JsonObject
from astaa_deft.model.sut import Spec
from astaa_deft.engine.spec.replay_section import ReplayModule
from astaa_deft.analysis.deft.extract import ExtractedFrame
from astaa_deft.analysis.deft.planner_section import replay_module_of

MANIFEST = "deft.json"
FRAMES = "frames.mcap"
PYTEST_INI = "pytest.ini"
# The suite's own pytest configuration: pytest takes the first ini file found
# from the suite's directory upwards, so this one shadows the settings of
# whatever project the suite is written into (addopts that need plugins the
# user has not installed, testpaths, markers) and the suite runs the same
# anywhere.
PYTEST_INI_TEXT = """\
# Written by astaa-deft extract: keeps this suite independent of any enclosing project's pytest settings.
[pytest]
addopts =
testpaths = .
"""
VERSION = 1


def export_suite(frames: Sequence[ExtractedFrame], spec: Spec, params: Mapping[str, str], out_dir: Path, *,
                 oracles: Sequence[Mapping[str, object]] = (), entry: ReplayModule | None = None) -> Path:
    """Write the suite of ``entry``'s module (default: the planner); the manifest names any other module.

    ``frames``: every frame the module is stepped on, in order; those not
    ``accepted`` carry ``"check": false`` (stepped for their state, no test).
    A frame a per-trigger module answered with nothing has ``"output": null``.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    cfg = entry if entry is not None else replay_module_of(spec)
    writer = LogWriter(out_dir / FRAMES, spec)
    channel_ids = {name: writer.bus_channel(spec.channel(name)) for name in list(cfg.inputs) + [cfg.output]}
    written: dict[tuple[str, int, bytes], int] = {}
    counts: dict[str, int] = {name: 0 for name in channel_ids}

    def put(name: str, msg: LoggedMessage) -> int:
        key = (name, msg.log_time, msg.data)
        if key not in written:
            writer.message(channel_ids[name], msg.log_time, msg.data, msg.publish_time)
            written[key] = counts[name]
            counts[name] += 1
        return written[key]

    entries = []
    for f in frames:
        entries.append({
            "index": f.index,
            "inputs": {name: put(name, msg) for name, msg in sorted(f.inputs.items())},
            "output": put(cfg.output, f.output) if f.output is not None else None,
            "frame_time_ns": f.frame_time,
            "trigger_time_ns": f.trigger_time,
            "output_time_ns": f.output.log_time if f.output is not None else f.trigger_time,
            "recorded_distance": f.comparison.distance,
            # A frame kept but not reproduced within θ is stepped for the state it builds, not tested: the
            # test of every later frame runs after the frames before it, as the extraction stepped them.
            "check": f.accepted,
        })
    writer.finish()
    manifest = {
        "version": VERSION,
        "spec_name": spec.name,
        "spec_yaml": spec.source_text,
        # Where the spec was: what it names relative to itself (a replay factory module beside it,
        # custom ROS 2 .msg files) is looked for there while that directory exists.
        "spec_dir": str(spec.path.resolve().parent) if spec.path is not None else None,
        "params": dict(params),
        "threshold": cfg.threshold,
        "frames": entries,
        "oracles": list(oracles),
    }
    if cfg.where != "planner":  # a planner suite's manifest stays as it always was
        manifest["module"] = cfg.module
        manifest["output"] = cfg.output
    write_atomic(out_dir / PYTEST_INI, PYTEST_INI_TEXT)
    path = out_dir / MANIFEST
    write_atomic(path, json.dumps(manifest, indent=1, default=_json_default) + "\n")
    return path


def is_checked(frame: Mapping[str, object]) -> bool:
    """Whether a manifest's frame entry is a test (``"check": false``: stepped for its state only; a manifest
    written before frames could be unchecked has no key, and every frame is a test)."""
    return bool(frame.get("check", True))


def oracles_of(manifest: Mapping[str, object]) -> list[JsonObject]:
    """A manifest's oracle entries as written ([]: a suite without oracles, or one written before them)."""
    found = manifest.get("oracles")
    return found if isinstance(found, list) else []


def _json_default(value: object) -> str:
    if isinstance(value, float):
        return repr(value)
    return str(value)
