"""Run the planner alone on frames: in-process (a factory) or its own process (lock-step over Zenoh).

Both take a frame as {channel name: decoded message} and return the decoded
output message. In-process planners can be snapshotted (deep copy), which is
what lets extraction try several candidate frames from the same state.
"""

from __future__ import annotations

import copy
import importlib
import importlib.util
import json
import queue
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping
from pathlib import Path
from types import FrameType, ModuleType
from typing import Any, Literal, NoReturn, Protocol, SupportsFloat, TypeGuard, TypeVar, overload

from astaa_deft.engine.bus import process_launch
from astaa_deft.engine.bus import zenoh_config as zc
from astaa_deft.engine.bus.processes import stop_process, tail
from astaa_deft.model.errors import AstaaDeftError, InputError, Problem
from astaa_deft.model.fields import get
from astaa_deft.model.json import DecodedMessage
from astaa_deft.model.sut import Spec
from astaa_deft.engine.spec.planner import resolve_args
from astaa_deft.engine.spec.replay_module import TrajectoryLayout
from astaa_deft.engine.spec.replay_section import ReplayModule
from astaa_deft.analysis.deft.planner_section import replay_module_of
from astaa_deft.analysis.deft.validator import Comparison, Point, compare, compare_messages

OUTPUT_TIMEOUT = 10.0
SETTLE_SECONDS = 0.01
SETTLE_MAX = 0.2


class ReplayPlanner(Protocol):
    """A module replayed on frames: {channel name: decoded message} in, its decoded output (or None) out.

    A snapshot is opaque to the caller: it only goes back into ``restore`` of
    the planner it came from (after a deep copy or a pickle round trip).
    """

    can_snapshot: bool

    def step(self, frame: Mapping[str, DecodedMessage]) -> DecodedMessage | None: ...
    def snapshot(self) -> object: ...
    def restore(self, snap: object) -> None: ...
    def close(self) -> None: ...


class StepModule(Protocol):
    """What a replay factory returns (``replay.factory`` of the spec): an object with ``step(frame)``."""

    def step(self, frame: Mapping[str, DecodedMessage]) -> DecodedMessage | None: ...


def _is_step_module(made: object) -> TypeGuard[StepModule]:
    """``made`` has a ``step`` to call (the one thing replay asks of what a factory returns)."""
    return callable(getattr(made, "step", None))


def load_factory(path: str, spec_dir: Path | None = None, where: str = "planner.replay", source: str = "<spec>"
                 ) -> object:
    """The factory named 'module:attr', imported from sys.path or else from the spec's directory.

    Whatever the module holds under that name (the caller checks it is callable).

    A planner that sits next to its spec (a user's own stack, not an installed
    package) is found without setting PYTHONPATH by hand. ``path/to/file.py:Name``
    names a file relative to the spec's directory (a module beside the SUT's
    sources, not beside the spec): only a spec the user gave as a file has one
    (``spec_dir``; a spec read from a log names no file to run).
    """
    module_name, _, attr = path.rpartition(":")
    if module_name.endswith(".py"):
        return getattr(_module_from_file(module_name, spec_dir, where), attr, None) or _no_attribute(path, where)
    try:
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            top = module_name.split(".")[0]
            if spec_dir is None or exc.name != top or not importable_from(spec_dir, top):
                raise
            if str(spec_dir) not in sys.path:
                sys.path.append(str(spec_dir))  # after installed packages: never shadows them
            module = importlib.import_module(module_name)
        return getattr(module, attr)
    except (ImportError, AttributeError) as exc:
        beside = f" or the spec's directory {spec_dir}" if spec_dir is not None else ""
        raise InputError(Problem(source, None, None, f"{where}: replay factory '{path}' cannot be loaded: {exc}",
                                 f"check '{where}.factory': its module must be importable from sys.path"
                                 f"{beside} (set PYTHONPATH, or install its package)")) from None


