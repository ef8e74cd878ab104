"""Decictor against the demo stack in one process (``demo.closed_loop``): no bus, no real time.

Lives beside the benchmarks (and is imported by the Decictor tests) because it
joins the tool to the demo SUT: the tool itself never imports the demo.

The participants are rendered into the planner's prediction messages by the
same code the ``participant`` action runs in the proxy (``render`` with the
spec's mapping), so a scenario here is the one a live campaign would run,
minus message timing. Benchmarks and tests use it to run hundreds of
scenarios; the live path is ``astaa-deft fuzz --strategy decictor``.
"""

from __future__ import annotations

from astaa_deft.analysis.decictor.oracle import RunObservation
from astaa_deft.analysis.decictor.paths import EgoPath, EgoState
from astaa_deft.demo.closed_loop import run_closed_loop
from astaa_deft.engine.intercept.actions.participant import ChannelMapping, Participant, render


def observe_closed_loop(scenario: str, participants: tuple[Participant, ...], mapping: ChannelMapping,
                        defects: bool) -> RunObservation:
    """Run the scenario with the participants injected on ``mapping.channel``; the ego's path and the task."""

    def rewrite(channel: str, message: dict) -> dict:
        if channel == mapping.channel and participants:
            stamp = message["header"]["stamp"]
            array = message[str(mapping.array)]
            for participant in participants:
                array.append(render(participant, mapping, stamp))
        return message

    result = run_closed_loop(scenario, defects=defects, rewrite=rewrite)
    states = tuple(EgoState(t=f["localization"]["header"]["stamp"], x=f["localization"]["x"], y=f["localization"]["y"],
                            heading=f["localization"]["heading"], speed=f["localization"]["speed"],
                            acceleration=f["localization"]["acceleration"]) for f in result.frames)
    return RunObservation(EgoPath(states), bool(result.status.get("goal_reached")),
                          bool(result.status.get("collision")))
