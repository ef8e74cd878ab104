"""The command line's parser class: help that states defaults, and usage errors that name the closest match.

``argparse`` alone says "unrecognized arguments: --budjet" or "invalid choice:
'cut_in' (choose from 'run')" — the second when a mistyped option of a
command with actions (`demo --scenaro cut_in`) leaves its value to be read as
an action. :class:`Parser` says which option or command was meant instead
(``difflib``'s closest match, the same one ``git`` and ``pip`` offer), and
its help lists every option's default. Every subparser of a :class:`Parser`
is one too (argparse builds subparsers with the parent's class), and gets
its one-line ``help`` as its ``description`` when it has none.
"""

from __future__ import annotations

import argparse
import difflib
import re
import sys
from collections.abc import Iterable, Sequence
from typing import Any, NoReturn

_INVALID_CHOICE = re.compile(r"invalid choice: '([^']*)'")


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Keeps the epilog's example lines as written, and appends each option's default unless its help says it."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        default = action.default
        if (action.option_strings and default not in (None, False, [], argparse.SUPPRESS)
                and "default" not in text.lower() and not isinstance(action, argparse._VersionAction)):
            text += " (default: %(default)s)"
        return text


class _Commands(argparse._SubParsersAction):
    """Subcommands whose ``help=`` line is also their own ``--help``'s description."""

    def add_parser(self, name: str, **kwargs: Any) -> argparse.ArgumentParser:
        if "help" in kwargs and "description" not in kwargs:
            kwargs["description"] = kwargs["help"][:1].upper() + kwargs["help"][1:] + "."
        kwargs.setdefault("formatter_class", HelpFormatter)
        return super().add_parser(name, **kwargs)


def closest(word: str, candidates: Iterable[str]) -> str | None:
    """The candidate most like ``word`` (difflib's ratio ≥ 0.6), or None."""
    found = difflib.get_close_matches(word, list(candidates), n=1, cutoff=0.6)
    return found[0] if found else None


class Parser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose usage errors name the closest option or command (see the module's doc)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", HelpFormatter)
        super().__init__(*args, **kwargs)
        self.register("action", "parsers", _Commands)
        self._arg_strings: list[str] = []

    def parse_known_args(self, args: Sequence[str] | None = None,  # type: ignore[override]
                         namespace: argparse.Namespace | None = None) -> tuple[argparse.Namespace, list[str]]:
        self._arg_strings = list(sys.argv[1:] if args is None else args)
        parsed, extras = super().parse_known_args(args, namespace)
        unknown = [a for a in extras if a.startswith("-") and a != "-"]
        if unknown:
            # The innermost command reports the mistyped option first, with its own usage line and options.
            self.error(self._unknown_option_message(unknown[0]))
        return parsed, extras

    def error(self, message: str) -> NoReturn:
        invalid = _INVALID_CHOICE.search(message)
        if invalid:
            flag = self._unknown_option_before(invalid.group(1))
            if flag:  # `demo --scenaro cut_in`: the mistyped option is the news, not 'cut_in' as an action
                message = self._unknown_option_message(flag)
            else:
                message += self._choice_hint(invalid.group(1))
        super().error(message)

    def _option_strings(self) -> list[str]:
        return [s for a in self._actions for s in a.option_strings]

    def _unknown_option_before(self, word: str) -> str | None:
        """The unknown option just before ``word`` on the command line (whose value ``word`` was meant to be)."""
        if word not in self._arg_strings:
            return None
        before = self._arg_strings[:self._arg_strings.index(word)]
        if not before or not before[-1].startswith("-") or "=" in before[-1] or "--" in before:
            return None
        # A known option's prefix (argparse's abbreviation) is not unknown.
        return None if any(k.startswith(before[-1]) for k in self._option_strings()) else before[-1]

    def _unknown_option_message(self, text: str) -> str:
        flag = text.split("=", 1)[0]
        near = closest(flag, (s for s in self._option_strings() if s.startswith("--")))
        hint = f"; did you mean {near}?" if near else f"; {self.prog} --help lists the options"
        return f"unrecognized option {flag}{hint}"

    def _choice_hint(self, word: str) -> str:
        names: list[str] = []
        for action in self._actions:
            if action.choices is not None:
                names.extend(str(c) for c in action.choices)
        near = closest(word, names)
        return f"; did you mean '{near}'?" if near else ""
