"""ASTAA test cases: XML files of interception policies, read safely and checked.

* ``model``: the frozen records (``TestCase``, ``Policy``, ``Window``, ``Selection``);
* ``xml_format``: the file format — hostile input refused, lxml with entity
  resolution, DTD loading and network off, the XSD, problems located in the
  source text (``Checker``), and writing (``TestCase.to_xml()``; reading its
  output gives an equal ``TestCase``);
* ``loader``: ``load_testcase`` / ``parse_testcase``, the gates in order, then
  names, field paths and values checked against the spec and the dictionary.
"""

from __future__ import annotations

from astaa_deft.engine.intercept.testcase.loader import ActionChecker, load_testcase, parse_testcase
from astaa_deft.engine.intercept.testcase.model import Policy, Selection, TestCase, Window
from astaa_deft.engine.intercept.testcase.xml_format import MAX_FILE_BYTES, SCHEMA_PATH, Checker, write_testcase

__all__ = [
    "MAX_FILE_BYTES", "SCHEMA_PATH", "ActionChecker", "Checker", "Policy", "Selection", "TestCase", "Window",
    "load_testcase", "parse_testcase", "write_testcase",
]
