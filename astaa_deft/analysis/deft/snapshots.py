"""Oracle tests that fail fast: the module's state just before the failing frame, kept with the suite.

A suite replays every frame in order (modules carry state), so a failing
oracle test near the end of a long run waits for the whole replay. For an
in-process module whose state pickles, :func:`add_oracle_snapshots` replays
the exported suite once, pickles the state just before each oracle frame
into ``DIR/snapshots/`` and names it in the oracle's manifest entry; the
pytest plugin then runs those oracle tests first, each from its snapshot
with one step (:meth:`.suite.Suite.result_from_snapshot`). A snapshot is
kept only if the step from it answers exactly (same message) as the
sequential replay did, so the verdict is the same either way; and it is
used only while the module's code (the sources beside its factory) and the
suite's params are the ones it was taken with: a fixed module, or one run
with other params, is replayed from the start (:func:`usable_snapshot`).
The suite's other tests are unchanged.

The snapshots are pickles written by this tool into the suite it wrote:
load a suite only from where you would run its code.
"""

from __future__ import annotations

import contextlib
import json
import pickle
from pathlib import Path

from astaa_deft.io.output_place import write_atomic
from astaa_deft.analysis.deft.export import MANIFEST, oracles_of
from astaa_deft.analysis.deft.oracle_entry import COLLISION, OracleEntry
from astaa_deft.analysis.deft.suite import Suite

SNAPSHOTS = "snapshots"


def add_oracle_snapshots(directory: Path) -> int:
    """Snapshot the state before each oracle frame of the suite in ``directory``; how many were kept."""
    suite = Suite(directory)
    oracles = oracles_of(suite.manifest)  # as written: the kept snapshots are added to these
    wanted = {o.frame for o in suite.oracles if o.frame is not None and o.kind == COLLISION}
    if not wanted:
        return 0
    from astaa_deft.analysis.deft.replay import code_fingerprint, make_planner

    planner = make_planner(suite.spec, suite.manifest["params"], entry=suite.entry)
    if not planner.can_snapshot:
        planner.close()
        return 0
    taken: dict[int, bytes] = {}
    try:
        for entry in suite.frames:
            if entry["index"] in wanted:
                # A state that does not pickle: that oracle replays sequentially.
                with contextlib.suppress(Exception):
                    taken[entry["index"]] = pickle.dumps(planner.snapshot(), protocol=pickle.HIGHEST_PROTOCOL)
            if entry["index"] >= max(wanted):
                break
            try:
                planner.step(suite.frame_inputs(entry))
            except Exception:  # the module's failure is its frame test's business; the states after it are not
                break
    finally:
        planner.close()
    fingerprint = code_fingerprint(suite.entry, suite.spec)
    if fingerprint is None:
        return 0
    sequential = {r.index: r for r in suite.results()}
    (directory / SNAPSHOTS).mkdir(exist_ok=True)
    kept = 0
    for oracle, typed in zip(oracles, suite.oracles, strict=True):
        data = taken.get(typed.frame) if typed.frame is not None else None
        if typed.frame is None or data is None:
            continue
        name = f"{SNAPSHOTS}/frame_{typed.frame:05d}.pickle"
        write_atomic(directory / name, data)
        fast = suite.result_from_snapshot(typed.frame, name)
        slow = sequential.get(typed.frame)
        if slow is not None and fast.error == slow.error and _same(fast.message, slow.message):
            oracle["snapshot"] = name
            oracle["snapshot_of"] = {"params": suite.manifest["params"], "code": fingerprint}
            kept += 1
        else:
            (directory / name).unlink()
    manifest_path = directory / MANIFEST
    manifest = json.loads(manifest_path.read_text())
    manifest["oracles"] = oracles
    write_atomic(manifest_path, json.dumps(manifest, indent=1) + "\n")
    return kept


def _same(a: object, b: object) -> bool:
    return json.dumps(a, sort_keys=True, default=str) == json.dumps(b, sort_keys=True, default=str)


def usable_snapshot(suite: Suite, oracle: OracleEntry) -> str | None:
    """The oracle's snapshot, if the module's code and the suite's params are still the ones it was taken with."""
    from astaa_deft.analysis.deft.replay import code_fingerprint

    name = oracle.snapshot
    if not name or oracle.snapshot_params != suite.manifest.get("params") or not (suite.directory / name).is_file():
        return None
    return name if oracle.snapshot_code == code_fingerprint(suite.entry, suite.spec) else None
