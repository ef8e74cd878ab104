"""Reading a SUT spec (YAML): one module per top-level section, the loader orders them.

Entry points: ``loader.load_spec(path)`` and ``loader.load_spec_text(text)``
return a validated ``model.sut.Spec`` or raise one InputError listing every
problem (file, line, column, fix).

Where each section is read:

- ``name``, the top-level keys, the order of sections — ``loader.py``
- ``params:`` — ``params_section.py``; values given on the command line
  (``--param``, ``fuzz --params``) checked against it — ``params.py``
- ``zenoh:`` — ``zenoh_section.py``
- ``modules:`` — ``modules_section.py``
- ``channels:`` — ``channels_section.py`` (a channel's ``time:`` and ``pair_by:``
  too); ``encoding: cdr`` channels and
  ``ros2:`` — ``ros2_section.py``
- ``types:`` and ``brittle:`` — ``types_section.py``
- ``invariants:`` — ``engine/monitor/invariants.py`` (each monitor kind
  parses its own entry through ``engine/monitor/spec_reader.py``)
- ``planner:`` — ``planner.py``; ``replay:`` — ``replay_section.py``; both
  load into ``replay_module.ReplayModule``
- ``run:`` — ``run_section.py``
- ``decictor:`` — ``decictor_section.py``
- ``liveliness:`` — ``liveliness_section.py``
- ``source:`` (the stack's git checkout, for ``verify``) — ``source_section.py``

The checks every section shares are ``reader.SpecReader``'s; what a loaded
spec would run (and the refusal to run a spec stored in a log) is
``executes.py``.
"""
