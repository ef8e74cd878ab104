"""The Zenoh loop the test stacks' JSON nodes share (modlevel_ctrl.py, modlevel_watch.py, zoo_consumer.py).

``serve`` opens a session from the environment the tool gives each module
(loopback, scouting off), subscribes to one key, prints the node's ready line,
and hands each JSON object that arrives to ``step`` in arrival order (on the
main thread: a node's state is never touched by two threads); what ``step``
returns, when not None, is put on ``publish``. A payload that is not a JSON
object is dropped, as a deserialiser drops it. A seeded defect — anything
``step`` raises — prints its traceback and exits at once with 1 (an open
session holds a normal exit). SIGTERM ends the loop and closes the session.
Imports nothing from astaa-deft; zenoh only when called (tests import the
nodes for their checks alone).
"""

import json
import os
import queue
import signal
import sys
import traceback


def serve(*, listen, ready, step, publish=None):
    import zenoh

    inbox = queue.Queue()
    signal.signal(signal.SIGTERM, lambda *_: inbox.put(None))
    session = zenoh.open(zenoh.Config.from_env())
    pub = session.declare_publisher(publish) if publish else None
    session.declare_subscriber(listen, lambda sample: inbox.put(sample.payload.to_bytes()))
    print(ready, flush=True)
    while True:
        payload = inbox.get()
        if payload is None:
            break
        try:
            message = json.loads(payload)
        except ValueError:
            continue
        if not isinstance(message, dict):
            continue
        try:
            out = step(message)
        except Exception:  # a seeded defect: its traceback, then exit at once
            traceback.print_exc()
            sys.stderr.flush()
            os._exit(1)
        if out is not None and pub is not None:
            pub.put(json.dumps(out).encode())
    session.close()
