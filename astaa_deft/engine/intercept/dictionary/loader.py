"""Loading dictionaries: the default file merged with the user's, in order."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from astaa_deft.io.inputfile import DICTIONARY
from astaa_deft.io.yamlsource import Source
from astaa_deft.engine.intercept.dictionary.model import Dictionary, Entry
from astaa_deft.engine.intercept.dictionary.yaml_format import DictionaryFile

DEFAULT_DICTIONARY = Path(__file__).resolve().parents[3] / "data" / "dictionaries" / "default.yaml"


def load_dictionary(files: Sequence[Path | str] = (), *, include_default: bool = True) -> Dictionary:
    """The default dictionary (unless excluded) merged with ``files`` in order.

    A later entry with the same ``group.name`` replaces the earlier one;
    ``{remove: true}`` deletes it. All problems of a file are reported together.
    """
    paths = ([DEFAULT_DICTIONARY] if include_default else []) + [Path(f) for f in files]
    merged: dict[str, Entry] = {}
    for path in paths:
        _merge(merged, DictionaryFile(Source.from_file(path, DICTIONARY)).read())
    return Dictionary(merged.values(), [str(p) for p in paths])


def dictionary_from_text(text: str, name: str = "<dictionary>", *, include_default: bool = True) -> Dictionary:
    """Like ``load_dictionary`` with one more file given as text (tests, tools)."""
    base = load_dictionary() if include_default else Dictionary(())
    merged = dict(base.entries)
    _merge(merged, DictionaryFile(Source(text, name)).read())
    return Dictionary(merged.values(), base.sources + (name,))


def _merge(merged: dict[str, Entry], read: list[tuple[str, Entry | None]]) -> None:
    for key, entry in read:
        if entry is None:
            merged.pop(key, None)
        else:
            merged[key] = entry
