"""Signal temporal logic through rtamt: check a formula once, monitor it online.

We do not write a logic engine: rtamt parses the formula and runs its
discrete-time online interpreter. What this module adds:

* the formula is checked before the run, with positions: unknown signal
  names, unbounded future operators, bounds that are not multiples of the
  sampling period, syntax errors;
* the formula must hold at *every* sample (an invariant), so a leading
  unbounded ``always`` is allowed and simply dropped: rtamt's online monitor
  cannot run it, and checking every sample is what it means;
* bounded future operators (``eventually[0:2]``) are turned into past ones
  with a delay (rtamt's "pastification"): the verdict for sample *k* is known
  at sample *k + H*, H being the formula's horizon. rtamt 0.4.10's pastifier
  delays a comparison under a future operator twice and drops a
  ``historically`` it has to delay; ``_Pastifier`` fixes those two visits
  (tests compare it with rtamt's own offline, whole-trace evaluation);
* division, sqrt, exp and pow are refused in formulas: rtamt raises on 1/0
  or sqrt(-1) in the middle of an update, which would leave the monitor in
  an unknown state. Compute such quantities in a signal's ``expr`` instead
  (evaluated per message, IEEE-safe).

rtamt is imported lazily: specs without temporal invariants never load it.
"""

from __future__ import annotations

import functools
import logging
import re
import sys
import types
import typing
import warnings
from dataclasses import dataclass
from fractions import Fraction
from typing import Any
from collections.abc import Sequence

from astaa_deft.model.errors import AstaaDeftError, did_you_mean

SIGNAL_NAME = re.compile(r"^[a-z][a-z0-9_]*\Z")
# Words of rtamt's language a formula may use.
OPERATORS = frozenset({
    "not", "and", "or", "implies", "iff", "xor", "rise", "fall", "abs", "true", "false",
    "always", "eventually", "until", "unless", "historically", "once", "since", "prev", "previous",
    "G", "F", "U", "W", "H", "O", "S", "Y", "TRUE", "FALSE",
})
# Words rtamt reserves that mean nothing in an invariant's formula (declarations, units, next).
RESERVED = frozenset({
    "next", "snext", "sprev", "X", "R", "sqrt", "exp", "pow", "s", "ms", "us", "ns", "ps", "topic", "import",
    "input", "output", "internal", "const", "real", "float", "long", "complex", "int", "bool", "assertion",
    "specification", "from", "A", "B", "E", "N", "P", "T",
})
_TOKENS = re.compile(r"(?P<number>(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)|(?P<name>[A-Za-z_][A-Za-z0-9_]*)"
                     r"|(?P<assign>(?<![=<>!])=(?!=))")
_RTAMT_POSITION = re.compile(r"(\d+):(\d+):\s*(.*)", re.DOTALL)
_REFUSED_ARITHMETIC = {"Division": "'/'", "Sqrt": "sqrt", "Exp": "exp", "Pow": "pow"}


class StlError(AstaaDeftError, ValueError):
    def __init__(self, message: str, position: int = 0, fix: str = ""):
        super().__init__(message)
        self.message = message
        self.position = position
        self.fix = fix


@dataclass(frozen=True)
class StlFormula:
    """A formula checked against its signals and sampling period."""

    text: str
    signals: tuple[str, ...]
    period: Fraction  # seconds
    horizon_samples: int  # how many samples late the verdict of a sample is known

    def online_monitor(self) -> OnlineStl:
        return OnlineStl(self)


def check_formula(text: str, signals: Sequence[str], period: Fraction) -> StlFormula:
    """Validate ``text``; raises StlError with the position of the first problem."""
    _check_names(text, signals)
    spec, horizon = _build(text, signals, period)
    samples = horizon / period
    if samples.denominator != 1:
        raise StlError(f"the formula's horizon ({float(horizon):g} s) is not a whole number of samples",
                       0, "use time bounds that are multiples of 'period'")
    formula = StlFormula(text, tuple(signals), period, int(samples))
    try:  # rtamt checks some things only on the first update (bounds vs. the period)
        spec.update(0, [(name, 0.0) for name in signals])
    except Exception as exc:  # rtamt raises plain Exception subclasses
        raise StlError(_rtamt_message(exc), 0, "use time bounds that are multiples of 'period'") from None
    return formula


