"""Load an exported module test suite and replay it (used by the pytest plugin)."""

from __future__ import annotations

import functools
import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from astaa_deft.io.codecs import get_codec
from astaa_deft.io.log.reader import read_log
from astaa_deft.model.json import DecodedMessage
from astaa_deft.model.sut import Spec
from astaa_deft.engine.spec.replay_section import ReplayModule
from astaa_deft.engine.spec.loader import load_spec_text
from astaa_deft.analysis.deft.export import FRAMES, MANIFEST, oracles_of
from astaa_deft.analysis.deft.oracle_entry import OracleEntry
from astaa_deft.analysis.deft.planner_section import replay_module_of
from astaa_deft.analysis.deft.replay import StepHang, compare_outputs, make_planner, trajectory_points, within_limit
from astaa_deft.analysis.deft.validator import Comparison, Point


@dataclass(kw_only=True)
class FrameResult:
    index: int
    comparison: Comparison
    replayed: list[Point]
    expected: list[Point]
    error: str | None = None
    message: DecodedMessage | None = None  # the replayed output message
    expected_message: DecodedMessage | None = None  # the recorded one (None: the module answered nothing)
    stopped: str = ""  # per-trigger modules: "crash" or "hang" on this frame, "not run" after one


class Suite:
    def __init__(self, directory: Path):
        self.directory = directory
        self.manifest = json.loads((directory / MANIFEST).read_text())
        spec_dir = self.manifest.get("spec_dir")
        base_dir = Path(spec_dir) if spec_dir and Path(spec_dir).is_dir() else directory
        self.spec_dir = base_dir
        self.spec: Spec = load_spec_text(self.manifest["spec_yaml"], name=f"{self.manifest['spec_name']} (embedded)",
                                         base_dir=base_dir)
        self.threshold = float(self.manifest["threshold"])
        # The replayed module: the planner unless the manifest names another (astaa-deft extract --module).
        self.entry: ReplayModule = replay_module_of(self.spec, self.manifest.get("module"),
                                                    self.manifest.get("output"))
        self.oracles = [OracleEntry.from_json(o) for o in oracles_of(self.manifest)]
        self._results: list[FrameResult] | None = None
        self._by_channel: dict[str, _Decoded] | None = None

    @property
    def hang_after(self) -> float:
        """Seconds a step may take before it counts as a hang: a per-trigger module's ``hang_after`` (its
        extraction judged hangs so); a module replayed per output, as extracted, has no limit (a slow cycle
        of a planner is no hang)."""
        return self.entry.hang_after if self.entry.per_trigger else 0.0

    @property
    def frames(self) -> list[dict]:
        return self.manifest["frames"]

    def results(self) -> list[FrameResult]:
        """Replay every frame once, in order (the planner keeps state across frames)."""
        if self._results is not None:
            return self._results
        cfg = self.entry
        by_channel = self._messages()
        planner = make_planner(self.spec, self.manifest["params"], entry=cfg, spec_dir=self.spec_dir)
        results = []
        stopped: str | None = None  # why a per-trigger module answers nothing more (it crashed or hung)
        try:
            for entry in self.frames:
                frame = {name: by_channel[name][i] for name, i in entry["inputs"].items()}
                expected_msg = by_channel[cfg.output][entry["output"]] if entry["output"] is not None else None
                error, how = stopped, "not run" if stopped else ""
                try:
                    if stopped is not None:
                        replayed_msg = None
                    else:
                        replayed_msg = within_limit(functools.partial(planner.step, frame), self.hang_after)
                except StepHang as exc:
                    replayed_msg, error, how = None, f"the module hangs: {exc}", "hang"
                except Exception as exc:  # the module under test crashing is a test failure, not ours
                    replayed_msg, error, how = None, f"{type(exc).__name__}: {exc}", "crash"
                layout = cfg.trajectory
                replayed = trajectory_points(replayed_msg, layout) if layout is not None else []
                expected = trajectory_points(expected_msg, layout) if layout is not None else []
                results.append(FrameResult(index=entry["index"],
                                           comparison=compare_outputs(cfg, replayed_msg, expected_msg),
                                           replayed=replayed, expected=expected, error=error, message=replayed_msg,
                                           expected_message=expected_msg, stopped=how))
                if error is not None and stopped is None and cfg.per_trigger:
                    # A crashed or hung module answers nothing more: the later frames are not run.
                    stopped = f"not run: the module stopped answering at frame {entry['index']} ({error})"
        finally:
            planner.close()
        self._results = results
        return results

    @property
    def replayed(self) -> bool:
        """Whether every frame has been replayed in order already (its results are then the ones to use)."""
        return self._results is not None

    def frame_inputs(self, entry: dict) -> dict[str, DecodedMessage]:
        """The decoded inputs of one manifest frame entry."""
        by_channel = self._messages()
        return {name: by_channel[name][i] for name, i in entry["inputs"].items()}

    def result_from_snapshot(self, index: int, snapshot: str) -> FrameResult:
        """Frame ``index`` stepped once from the module state pickled just before it (snapshots.py)."""
        import pickle

        cfg = self.entry
        entry = next(e for e in self.frames if e["index"] == index)
        expected_msg = self.decoded(cfg.output, entry["output"]) if entry["output"] is not None else None
        planner = make_planner(self.spec, self.manifest["params"], entry=cfg)
        error, how = None, ""
        try:
            planner.restore(pickle.loads((self.directory / snapshot).read_bytes()))
            replayed_msg = within_limit(functools.partial(planner.step, self.frame_inputs(entry)), self.hang_after)
        except StepHang as exc:
            replayed_msg, error, how = None, f"the module hangs: {exc}", "hang"
        except Exception as exc:  # the module under test crashing is a test failure, not ours
            replayed_msg, error, how = None, f"{type(exc).__name__}: {exc}", "crash"
        finally:
            planner.close()
        layout = cfg.trajectory
        replayed = trajectory_points(replayed_msg, layout) if layout is not None else []
        expected = trajectory_points(expected_msg, layout) if layout is not None else []
        return FrameResult(index=index, comparison=compare_outputs(cfg, replayed_msg, expected_msg), replayed=replayed,
                           expected=expected, error=error, message=replayed_msg, expected_message=expected_msg,
                           stopped=how)

    def _messages(self) -> dict[str, _Decoded]:
        if self._by_channel is None:
            log = read_log(self.directory / FRAMES)
            cfg = self.entry
            self._by_channel = {}
            for name in list(cfg.inputs) + [cfg.output]:
                codec = get_codec(self.spec.channel(name).encoding)
                self._by_channel[name] = _Decoded([m.data for m in log.on(self.spec.channel(name).key)],
                                                  codec.decode)
        return self._by_channel

    def decoded(self, channel: str, index: int) -> DecodedMessage:
        return self._messages()[channel][index]


class _Decoded:
    """A channel's messages in the suite, each decoded when first asked for (an oracle run from a snapshot
    needs one frame's, not the whole run's), then the same object every time."""

    def __init__(self, payloads: list[bytes], decode: Callable[[bytes], DecodedMessage]):
        self._payloads = payloads
        self._decode = decode
        self._cache: dict[int, DecodedMessage] = {}

    def __getitem__(self, index: int) -> DecodedMessage:
        if index not in self._cache:
            self._cache[index] = self._decode(self._payloads[index])
        return self._cache[index]

    def __len__(self) -> int:
        return len(self._payloads)
