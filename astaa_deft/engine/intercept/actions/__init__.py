"""Interception actions, one module each, each registering itself on ``ACTIONS``.

``ACTIONS`` (a ``model.registry.Registry``) maps an XML element name
(``set``, ``drop``...) to its ``ActionConfig`` class: the one registry the
engine, the test case reader (and its schema) and the minimiser look actions
up in. To add an action, add a module here defining an ``ActionConfig``
subclass decorated with ``@ACTIONS.register_class``, with a ``name``, its
element's XSD type (``schema``), its runtime, its flags, its ``ActionDetail``
record and ``pinned`` (see ``base``); nothing else changes (the test case
schema's Action group is assembled from the registry;
tests/test_extension_points.py adds one from a temporary package).
"""

from __future__ import annotations

from astaa_deft.engine.intercept.actions.base import ACTIONS, ActionConfig, ActionRuntime, Delivery
from astaa_deft.model.records import FieldChange, Mutation

__all__ = ["ACTIONS", "ActionConfig", "ActionRuntime", "Delivery", "FieldChange", "Mutation"]
