"""ASTAA interception: test cases of policies that rewrite live bus messages.

* ``dictionary``: exceptional values per declared type (``dict:GROUP.NAME``);
* ``testcase``: the XML test case format, read safely and checked;
* ``actions``: one module per action (set, drop, delay, ...);
* ``engine``: the ``Interceptor`` the proxy feeds messages through;
* ``generate``: test cases drawn from a spec and the dictionary.
"""

from __future__ import annotations

from astaa_deft.engine.intercept.actions.base import Delivery
from astaa_deft.model.records import FieldChange, Mutation
from astaa_deft.engine.intercept.dictionary import Dictionary, load_dictionary
from astaa_deft.engine.intercept.engine import Interceptor, load_interceptor
from astaa_deft.engine.intercept.testcase import Policy, Selection, TestCase, Window, load_testcase, parse_testcase

__all__ = [
    "Delivery", "Dictionary", "FieldChange", "Interceptor", "Mutation", "Policy", "Selection",
    "TestCase", "Window", "load_dictionary", "load_interceptor", "load_testcase", "parse_testcase",
]
