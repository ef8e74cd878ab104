"""Param values given on the command line, checked against the spec's declared choices.

A spec declares a param as ``name: value`` (any value goes) or
``name: {default: value, choices: [value, …]}``; a value given for a param
with choices (``--param``, ``fuzz --params``) must be one of them.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

from astaa_deft.model.errors import InputError, Problem
from astaa_deft.model.sut import Spec


def check_param_values(spec: Spec, values: Mapping[str, Iterable[str]], source: str) -> None:
    """Every value given for a param with declared choices is one of them.

    ``values``: the values given per param name; ``source``: the option they
    came from (``--param``), named in the problems. Raises InputError with
    one problem per value outside its param's choices.
    """
    problems = []
    declared_in = str(spec.path or spec.name)
    for name, given in values.items():
        choices = spec.param_choices.get(name)
        if choices is None:
            continue
        for value in given:
            if value not in choices:
                problems.append(Problem(source, None, None,
                                        f"param '{name}' is '{value}', not one of the choices {declared_in} declares",
                                        f"use one of: {', '.join(choices)}"))
    if problems:
        raise InputError(problems)


def spread_choices(spec: Spec, given: Mapping[str, list[str]]) -> dict[str, list[str]]:
    """The values a campaign spreads its cases over: those ``given`` per param, and for every other param
    with declared choices, all its choices."""
    return {**{name: list(choices) for name, choices in spec.param_choices.items()}, **given}
