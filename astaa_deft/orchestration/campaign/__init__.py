"""Fuzzing campaigns: many generated test cases, each a fresh run of the SUT, findings bucketed.

One concern per module (the case model, the journal and its rows are ``orchestration/journal/``, shared with
``verify``):

* ``payload``: what a pool gets for one case, and the pool interface the campaign drives;
* ``runner``: the one adapter to the rest of the tool that runs a case (a session);
* ``minimiser``: the one adapter that minimises a bucket's first failure;
* ``worker``: a case in its own process (local pool) or on a Dask worker;
* ``executors``: where cases run (a local process pool, or a Dask cluster);
* ``signature``: a failure's signature, which groups failures into buckets;
* ``cost``: what a run costs the machine (CPU of all its processes, CPU waited for, memory);
* ``calibration``: how many runs at once, from those costs and the clean runs' timing (pure);
* ``known``: known baseline findings, and when a case makes one worse (pure);
* ``strategies``: how the next test case is drawn (the ``Strategy`` base class and its hooks; random, guided,
  decictor);
* ``campaign``: the workflow (baseline and calibration, cases, control runs, buckets, minimisation alongside);
* ``progress``: a live bar on a terminal, plain lines otherwise;
* ``report``: the static HTML report.
"""
