"""Names that come from data (a journal, a campaign folder) and become file names or Python identifiers.

A campaign's journal travels — CI artefacts, a colleague's results, a bug
report — so a bucket id read back from it is data, not a name the tool
chose. Where such a name becomes part of a path (``cases/B001.xml``,
``verify/…/B001/``) or of generated Python (``def test_B001_speed(…)``), it
must be one the tool itself would have written: this module's one pattern.
A name that does not match is refused where it is read (``InputError``
naming the file and the row), never repaired, never spliced. Text that is
only shown (an invariant, a culprit) enters generated code as a ``repr``
literal instead (``export.py``), and needs no pattern. Pure.
"""

from __future__ import annotations

import re

from astaa_deft.model.errors import InputError, Problem

# Letters, digits, '_' and '-', starting with a letter, at most 100: a path component that is never '.', '..',
# hidden, absolute, empty or of another folder. The tool writes bucket ids B001, …, case ids c-000001, r-B001-2, …
DATA_NAME_RE = re.compile(r"[A-Za-z][A-Za-z0-9_-]{0,99}")
DATA_NAME_RULE = ("letters, digits, '_' and '-', starting with a letter, at most 100 characters (the tool writes "
                  "B001, c-000001, …)")


def is_data_name(value: object) -> bool:
    """Whether ``value`` is a name the tool would write (``DATA_NAME_RE``, in full)."""
    return isinstance(value, str) and DATA_NAME_RE.fullmatch(value) is not None


def check_data_name(value: object, *, file: str, field: str, fix: str) -> str:
    """``value`` when it is a data name, else InputError naming ``file`` and ``field`` (the row and column)."""
    if is_data_name(value):
        assert isinstance(value, str)
        return value
    shown = repr(value)[:80] + ("…" if len(repr(value)) > 80 else "")
    raise InputError(Problem(file, None, None, f"{field} is {shown}: a name that becomes a file name must be "
                             f"{DATA_NAME_RULE}", fix))


def python_name(name: str) -> str:
    """A data name as the tail of a Python identifier ('-' → '_'; the rest of the pattern is already one)."""
    assert is_data_name(name), name
    return name.replace("-", "_")
