"""Extraction: from a recorded log to validated frames, replaying the module in order.

One concern a module: ``records`` (what is decided: frames, the whole
extraction), ``recorded`` (the module's recorded traffic, decoded once),
``judging`` (a replayed output against the recorded one), ``per_trigger``
(a module answering each trigger), ``run`` (the state one extraction's
steps share), ``in_order`` (each output decided in turn), ``speculation``
(a cheap output stepped in the replay process, a shadow copy behind),
``forked`` (the candidates of an output in forked copies, with learned time
limits), ``suite_run`` (the suite's own run beside the search) and
``notes`` (what the summary says about the search). This front holds
:func:`extract` and the names the rest of the tool uses.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from astaa_deft.analysis.deft.extract.in_order import extract_in_order
from astaa_deft.analysis.deft.extract.judging import NEAR_MISS_M
from astaa_deft.analysis.deft.extract.notes import ground_truth_rate, near_miss_note, search_note
from astaa_deft.analysis.deft.extract.per_trigger import extract_per_trigger
from astaa_deft.analysis.deft.extract.recorded import channel_messages, log_start, names_message, provenance_of
from astaa_deft.analysis.deft.extract.records import Decided, ExtractedFrame, Extraction, InOrder, OnOutput
from astaa_deft.analysis.deft.extract.speculation import IN_TURN, Speculation
from astaa_deft.analysis.deft.extract.suite_run import SuiteRun
from astaa_deft.analysis.deft.fork_replay import ForkedSearch, run_supervised
from astaa_deft.analysis.deft.planner_section import replay_module_of
from astaa_deft.analysis.deft.replay import ReplayPlanner
from astaa_deft.engine.bus.process_launch import fork_is_safe
from astaa_deft.engine.spec.replay_section import ReplayModule
from astaa_deft.io.codecs import get_codec
from astaa_deft.io.log.reader import LogContents
from astaa_deft.model.sut import Spec


def extract(log: LogContents, spec: Spec, planner: ReplayPlanner, *,
            on_output: OnOutput = lambda done, total, outcome: None,
            jobs: int | Callable[[], int] | None = None, entry: ReplayModule | None = None,
            resume: Sequence[Decided] = (), fresh: Callable[[], ReplayPlanner] | None = None) -> Extraction:
    """Reconstruct and validate a frame per recorded output (per trigger message for a per-trigger module).

    ``entry`` names the module replayed (default: the planner). With ``jobs``
    (an in-process planner on a system that can fork), the candidates of an
    output are tried in forked processes, up to ``jobs`` at a time, from the
    very same planner state (see fork_replay; a callable ``jobs`` is asked
    only when a search could first run two at once); otherwise — or while this
    process runs other Python threads, which a fork must not copy in the
    middle of their work — from deep copies of the planner, one after another.
    ``on_output(outputs done, outputs in all, outcome)`` gets each output
    as soon as it is decided, in order (progress and checkpoints follow it).
    ``resume``: the outputs an earlier extraction of this log decided (in
    order, from the first): their frames are stepped once each, as decided,
    and the search goes on after them.
    ``fresh`` makes a fresh module like ``planner`` (a forked extraction):
    the replay makes its own and its in-order steps are the suite's own run
    (see SuiteRun); without it ``planner`` is forked and this process runs
    the suite beside the search.
    """
    cfg = entry if entry is not None else replay_module_of(spec)
    if cfg.per_trigger:
        return extract_per_trigger(log, spec, planner, cfg=cfg, progress=on_output)
    if jobs is not None and planner.can_snapshot and fork_is_safe(native_threads_ok=True):
        # The search runs in forked copies; here, beside it, the fresh ``planner`` runs the suite: it steps
        # every frame as it is decided and compares the accepted ones, as `pytest DIR` will.
        follower = SuiteRun(planner, cfg, {name: get_codec(spec.channel(name).encoding)
                                           for name in list(cfg.inputs) + [cfg.output]})

        def on_message(message: tuple[int, int, Decided]) -> None:
            on_output(*message)
            follower.add(message[2])

        def body(send: Callable[[tuple[int, int, Decided]], None]) -> Extraction:
            # A module made here, in the replay process: its steps in this process, in order, are the suite's
            # (a fork of the caller's module is not: a module may answer otherwise in a forked process).
            return extract_in_order(log, spec, fresh() if fresh is not None else planner,
                                    lambda *message: send(message), search=ForkedSearch(jobs, send), cfg=cfg,
                                    resume=resume, made_here=fresh is not None)

        result: Extraction = run_supervised(body, on_message=on_message, idle=follower.step_one)
        follower.finish(result)
        return result
    return extract_in_order(log, spec, planner, on_output, search=None, cfg=cfg, resume=resume)


__all__ = ["IN_TURN", "NEAR_MISS_M", "Decided", "ExtractedFrame", "Extraction", "InOrder", "OnOutput", "Speculation",
           "SuiteRun", "channel_messages", "extract", "ground_truth_rate", "log_start", "names_message",
           "near_miss_note", "provenance_of", "search_note"]
