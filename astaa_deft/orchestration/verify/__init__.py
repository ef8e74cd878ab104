"""A campaign's findings against the stack as it is now: ``astaa-deft verify``, ``export``, ``verify --bisect``.

- ``model.py``: what one bucket's check is and how its runs classify it (fixed, still failing, changed,
  flaky, not observed), pure;
- ``records.py``: the journal's ``verifications`` table (additive: the campaign's tables are untouched);
- ``history.py``: each bucket's history from those rows (found on, fixed on, reopened), pure;
- ``revision.py``: the stack's revision (``git describe`` of the spec's ``source:`` folder);
- ``workflow.py``: ``verify_campaign`` — every bucket's minimal test case live, beside unmutated twins,
  and its module tests;
- ``bisect.py``: the first revision where a bucket starts or stops failing;
- ``export.py``: the campaign's findings as a pytest suite for the stack's own CI (``regress/``).
"""