def _module_from_file(relative: str, spec_dir: Path | None, where: str) -> ModuleType:
    """The module in the file ``relative`` to the spec's directory, imported under its own name (so its objects
    pickle), its directory added after installed packages (so it finds the modules beside it)."""
    if spec_dir is None:
        raise InputError(Problem("<spec>", None, None, f"replay factory file '{relative}' ({where}.factory) is"
                                 " relative to a spec file, and this spec was not read from one",
                                 "give the spec file (--spec), or name the factory as package.module:Name"))
    file = (spec_dir / relative).resolve()
    name = file.stem
    loaded = sys.modules.get(name)
    if loaded is not None and Path(getattr(loaded, "__file__", "") or "").resolve() == file:
        return loaded
    if loaded is not None or not file.is_file() or not name.isidentifier():
        why = (f"another module named '{name}' is loaded already" if loaded is not None
               else f"{file} is not a Python file" if file.is_file() else f"{file} does not exist")
        raise InputError(Problem("<spec>", None, None, f"replay factory file '{relative}' cannot be loaded: {why}",
                                 f"check '{where}.factory': a path relative to the spec, to a file whose name is"
                                 " a free module name"))
    if str(file.parent) not in sys.path:
        sys.path.append(str(file.parent))  # after installed packages: never shadows them
    spec = importlib.util.spec_from_file_location(name, file)
    assert spec is not None and spec.loader is not None  # a .py file always has a source loader
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except Exception as exc:  # the user's module failing to import is their input problem
        del sys.modules[name]
        raise InputError(Problem("<spec>", None, None, f"replay factory file '{relative}' cannot be imported:"
                                 f" {type(exc).__name__}: {exc}", f"check '{where}.factory' and that file")) from None
    return module


def _no_attribute(path: str, where: str) -> NoReturn:
    raise InputError(Problem("<spec>", None, None, f"replay factory '{path}' cannot be loaded: its file has no"
                             f" '{path.rpartition(':')[2]}'", f"check '{where}.factory'"))


def importable_from(directory: Path, top: str) -> bool:
    """A module or package named ``top`` sits in ``directory``."""
    return (directory / f"{top}.py").is_file() or (directory / top / "__init__.py").is_file() \
        or (directory / top).is_dir()


class InProcessPlanner:
    can_snapshot = True

    def __init__(self, factory: str, kwargs: Mapping[str, object], *, spec_dir: Path | None = None,
                 where: str = "planner.replay", source: str = "<spec>"):
        self.factory = factory
        make = load_factory(factory, spec_dir, where, source)  # ``source``: the spec's file, named in errors
        if not callable(make):
            raise InputError(Problem(source, None, None, f"{where}: replay factory '{factory}' is not callable",
                                     f"check '{where}.factory': name a class or function"))
        _check_arguments(make, kwargs, factory=factory, where=where, source=source)
        made = make(**kwargs)
        if not _is_step_module(made):
            raise InputError(Problem(source, None, None, f"{where}: replay factory '{factory}' returned an object "
                                     "without a step(frame) method", f"check '{where}.factory'"))
        self.obj: StepModule = made

    def step(self, frame: Mapping[str, DecodedMessage]) -> DecodedMessage | None:
        return self.obj.step(frame)

    def snapshot(self) -> StepModule:
        return copy.deepcopy(self.obj)

    def restore(self, snap: object) -> None:
        if not _is_step_module(snap):
            raise TypeError(f"not a snapshot of replay factory '{self.factory}''s module: {type(snap).__name__}")
        self.obj = snap

    def close(self) -> None:
        pass


def _check_arguments(make: Callable[..., object], kwargs: Mapping[str, object], *, factory: str, where: str,
                     source: str = "<spec>") -> None:
    """InputError when the spec's args do not fit the factory's parameters (a misspelt or missing arg)."""
    import inspect

    try:
        signature = inspect.signature(make)
    except (TypeError, ValueError):  # no signature to read (a builtin): the call itself will tell
        return
    try:
        signature.bind(**kwargs)
    except TypeError as exc:
        raise InputError(Problem(source, None, None,
                                 f"{where}: replay factory '{factory}' does not take these args: {exc}",
                                 f"give the args its parameters name ({signature})")) from None


