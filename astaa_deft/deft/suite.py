"""Load an exported module test suite and replay it (used by the pytest plugin)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..codecs import get_codec
from ..log.reader import read_log
from ..spec.model import Spec
from ..spec_loader import load_spec_text
from .export import FRAMES, MANIFEST
from .planner_section import planner_of
from .replay import make_planner, trajectory_points
from .validator import Comparison, Point, compare


@dataclass
class FrameResult:
    index: int
    comparison: Comparison
    replayed: list[Point]
    expected: list[Point]
    error: str | None = None
    message: Any = None  # the replayed output message


class Suite:
    def __init__(self, directory: Path):
        self.directory = directory
        self.manifest = json.loads((directory / MANIFEST).read_text())
        self.spec: Spec = load_spec_text(self.manifest["spec_yaml"], name=f"{self.manifest['spec_name']} (embedded)",
                                         base_dir=directory)
        # The original spec's folder, while it exists: a replay factory beside it (not installed) is found there.
        spec_dir = self.manifest.get("spec_dir")
        self.spec_dir = Path(spec_dir) if spec_dir and Path(spec_dir).is_dir() else None
        self.threshold = float(self.manifest["threshold"])
        self._results: list[FrameResult] | None = None
        self._by_channel: dict[str, list[Any]] | None = None

    @property
    def frames(self) -> list[dict]:
        return self.manifest["frames"]

    def results(self) -> list[FrameResult]:
        """Replay every frame once, in order (the planner keeps state across frames)."""
        if self._results is not None:
            return self._results
        cfg = planner_of(self.spec)
        by_channel = self._messages()
        planner = make_planner(self.spec, self.manifest["params"], spec_dir=self.spec_dir)
        results = []
        try:
            for entry in self.frames:
                frame = {name: by_channel[name][i] for name, i in entry["inputs"].items()}
                expected = trajectory_points(by_channel[cfg.output][entry["output"]], cfg.trajectory)
                error = None
                try:
                    replayed_msg = planner.step(frame)
                except Exception as exc:  # the planner under test crashing is a test failure, not ours
                    replayed_msg, error = None, f"{type(exc).__name__}: {exc}"
                replayed = trajectory_points(replayed_msg, cfg.trajectory)
                results.append(FrameResult(entry["index"], compare(replayed, expected), replayed, expected, error,
                                           replayed_msg))
        finally:
            planner.close()
        self._results = results
        return results

    def _messages(self) -> dict[str, list[Any]]:
        if self._by_channel is None:
            log = read_log(self.directory / FRAMES)
            cfg = planner_of(self.spec)
            self._by_channel = {}
            for name in list(cfg.inputs) + [cfg.output]:
                codec = get_codec(self.spec.channel(name).encoding)
                self._by_channel[name] = [codec.decode(m.data) for m in log.on(self.spec.channel(name).key)]
        return self._by_channel

    def decoded(self, channel: str, index: int) -> Any:
        return self._messages()[channel][index]
