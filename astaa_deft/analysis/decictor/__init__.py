"""Decictor on the bus: search for non-optimal planning decisions (Cheng et al., ICSE 2025).

Harmless participants (the ``participant`` interception action) are injected
into the planner's input; a run whose ego path leaves the seed run's lanes
although the seed path was still free is a non-optimal decision.

* ``paths``: the ego path, the feedback distances (path distance, behaviour MMD);
* ``feasible``: the non-invasive placement region and participant generation;
* ``oracle``: task check, seed-path availability, lane-grid path consistency;
* ``config``: the spec's ``decictor:`` section (lanes, ego fields, clearance);
* ``search``: the population search and its random baselines;
* ``observe``: a run's observation read from its log.
"""