class LockstepPlanner:
    """The planner's own process on a private Zenoh router, one frame at a time.

    For each frame: publish the non-trigger inputs, then the trigger, then wait
    for one output. Its state lives in the process, so no snapshots: only the
    most likely candidate frame can be tried.
    """

    can_snapshot = False

    def __init__(self, spec: Spec, planner: ReplayModule, params: Mapping[str, str]):
        import zenoh

        self.spec, self.planner = spec, planner
        self._dir = tempfile.TemporaryDirectory(prefix="astaa-deft-replay-")
        run_dir = Path(self._dir.name)
        endpoint = zc.loopback_endpoint()
        self.session = zc.open_session(zc.config_dict(mode="router", listen=[endpoint]))
        config = zc.write_config_file(zc.config_dict(mode="client", connect=[endpoint]), run_dir / "zenoh.json5")
        values = {**spec.params, **params, "python": sys.executable, "zenoh_config": str(config),
                  "module": planner.module, "run_dir": str(run_dir),
                  "spec_dir": str(spec.path.parent if spec.path else Path.cwd())}
        argv = [part.format_map(values) for part in planner.command]
        self.log_path = run_dir / "planner.log"
        self.outputs: queue.Queue[bytes] = queue.Queue()
        out_key = spec.channel(planner.output).key
        self._sub = self.session.declare_subscriber(out_key, lambda s: self.outputs.put(s.payload.to_bytes()))
        self._pubs = {name: self.session.declare_publisher(spec.channel(name).key,
                                                           congestion_control=zenoh.CongestionControl.BLOCK)
                      for name in planner.inputs}
        # The router is private, but a port is only free until someone takes it: a process
        # left from an earlier run can reconnect to a port the OS handed out again and publish
        # on the module's inputs. Our own puts reach these counters too (local delivery), so
        # more arrivals than puts on a key are another session's messages.
        self._published = dict.fromkeys(planner.inputs, 0)
        self._arrived = dict.fromkeys(planner.inputs, 0)
        self._watchers = [self.session.declare_subscriber(spec.channel(name).key, self._counter(name))
                          for name in planner.inputs]
        self.endpoint = endpoint
        with open(self.log_path, "wb") as log:
            self.proc = process_launch.start(argv, env={**_env(), "ZENOH_CONFIG": str(config)}, stdout=log,
                                             stderr=subprocess.STDOUT)
        self._sent: dict[str, DecodedMessage] = {}
        self._latencies: deque[float] = deque([0.0], maxlen=10)
        self._wait_connected()

    def _wait_connected(self) -> None:
        deadline = time.monotonic() + 20.0
        trigger_pub = self._pubs[self.planner.trigger]
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise InputError(f"the planner process exited while starting:\n{tail(self.log_path)}")
            # zenoh's stub types Publisher.matching_status as bool; at run time it is a MatchingStatus.
            if trigger_pub.matching_status.matching:  # type: ignore[attr-defined]
                time.sleep(0.3)  # its other subscriptions follow the first within moments
                return
            time.sleep(0.05)
        raise InputError("the planner process never subscribed to its trigger channel")

    def _counter(self, name: str) -> Callable[[object], None]:
        def arrived(_sample: object) -> None:
            self._arrived[name] += 1
        return arrived

    def _publish(self, name: str, message: DecodedMessage) -> None:
        self._published[name] += 1
        self._pubs[name].put(json.dumps(message))

    def _check_private(self) -> None:
        foreign = sorted(name for name in self._arrived if self._arrived[name] > self._published[name])
        if foreign or not self.outputs.empty():
            what = (f"messages on {', '.join(foreign)} that the replay did not send" if foreign
                    else "an output the replay did not ask for")
            raise InputError(f"the replay's private Zenoh router ({self.endpoint}) got {what}: another "
                             "session joined it (a process left from an earlier run, on a port the OS gave out "
                             "again), or the module answers one trigger twice; its outputs cannot be trusted, "
                             "run the replay again")

    def step(self, frame: Mapping[str, DecodedMessage]) -> DecodedMessage | None:
        self._check_private()
        changed = False
        for name, message in frame.items():
            if name != self.planner.trigger and self._sent.get(name) != message:
                self._publish(name, message)
                self._sent[name] = message
                changed = True
        if changed:
            # A module may take each key's messages on a thread of its own: let the inputs
            # land before the trigger, or it plans on the previous ones. The busier the
            # module (the longer it takes to answer), the longer the wait.
            time.sleep(min(SETTLE_MAX, max(SETTLE_SECONDS, 2.0 * statistics.median(self._latencies))))
        sent = time.monotonic()
        self._publish(self.planner.trigger, frame[self.planner.trigger])
        try:
            output = json.loads(self.outputs.get(timeout=OUTPUT_TIMEOUT))
            self._latencies.append(time.monotonic() - sent)
            self._check_private()
            return output
        except queue.Empty:
            raise InputError(f"the planner process gave no output within {OUTPUT_TIMEOUT:g} s:\n"
                             f"{tail(self.log_path)}") from None

    def snapshot(self) -> object:
        raise NotImplementedError

    def restore(self, snap: object) -> None:
        raise NotImplementedError

    def close(self) -> None:
        stop_process(self.proc, grace=5.0)
        self._sub.undeclare()
        for watcher in self._watchers:
            watcher.undeclare()
        self.session.close()
        self._dir.cleanup()


