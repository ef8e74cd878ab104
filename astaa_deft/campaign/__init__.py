"""Fuzzing campaigns: many generated test cases, each a fresh run of the SUT, findings bucketed.

One concern per module:

* ``model``: the typed records (a planned case, its outcome, a bucket);
* ``runner``: the one adapter to the rest of the tool that runs a case (a session);
* ``minimiser``: the one adapter that minimises a bucket's first failure;
* ``worker``: a case in its own process (local pool) or on a Dask worker;
* ``executors``: where cases run (a local process pool, or a Dask cluster);
* ``journal``: the SQLite journal, the source of truth for resume, status and report;
* ``signature``: a failure's signature, which groups failures into buckets;
* ``strategies``: how the next test case is drawn (random, guided);
* ``campaign``: the workflow (baseline, cases, buckets, rates, minimisation);
* ``progress``: a live bar on a terminal, plain lines otherwise;
* ``report``: the static HTML report.
"""
