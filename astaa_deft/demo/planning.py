"""Planning process: runs ``planner_core.Planner`` on every prediction message.

Keeps the newest valid message of each input channel; when a prediction
arrives (the trigger) it assembles the frame from what it holds at that
moment and publishes the planner's trajectory. All the planning logic is in
``planner_core`` so that DeFT can replay it without Zenoh.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable

import zenoh

from astaa_deft.demo import messages
from astaa_deft.demo.common import KEYS, Inbox, JsonPublisher, log, run_module
from astaa_deft.demo.planner_core import INPUT_CHANNELS, TRIGGER_CHANNEL, Planner

MODULE = "planning"
# Shape checks per input, so the planner only ever sees well-formed messages.
READERS: dict[str, Callable[[dict], object]] = {
    "routing": messages.routing,
    "localization": messages.localization,
    "traffic_light": messages.traffic_lights,
    "prediction": messages.prediction,
}


def main(session: zenoh.Session, args: argparse.Namespace) -> None:
    planner = Planner(defects=args.defects)
    inbox = Inbox(session, MODULE)
    for channel in INPUT_CHANNELS:
        inbox.subscribe(KEYS[channel], channel)
    publisher = JsonPublisher(session, KEYS["trajectory"])
    latest: dict[str, dict] = {}
    while True:
        received = inbox.get(timeout=0.5)
        if received is None:
            continue
        channel, message = received
        try:
            READERS[channel](message)
            messages.header(message)
        except messages.BadMessage as exc:
            log(MODULE, f"ignored malformed {channel} message: {exc}")
            continue
        latest[channel] = message
        if channel != TRIGGER_CHANNEL:
            continue
        if any(name not in latest for name in INPUT_CHANNELS):
            continue  # still starting up: the simulator publishes every input from its first moment
        frame = {name: latest[name] for name in INPUT_CHANNELS}
        publisher.publish_message(planner.step(frame))


if __name__ == "__main__":
    sys.exit(run_module(MODULE, "Demo AV planning: a deterministic sampling planner.", main))
