"""The spec a run was recorded with, read back from the log it is attached to.

The recorder attaches the spec's own text (``layout.SPEC_ATTACHMENT``), so a
log is judged, replayed and minimised against the spec it ran under. That
text is data from whoever recorded the log: loading it runs nothing (what it
would run is :mod:`astaa_deft.engine.spec.executes`' concern).
"""

from __future__ import annotations

from astaa_deft.engine.spec.loader import load_spec_text
from astaa_deft.io.log import layout
from astaa_deft.io.log.reader import LogContents
from astaa_deft.io.yamlsource import decode_utf8
from astaa_deft.model.errors import InputError, Problem
from astaa_deft.model.sut import Spec


def spec_from_log(log: LogContents, name: str) -> Spec | None:
    """The spec the run was recorded with (attached to the log), or None when the log holds none.

    ``name`` names the attachment in messages. Raises InputError listing the spec's problems and one more
    naming the log, when the stored spec does not load.
    """
    data = log.attachments.get(layout.SPEC_ATTACHMENT)
    if data is None:
        return None
    try:
        return load_spec_text(decode_utf8(data, name), name=name)
    except InputError as exc:
        raise InputError(exc.problems + [Problem(str(log.path), None, None, "the spec stored in the log is unreadable",
                                                 "give the SUT spec with --spec sut.yaml")]) from None