def make_planner(spec: Spec, params: Mapping[str, str], *, prefer_process: bool = False,
                 entry: ReplayModule | None = None, spec_dir: Path | None = None) -> ReplayPlanner:
    """The module of ``entry`` (default: the planner) ready to step, in-process or as its own process.

    Its factory is looked for beside the spec (``spec_dir`` for a spec not read from a file).
    """
    planner = entry if entry is not None else replay_module_of(spec)
    if planner.factory and not (prefer_process and planner.command):
        where = "planner.replay" if planner.where == "planner" else planner.where
        return InProcessPlanner(planner.factory, resolve_args(planner.factory_args, {**spec.params, **params}),
                                spec_dir=spec.path.parent.resolve() if spec.path else spec_dir, where=where,
                                source=str(spec.path) if spec.path else spec.name)
    return LockstepPlanner(spec, planner, params)


def code_fingerprint(entry: ReplayModule, spec: Spec) -> str | None:
    """A hash of the sources beside the factory's module (its package's own files); None if not found.

    A snapshot of the module's state is only as good as the code that made
    it: a fixed module must be replayed from the start.
    """
    import hashlib
    import inspect

    if not entry.factory:
        return None
    try:
        factory = load_factory(entry.factory, spec.path.parent.resolve() if spec.path else None)
        source = inspect.getsourcefile(factory) if callable(factory) else None  # no source: not a factory
    except (InputError, TypeError, OSError):
        return None
    if source is None:
        return None
    digest = hashlib.sha256()
    for path in sorted(Path(source).parent.glob("*.py")):
        digest.update(path.name.encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()


def compare_outputs(entry: ReplayModule, replayed: object, recorded: object) -> Comparison:
    """A replayed output against the recorded one: as trajectories (the planner), else field by field."""
    if entry.trajectory is not None:
        return compare(trajectory_points(replayed, entry.trajectory), trajectory_points(recorded, entry.trajectory))
    return compare_messages(replayed, recorded, entry.ignore)


class StepHang(AstaaDeftError):
    """A module's step ran past its ``hang_after``: the module hangs on this frame."""


T = TypeVar("T")


HANG_WALL_FACTOR = 10.0  # a step that uses no CPU (blocked) is a hang after this many times its CPU limit


def within_limit(call: Callable[[], T], seconds: float) -> T:
    """``call()``, interrupted by StepHang once it has used ``seconds`` of CPU time (0: no limit), or has
    waited ``HANG_WALL_FACTOR`` times that long without using it (a step blocked on something that never comes).

    CPU time, not wall time: on a loaded machine a step waits for a core, and a
    limit on wall time would call a step that merely waited a hang — the
    module "answers nothing more" and every later frame is lost, a result that
    depends on the load (a replay's results must not). A SIGPROF timer (the
    process's CPU time) interrupts Python code that never returns, a SIGALRM
    timer one that blocks, in the main thread of a POSIX process; elsewhere, or
    inside native code that never returns to the interpreter, the call is not
    limited here (the replay pool's per-test timeout still stops it). A wall
    timer set before (pytest-timeout's) is set again afterwards, less the time
    the step took.
    """
    if seconds <= 0 or not hasattr(signal, "setitimer") or threading.current_thread() is not threading.main_thread():
        return call()
    blocked_after = seconds * HANG_WALL_FACTOR

    def used_up(signum: int, frame: FrameType | None) -> NoReturn:
        raise StepHang(f"the step did not return within {seconds:g} s of CPU time")

    def waited(signum: int, frame: FrameType | None) -> NoReturn:
        raise StepHang(f"the step did not return within {blocked_after:g} s, blocked")

    previous_prof = signal.signal(signal.SIGPROF, used_up)
    previous_alarm = signal.signal(signal.SIGALRM, waited)
    started = time.monotonic()
    outer_delay, outer_interval = signal.setitimer(signal.ITIMER_REAL, blocked_after)
    signal.setitimer(signal.ITIMER_PROF, seconds)
    try:
        return call()
    finally:
        signal.setitimer(signal.ITIMER_PROF, 0)
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGPROF, previous_prof)
        signal.signal(signal.SIGALRM, previous_alarm)
        if outer_delay > 0:  # the caller's own wall timer runs on where it was
            signal.setitimer(signal.ITIMER_REAL, max(outer_delay - (time.monotonic() - started), 1e-6),
                             outer_interval)