def _check_names(text: str, signals: Sequence[str]) -> None:
    known = set(signals)
    for match in _TOKENS.finditer(text):
        if match.lastgroup == "assign":
            raise StlError("'=' is not allowed in a formula", match.start(),
                           "compare with == (the formula is a condition, not an assignment)")
        if match.lastgroup != "name":
            continue
        word = match.group()
        if word in known or word in OPERATORS:
            continue
        if word in RESERVED:
            raise StlError(f"'{word}' is not supported in an invariant's formula", match.start(), _reserved_fix(word))
        hint = did_you_mean(word, list(known)) or f"declare it under 'signals' (declared: {', '.join(signals)})"
        raise StlError(f"unknown signal '{word}'", match.start(), hint)


def _reserved_fix(word: str) -> str:
    if word in ("next", "snext", "X"):
        return "use eventually[P:P](...) with P the sampling period"
    if word in ("s", "ms", "us", "ns", "ps"):
        return "write time bounds in seconds, without a unit: eventually[0:0.5]"
    if word in ("sqrt", "exp", "pow"):
        return "compute the quantity in a signal's expr, which is evaluated safely per message"
    return "declare signals under 'signals'; the formula is a single condition"


@functools.lru_cache(maxsize=1)
def _rtamt() -> Any:
    """Import rtamt, which pins antlr4-python3-runtime 4.7.

    That runtime does ``from typing.io import TextIO``; Python 3.13 removed
    ``typing.io``, so provide it when missing (it only ever held TextIO & co).
    """
    if "typing.io" not in sys.modules:
        shim = types.ModuleType("typing.io")
        shim.TextIO, shim.BinaryIO, shim.IO = typing.TextIO, typing.BinaryIO, typing.IO  # type: ignore[attr-defined]
        sys.modules["typing.io"] = shim
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)  # the same typing.io import, on 3.11/3.12
        import rtamt
    return rtamt


def _build(text: str, signals: Sequence[str], period: Fraction) -> tuple[Any, Fraction]:
    """A parsed, pastified rtamt specification and the formula's horizon in seconds."""
    rtamt = _rtamt()
    from rtamt.pastifier.stl.horizon import StlHorizon
    from rtamt.syntax.node.ltl.always import Always

    spec = rtamt.StlDiscreteTimeSpecification()
    for name in signals:
        spec.declare_var(name, "float")
    spec.spec = text
    spec.set_sampling_period(Fraction(period) * 1000, "ms", 0.5)
    previous_level = logging.root.manager.disable
    logging.disable(logging.WARNING)  # rtamt logs implicit declarations; our own check came first
    try:
        spec.parse()
    except Exception as exc:
        raise _located(exc, text) from None
    finally:
        logging.disable(previous_level)
    if len(spec.ast.specs) != 1:
        raise StlError("give exactly one formula", 0, "combine conditions with 'and'")
    root = spec.ast.specs[0]
    if type(root) is Always:  # "always(phi)" at the top means: phi at every sample
        root = root.children[0]
        spec.ast.specs = [root]
    _refuse_unsafe_arithmetic(root)
    try:
        horizon = Fraction(StlHorizon().visit(root, None))
        spec.ast = _pastifier_class()().pastify(spec.ast)
    except Exception as exc:
        message = _rtamt_message(exc)
        unbounded = re.search(r"unbounded (\w+)", message)
        if unbounded:
            raise StlError(f"an unbounded '{unbounded.group(1)}' cannot be monitored inside the formula", 0,
                           "give it a time bound, e.g. eventually[0:2](...); only a leading 'always' may be "
                           "unbounded") from None
        raise StlError(message, 0, "check the formula's operators") from None
    return spec, horizon


