"""A campaign's findings against the stack as it is now: ``astaa-deft verify``, ``export``, ``verify --bisect``.

- what a check is, its rows in the journal's ``verifications`` table and each bucket's history live in
  ``orchestration/journal/`` (``checks.py``, ``verifications.py``, ``history.py``): the campaign reads them too;
- ``revision.py``: the stack's revision (``git describe`` of the spec's ``source:`` folder);
- ``workflow.py``: ``verify_campaign`` — every bucket's minimal test case live, beside unmutated twins,
  and its module tests;
- ``bisect.py``: the first revision where a bucket starts or stops failing;
- ``export.py``: the campaign's findings as a pytest suite for the stack's own CI (``regress/``).
"""
