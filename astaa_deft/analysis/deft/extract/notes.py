"""What the extraction summary says about a search: the time it saved, its near misses, the ground-truth rate."""

from __future__ import annotations

from astaa_deft.analysis.deft.extract.judging import NEAR_MISS_M
from astaa_deft.analysis.deft.extract.recorded import names_message, provenance_of
from astaa_deft.analysis.deft.extract.records import Extraction
from astaa_deft.analysis.deft.planner_section import planner_of
from astaa_deft.analysis.deft.search_policy import EXPENSIVE_TRIES
from astaa_deft.engine.spec.replay_section import ReplayModule
from astaa_deft.io.codecs import get_codec
from astaa_deft.io.codecs.base import DecodeError
from astaa_deft.model.sut import Spec


def search_note(extraction: Extraction) -> str | None:
    """What the candidate search did to save time, when it did anything: for the extraction summary."""
    parts = []
    if extraction.reordered:
        parts.append(f"{extraction.reordered} output(s) tried first the way earlier outputs were reproduced "
                     f"(trigger rule and input offsets)")
    stepped = extraction.first_stepped_in_runner + extraction.first_missed_in_runner
    if stepped:
        parts.append(f"{stepped} cheap output(s) stepped their first candidate in the replay process "
                     f"({extraction.first_missed_in_runner} wrong: searched on by a copy one output behind)")
    if extraction.capped:
        parts.append(f"{extraction.capped} output(s) not reproduced by their likeliest candidates (at most "
                     f"{EXPENSIVE_TRIES} for an expensive output; after outputs in a row not reproduced, 8, 2, "
                     f"then 1: the module's state has left the recorded one), the others not tried")
    if extraction.candidates_cut:
        parts.append(f"{extraction.candidates_cut} candidate(s) cut by the time limit learned from the accepted "
                     f"steps, {extraction.cut_retried} of them retried under the full limit (nothing else was "
                     f"accepted), {extraction.retried_kept} kept after that")
    if extraction.declared:
        parts.append(f"{extraction.declared} output(s) named the inputs they used (provenance): that frame tried "
                     f"first")
    if extraction.checked_in_replay:
        parts.append(f"the suite's own run done by the replay's in-order steps of a fresh module for "
                     f"{extraction.checked_in_replay} frame(s)")
    elif extraction.checked_beside:
        parts.append(f"the suite's own run stepped {extraction.checked_beside} frame(s) beside the search")
    if extraction.confirmed_unforked:
        parts.append(f"{extraction.confirmed_unforked} output(s) reproduced by the suite's own run (a fresh module, "
                     f"not forked) though forked copies answered a little off")
    return "candidate search: " + "; ".join(parts) if parts else None


def near_miss_note(extraction: Extraction, unit: str = " m") -> str | None:
    """Why outputs that match at 1e-9 m are not counted at θ = 0: the distances, what was measured about their
    cause, and the flag that sets θ (``unit``: "" for a module compared field by field)."""
    near = sorted(f.comparison.distance for f in extraction.frames if 0.0 < f.comparison.distance <= NEAR_MISS_M)
    if not near:
        return None
    quantiles = ", ".join(f"{name} {near[min(len(near) - 1, int(q * len(near)))]:.3g}{unit}"
                          for name, q in (("min", 0.0), ("median", 0.5), ("p90", 0.9)))
    measured = extraction.copies_differ
    if measured is None:
        why = "floating-point noise (not measured whether copies of the module's state answer alike)"
    elif measured == 0.0:
        why = ("not the copying: two copies of the module's state stepped on the same frame answer bit for bit "
               "(measured), so the frame or the module's own run-to-run noise differs")
    else:
        why = (f"the module's state does not survive copying bit for bit: two copies stepped on the same frame "
               f"answer {measured:.3g}{unit} apart (measured)")
    return (f"{len(near)} output(s) match within {NEAR_MISS_M:g}{unit} but not exactly (distances: {quantiles}, "
            f"max {near[-1]:.3g}{unit}): {why}. If that is acceptable, set θ with --threshold {NEAR_MISS_M:g} "
            f"(or the module's threshold in the spec).")


def ground_truth_rate(extraction: Extraction, spec: Spec, debug_path: str = "debug.inputs",
                      entry: ReplayModule | None = None) -> tuple[int, int]:
    """(frames whose chosen inputs are those the module's output names, frames checked).

    Evaluation only: reads the output's record (``debug_path``, e.g. the demo
    planner's debug block) naming the header sequence numbers (or stamps) of
    the inputs it used; an input named null was absent. ``entry``: the module
    (default: the planner).
    """
    cfg = entry if entry is not None else planner_of(spec)
    codec = get_codec(spec.channel(cfg.output).encoding)
    exact = checked = 0
    for f in extraction.frames:
        if f.output is None:
            continue
        try:
            truth = provenance_of(codec.decode(f.output.data), debug_path)
        except DecodeError:
            continue
        if truth is None:
            continue
        checked += 1
        same = True
        for name, named in truth.items():
            msg = f.inputs.get(name)
            if msg is None:
                same = same and named is None
                continue
            try:
                same = same and names_message(get_codec(spec.channel(name).encoding).decode(msg.data), named)
            except DecodeError:
                same = False
        exact += same
    return exact, checked
