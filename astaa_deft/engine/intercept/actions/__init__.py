"""Interception actions, one module each, found by scanning this package.

``ACTIONS`` maps an XML element name (``set``, ``drop``...) to its
``ActionConfig`` class: the one registry the engine, the test case reader
and the minimiser look actions up in. To add an action, add a module here
defining an ``ActionConfig`` subclass with a ``name``, its runtime, its
flags, its ``ActionDetail`` record and ``pinned`` (see ``base``), and add
its element to ``astaa_deft/data/policies/testcase.xsd``; nothing else
changes (tests/test_intercept_actions.py checks the schema lists exactly
the registered actions).
"""

from __future__ import annotations

import importlib
import pkgutil

from astaa_deft.engine.intercept.actions.base import ActionConfig, ActionRuntime, Delivery
from astaa_deft.model.records import FieldChange, Mutation

__all__ = ["ACTIONS", "ActionConfig", "ActionRuntime", "Delivery", "FieldChange", "Mutation"]


def _discover() -> dict[str, type[ActionConfig]]:
    found: dict[str, type[ActionConfig]] = {}
    for module_info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if module_info.name == "base":
            continue
        module = importlib.import_module(f"{__name__}.{module_info.name}")
        for value in vars(module).values():
            if (isinstance(value, type) and issubclass(value, ActionConfig) and value is not ActionConfig
                    and value.__module__ == module.__name__):
                if value.name in found:
                    raise RuntimeError(f"two actions named {value.name!r}: {found[value.name]} and {value}")
                found[value.name] = value
    return found


ACTIONS: dict[str, type[ActionConfig]] = _discover()