def _refuse_unsafe_arithmetic(node: Any) -> None:
    name = type(node).__name__
    if name in _REFUSED_ARITHMETIC:
        raise StlError(f"{_REFUSED_ARITHMETIC[name]} is not allowed in a formula (it can fail mid-run)", 0,
                       "compute the quantity in a signal's expr, which is evaluated safely per message")
    for child in getattr(node, "children", ()):
        _refuse_unsafe_arithmetic(child)


def _rtamt_message(exc: BaseException) -> str:
    return str(exc).replace("RTAMT Exception:", "").strip()


def _located(exc: BaseException, text: str) -> StlError:
    message = _rtamt_message(exc)
    match = _RTAMT_POSITION.match(message)
    if not match:
        return StlError(f"not a valid formula: {message}", 0, "see docs/monitors.md for the STL syntax")
    line, column, reason = int(match.group(1)), int(match.group(2)), match.group(3).strip()
    offset = sum(len(row) + 1 for row in text.split("\n")[:line - 1]) + column
    reason = re.sub(r"\s*expecting \{.*", "", reason.replace("Syntax ERROR, ", ""), flags=re.DOTALL)
    reason = reason.replace("mismatched input '<EOF>'", "the formula ends too early")
    return StlError(f"not a valid formula: {reason}", offset, "see docs/monitors.md for the STL syntax")


class OnlineStl:
    """rtamt's online monitor of one formula, fed one sample per period.

    ``update`` returns the robustness of the sample ``horizon_samples``
    updates ago (None while fewer samples than that have been given).

    The first sample is given twice, one period apart, and the first
    copy's verdict dropped: the signals held their first values a period
    before sampling began. So ``prev x`` at the first sample is x itself
    (rtamt alone gives +inf there, and ``always(x >= prev x)`` would fail at
    the first sample of any signal), and ``rise``/``fall`` see no edge there.
    """

    def __init__(self, formula: StlFormula):
        self.formula = formula
        self._spec, _ = _build(formula.text, formula.signals, formula.period)
        self._step = float(formula.period)
        self._count = 0

    def update(self, values: Sequence[tuple[str, float]]) -> float | None:
        if self._count == 0:
            self._spec.update(0.0, list(values))  # the held first values, one period before: prev's value
        robustness = self._spec.update((self._count + 1) * self._step, list(values))
        self._count += 1
        return robustness if self._count > self.formula.horizon_samples else None


@functools.lru_cache(maxsize=1)
def _pastifier_class() -> type[Any]:
    """rtamt's pastifier with two visits fixed (see the module docstring); built lazily."""
    from rtamt.pastifier.stl.pastifier import StlPastifier
    from rtamt.semantics.interval.interval import Interval
    from rtamt.syntax.node.ltl.predicate import Predicate
    from rtamt.syntax.node.stl.timed_historically import TimedHistorically
    from rtamt.syntax.node.stl.timed_once import TimedOnce

    class FixedPastifier(StlPastifier):
        def visitPredicate(self, node: Any, *args: Any, **kwargs: Any) -> Any:
            # upstream visits the operands with the *remaining* horizon and then
            # delays the comparison again: a double delay
            own = self.subformula_horizons[node]
            delay = args[0] - own
            left = self.visit(node.children[0], own)
            right = self.visit(node.children[1], own)
            out = Predicate(left, right, node.operator)
            return TimedOnce(out, Interval(delay, delay)) if delay > 0 else out

        def visitTimedHistorically(self, node: Any, *args: Any, **kwargs: Any) -> Any:
            # upstream delays the operand instead of the historically node (dropping it)
            own = self.subformula_horizons[node]
            delay = args[0] - own
            out = TimedHistorically(self.visit(node.children[0], own), Interval(node.begin, node.end))
            return TimedOnce(out, Interval(delay, delay)) if delay > 0 else out

    return FixedPastifier
