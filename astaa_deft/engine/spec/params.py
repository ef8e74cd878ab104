"""Param values given on the command line, checked against the spec's declared params and choices.

A spec declares a param as ``name: value`` (any value goes) or
``name: {default: value, choices: [value, …]}``; a value given for a param
with choices (``--param``, ``fuzz --params``) must be one of them, and a
name the spec does not declare is refused (it would change nothing). A
campaign's grid — every combination of the values it spreads over — is at
most ``MAX_GRID`` combinations: each gets its own clean runs.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

from astaa_deft.model.errors import InputError, Problem, did_you_mean
from astaa_deft.model.sut import Spec

MAX_GRID = 1000  # combinations of param values a campaign spreads its cases over (each gets --baseline runs)


def check_param_values(spec: Spec, values: Mapping[str, Iterable[str]], source: str) -> None:
    """Every value given for a param with declared choices is one of them.

    ``values``: the values given per param name; ``source``: the option they
    came from (``--param``), named in the problems. Raises InputError with
    one problem per value outside its param's choices.
    """
    problems = []
    declared_in = str(spec.path or spec.name)
    for name, given in values.items():
        if name not in spec.params:
            declared = ", ".join(sorted(spec.params)) or "none"
            problems.append(Problem(source, None, None, f"param '{name}' is not declared in {declared_in}"
                                    f"{did_you_mean(name, spec.params)}",
                                    f"give a param the spec declares under 'params:' (declared: {declared}), "
                                    "or declare it there"))
            continue
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


def check_grid(values: Mapping[str, list[str]], source: str) -> None:
    """InputError when the combinations of ``values`` (name → values) exceed ``MAX_GRID``."""
    size = 1
    for given in values.values():
        size *= max(1, len(given))
        if size > MAX_GRID:
            counts = " × ".join(f"{len(v)} ({n})" for n, v in values.items())
            raise InputError(Problem(source, None, None, f"the param grid has more than {MAX_GRID:,} combinations: "
                                     f"{counts}", f"give fewer values (at most {MAX_GRID:,} combinations: each gets "
                                     "its own clean runs), or run several campaigns"))
