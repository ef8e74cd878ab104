"""The campaign's journal: one SQLite file a campaign writes and ``verify``, ``report`` and ``--resume`` read.

Below both ``orchestration/campaign`` and ``orchestration/verify`` (contract
``verify > campaign > journal`` in ``pyproject.toml``): what the journal
stores is defined here, once, so a campaign reads its verifications and a
verify writes them without the two importing each other.

One concern per module:

* ``model``: what a case is and what its run gave (a planned case, its outcome, a bucket's signature, the
  vocabularies as enums), pure;
* ``rows``: the journal's typed rows (a case, a bucket, a minimisation, module tests, a note, a blame, the
  settings), pure;
* ``checked_rows``: each row read back schema-checked (a damaged journal is one ``InputError``);
* ``journal``: the SQLite journal itself, the source of truth for resume, status and report;
* ``checks``: one bucket checked against a revision of the stack, and how its runs classify it, pure;
* ``verifications``: the journal's ``verifications`` table (additive: the campaign's tables are untouched);
* ``history``: each bucket's history from those rows (found on, fixed on, reopened), pure.
"""
