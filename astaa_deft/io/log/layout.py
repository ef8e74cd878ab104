"""Names inside a test log, in one place so writer and readers agree.

A bus message is logged on a topic equal to its Zenoh key; everything the
tool adds lives under ``/astaa/``.
"""

EVENTS_TOPIC = "/astaa/events"  # process exits, undeclared keys, run start/stop, later mutations and verdicts
FLAGS_TOPIC = "/astaa/flags"  # a bus message the recorder could not decode (logged raw on its own topic)
ORIGINAL_PREFIX = "/astaa/original/"  # the message before a mutation, by key
MUTATIONS_TOPIC = "/astaa/mutations"  # what the interceptor did: test case, policy, action, fields, old → new
# The reason of the run_end event a recorder writes when its tool died mid-run: no verdict may be a Pass.
TOOL_LOST = "tool lost: the tool stopped without ending the run, which was not observed to its end"

SPEC_ATTACHMENT = "spec.yaml"
POLICY_ATTACHMENT = "policy.xml"  # the ASTAA test case applied during the run, if any
DICTIONARY_ATTACHMENT = "dictionary-{n}.yaml"  # user dictionaries on top of the default one
RUN_METADATA = "astaa-deft.run"
PROFILE = "astaa-deft"

EVENT_SCHEMA = {
    "type": "object",
    "title": "astaa_deft.Event",
    "properties": {
        "kind": {"type": "string"},
        "time_ns": {"type": "integer"},
    },
    "required": ["kind"],
}