def _getter(path: str) -> Callable[[Any], Any]:
    """A fast reader for a field path: plain keys are indexed directly (the common case)."""
    if path.replace("_", "").isalnum():
        return lambda value: value[path]

    def slow(value: Any) -> Any:
        found = get(value, path)
        if not found:
            raise KeyError(path)
        return found[0][1]

    return slow


@overload
def trajectory_points(message: object, layout: TrajectoryLayout,
                      with_heading: Literal[False] = False) -> list[Point]: ...


@overload
def trajectory_points(message: object, layout: TrajectoryLayout,
                      with_heading: Literal[True]) -> list[tuple[float, float, float, float]]: ...


def trajectory_points(message: object, layout: TrajectoryLayout,
                      with_heading: bool = False) -> list[Point] | list[tuple[float, float, float, float]]:
    """(x, y, t absolute) of each planned point, per the spec's layout; (x, y, t, heading) with_heading."""
    if not isinstance(message, Mapping):
        return []
    found = get(message, layout.points)
    if not found or not isinstance(found[0][1], list):
        return []
    offset = 0.0
    if layout.time == "relative":
        stamp = get(message, layout.stamp)
        try:
            offset = seconds(stamp[0][1]) if stamp else 0.0
        except (KeyError, TypeError, ValueError):
            offset = 0.0
    gx, gy, gt, gh = _getter(layout.x), _getter(layout.y), _getter(layout.t), _getter(layout.heading)
    out: list = []
    for point in found[0][1]:
        try:
            xyt = (float(gx(point)), float(gy(point)), seconds(gt(point)) + offset)
        except (KeyError, IndexError, TypeError, ValueError):
            continue
        if with_heading:
            try:
                heading = float(gh(point))
            except (KeyError, IndexError, TypeError, ValueError):
                heading = 0.0
            out.append((*xyt, heading))
        else:
            out.append(xyt)
    return out


def seconds(value: SupportsFloat | str | Mapping[str, SupportsFloat | str]) -> float:
    """A time as seconds: a number, or a ROS 2 ``builtin_interfaces/msg/Time`` decoded ({sec, nanosec}).

    Anything else raises as ``float`` does (TypeError, ValueError; KeyError without ``sec`` or ``nanosec``):
    a planned point's time is read from whatever the module wrote, and its caller skips what does not read.
    """
    if isinstance(value, Mapping):
        return float(value["sec"]) + float(value["nanosec"]) * 1e-9
    return float(value)


def _env() -> dict[str, str]:
    import os

    return dict(os.environ)
