"""The journal's rows and settings read back schema-checked: typed rows, or one ``InputError`` (exit 2).

SQLite keeps whatever was written, whatever a column declares: a journal
edited by hand (or damaged) may hold text in ``buckets.reruns``, a case
outcome nested 100,000 deep or a meta value that is not JSON. Each row the
journal reads passes here (``io/statefile.py`` does the checking): every
column of the row's type and range, every JSON cell parsed within the
size and depth caps and its fields checked, vocabularies (case kind and
status, bucket kind) read into their enums. A mismatch names the journal
file and the field (``buckets[B001].reruns``) and says what to do; the
report, ``fuzz --status`` and ``fuzz --resume`` exit 2 on it, never with a
traceback. ``check_columns``: a journal whose tables lack columns this
version needs is damaged input (exit 2), not an unwritable place.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
import hashlib
import json
import sqlite3
from collections.abc import Callable, Iterable, Mapping
from typing import Any

from astaa_deft.io.statefile import MAX_INT, MAX_NAME, StateReader, load_json
from astaa_deft.model.data_names import DATA_NAME_RULE, is_data_name
from astaa_deft.model.errors import InputError, Problem
from astaa_deft.model.limits import MAX_PROCESSES, MAX_WINDOW_S
from astaa_deft.model.json import JsonObject
from astaa_deft.model.vocabulary import TextEnum
from astaa_deft.orchestration.journal.model import BucketKind, CaseKind, CaseOutcome, CaseStatus, Finding
from astaa_deft.orchestration.journal.rows import (
    BlameRow, Bucket, CampaignMeta, CaseRow, MinimisationRow, ModuleTestsRow, NoteRow,
)

FIX = "move the damaged journal away (or restore it from a copy), or give another campaign directory (-o)"
MAX_CELL = 1 << 20  # characters of one text cell (a minimal XML, a summary): far above real ones
MAX_JSON_CELL = 16 << 20  # characters of one JSON cell (a case outcome)
CORE_TABLES = ("meta", "cases", "buckets")  # in every journal since the first
MAX_SECONDS = 1e11  # an epoch time or a duration in seconds (year 5138): beyond, the cell is damaged
MAX_VERDICT = 100  # characters of a verdict (a CRASH class name)
MAX_LABEL = 10_000  # characters of a stack revision (verify --label, git describe): the writer checks it too
MAX_PARAM = 10_000  # characters of a param's value: the writer checks it too
MAX_BUCKETS = 10_000  # buckets one journal may hold: a real campaign files tens; beyond, the journal is damaged

Read = Callable[[StateReader], Any]


@dataclass(frozen=True)
class Table:
    """A journal table as its rows are read: its name, the column that names a row in messages (None: none
    does), and each column's reader."""

    name: str
    key_column: str | None
    columns: Mapping[str, Read]


def _quick(read: Read, accepts: Callable[[Any], bool]) -> Read:
    """``read`` with a quick test of the plain values it takes as they are (the common case: no reader made)."""
    read.accepts = accepts  # type: ignore[attr-defined]
    return read


def _text(optional: bool = False, max_chars: int = MAX_CELL) -> Read:
    return _quick(lambda r: r.text(max_chars, optional=optional),
                  lambda v: (type(v) is str and len(v) <= max_chars) or (optional and v is None))


def _name(optional: bool = False) -> Read:
    """A bucket or case id: it becomes a file name (``verify``'s runs, ``export``'s cases) and part of generated
    Python, so it must be a name the tool writes (model/data_names.py), never repaired."""
    def read(r: StateReader) -> str | None:
        if optional and r.value is None:
            return None
        if not is_data_name(r.value):
            r.fail(f"is {str(r.value)[:60]!r}: a name that becomes a file name must be {DATA_NAME_RULE}")
        return str(r.value)
    return _quick(read, lambda v: is_data_name(v) or (optional and v is None))


def _integer(optional: bool = False, low: int = 0, high: int = MAX_INT) -> Read:
    return _quick(lambda r: r.integer(low, high, optional=optional),
                  lambda v: (type(v) is int and low <= v <= high) or (optional and v is None))


def _signed(optional: bool = False) -> Read:
    return _integer(optional, -(2**63))


def _number(optional: bool = False, low: float = 0.0, high: float = 1e11) -> Read:
    """A finite number in [low, high]; by default an epoch time or a duration in seconds (never negative;
    beyond year 5138 the cell is damaged)."""
    return _quick(lambda r: r.number(low, high, optional=optional),
                  lambda v: (type(v) in (int, float) and low <= v <= high) or (optional and v is None))


def _flag(optional: bool = False) -> Read:
    return lambda r: r.flag(optional=optional, numeric=True)


def _enum(kind: type[TextEnum]) -> Read:
    names = tuple(str(member) for member in kind)
    members = {str(member): member for member in kind}

    def read(r: StateReader) -> TextEnum:
        member = members.get(r.value) if type(r.value) is str else None
        return member if member is not None else kind(r.string(100, choices=names))
    return read


def _json(read: Read) -> Read:
    def parse(r: StateReader) -> Any:
        text = r.string(MAX_JSON_CELL)
        return read(StateReader(r.file, load_json(text, r.file, r.field, r.fix, max_chars=MAX_JSON_CELL), r.fix,
                                field=r.field))
    return parse


def _params(r: StateReader) -> dict[str, str]:
    return r.map(lambda v: v.string(MAX_PARAM), max_items=10_000)


def _params_cell(r: StateReader) -> dict[str, str]:
    """The ``params`` cell: a JSON object of texts (checked field by field only when the quick look fails)."""
    if type(r.value) is str and len(r.value) <= 100_000 and r.value.startswith("{"):
        try:
            value = json.loads(r.value)
        except (ValueError, RecursionError):
            value = None
        if type(value) is dict and len(value) <= 10_000 and all(
                type(v) is str and len(v) <= MAX_PARAM and len(k) <= MAX_NAME for k, v in value.items()):
            return value
    return _json(_params)(r)


_CHECKED_OUTCOMES: set[bytes] = set()  # digests of outcome texts already checked (a journal is read often)
_CHECKED_MOST = 200_000


def _outcome_text(r: StateReader) -> str | None:
    """The ``outcome`` cell: checked (parsed, every field CaseOutcome reads), kept as its text."""
    if r.value is None:
        return None
    text = r.string(MAX_JSON_CELL)
    digest = hashlib.blake2b(text.encode("utf-8", "surrogatepass"), digest_size=16).digest()
    if digest not in _CHECKED_OUTCOMES:
        _json(_outcome)(r)
        if len(_CHECKED_OUTCOMES) >= _CHECKED_MOST:
            _CHECKED_OUTCOMES.clear()
        _CHECKED_OUTCOMES.add(digest)
    return text


def _finding(r: StateReader) -> JsonObject:
    r.obj()
    known = Finding.__dataclass_fields__
    for name, value in r.entries(100):
        if name not in known:
            value.fail("is not a field of a finding this version knows")
        read = _FINDING.get(name)
        if read is not None:
            read(value)
        elif isinstance(value.value, (list, dict)):
            value.fail("must be a plain value")
    for name, declared in known.items():
        if declared.default is dataclasses.MISSING and declared.default_factory is dataclasses.MISSING \
                and not r.has(name):
            r.get(name).fail("is missing")
    return dict(r.json_object())


_FINDING: dict[str, Read] = {
    "invariant": _text(max_chars=1000), "crash": _text(max_chars=MAX_VERDICT), "module": _text(True, 1000),
    "channel": _text(True, 1000),
    "detail": _text(), "severity": _text(), "at": lambda r: r.number(infinite=True, optional=True),
}


def _only(r: StateReader, names: tuple[str, ...]) -> None:
    for name, value in r.obj().entries(100):
        if name not in names:
            value.fail("is not a field this version knows")


def _channel_rate(r: StateReader) -> None:
    _only(r, ("count", "rate", "max_gap"))
    count, rate, max_gap = r.fields("count", "rate", "max_gap")
    count.whole()
    rate.real(0.0, infinite=True)
    max_gap.real(0.0, infinite=True)


_OUTCOME: dict[str, Read] = {
    "status": _text(max_chars=100), "verdict": _text(max_chars=MAX_VERDICT), "summary": _text(),
    "findings": lambda r: r.each(_finding, 100_000),
    "seconds": lambda r: r.real(0.0, MAX_SECONDS), "log_path": _text(True), "reason": _text(),
    "mutations": _integer(),
    "margins": lambda r: r.map(lambda v: v.real(infinite=True), 100_000), "error": _text(),
    "first_seen": lambda r: r.map(lambda v: v.real(infinite=True), 100_000),
    "cpu": lambda r: r.real(0.0, MAX_SECONDS), "cpu_waited": lambda r: r.real(0.0, MAX_SECONDS),
    "wall": lambda r: r.real(0.0, MAX_SECONDS), "rss_mb": lambda r: r.real(0.0, MAX_SECONDS),
    "timing": lambda r: r.map(_channel_rate, 100_000), "violating": lambda r: r.map(lambda v: v.whole(), 100_000),
    "shutdowns": lambda r: r.map(lambda v: v.real(0.0, MAX_SECONDS), 10_000),
}


def _outcome(r: StateReader) -> CaseOutcome:
    r.obj()
    for name in ("status", "verdict", "summary"):
        if not r.has(name):
            r.get(name).fail("is missing")
    for name, read in _OUTCOME.items():
        if r.has(name):
            read(r.get(name))
    return CaseOutcome.from_json(r.json_object())


CASE_COLUMNS: dict[str, Read] = {
    "case_id": _name(), "kind": _enum(CaseKind), "number": _integer(), "seed": _signed(),
    "params": _params_cell, "testcase_xml": _text(True, 64 << 20), "strategy": _text(max_chars=1000),
    "parent": _name(True), "status": _enum(CaseStatus), "verdict": _text(True, MAX_VERDICT),
    "summary": _text(True),
    "signature": _text(True), "failure_key": _text(True), "bucket": _name(True), "outcome": _outcome_text,
    "planned_at": _number(True), "started_at": _number(True), "finished_at": _number(True),
    "seconds": _number(True), "log_path": _text(True), "worker": _text(True), "cpu": _number(True),
    "load": _number(True), "at_once": _integer(True),
}
BUCKET_COLUMNS: dict[str, Read] = {
    "bucket": _name(), "signature": _text(), "verdict": _text(max_chars=MAX_VERDICT),
    "invariant": _text(max_chars=1000),
    "module": _text(True, 1000), "family": _text(), "first_case": _name(), "without_mutation": _flag(),
    "cases": _integer(), "reruns": _integer(), "rerun_failures": _integer(), "merged_into": _name(True),
    "created_at": _number(), "created_after_cases": _integer(), "kind": _enum(BucketKind), "controls": _integer(),
    "control_failures": _integer(),
}
MINIMISATION_COLUMNS: dict[str, Read] = {
    "bucket": _name(), "status": _text(), "exit_code": _signed(True),
    "minimal_xml": _text(True, 64 << 20), "culprit": _text(True), "out_dir": _text(True), "tests_dir": _text(True),
    "seconds": _number(True), "detail": _text(True), "started_at": _number(True), "finished_at": _number(True),
}
MODULE_TESTS_COLUMNS: dict[str, Read] = {
    "bucket": _name(), "tests_dir": _text(), "fails_on_defect": _flag(True), "detail": _text(),
}
NOTE_COLUMNS: dict[str, Read] = {"time": _number(), "topic": _text(), "text": _text()}

BLAME_COLUMNS: dict[str, Read] = {
    "bucket": _name(), "module": _text(True, 1000), "output": _text(True), "how": _text(),
    "chain": _text(), "detail": _text(), "twins": _integer(), "identity": _text(True), "replay": _text(True),
}

VERIFICATION_COLUMNS: dict[str, Read] = {
    "id": _integer(), "bucket": _name(), "revision": _text(max_chars=MAX_LABEL),
    "status": _text(max_chars=100), "failing": _integer(), "runs": _integer(), "other": _integer(),
    "unobserved": _integer(), "twin_failures": _integer(), "twins": _integer(), "module_tests": _flag(True),
    "detail": _text(), "params": _params_cell, "at": _number(),
}
VERIFICATIONS = Table("verifications", "bucket", VERIFICATION_COLUMNS)
_MINIMISATIONS = Table("minimisations", "bucket", MINIMISATION_COLUMNS)
_MODULE_TESTS = Table("module_tests", "bucket", MODULE_TESTS_COLUMNS)
_BLAMES = Table("blames", "bucket", BLAME_COLUMNS)


def _read(file: str, row: sqlite3.Row | Mapping[str, object], table: Table) -> dict[str, Any]:
    """Each column of ``row`` read by its reader (columns this module does not know are passed as they are)."""
    fields = dict(row)
    out: dict[str, Any] = {}
    for name, value in fields.items():
        read = table.columns.get(name)
        accepts = getattr(read, "accepts", None)
        if read is None or (accepts is not None and accepts(value)):
            out[name] = value
            continue
        key = fields.get(table.key_column) if table.key_column else None
        out[name] = read(StateReader(file, value, FIX,
                                     field=f"{table.name}[{str(key)[:60] if key is not None else '?'}].{name}"))
    return out


def _known(kind: type, values: Mapping[str, Any]) -> dict[str, Any]:
    fields = _FIELDS.get(kind)
    if fields is None:
        fields = _FIELDS[kind] = frozenset(f.name for f in dataclasses.fields(kind))
    return {k: v for k, v in values.items() if k in fields}


_FIELDS: dict[type, frozenset[str]] = {}


def case_row(file: str, row: sqlite3.Row) -> CaseRow:
    fields = _read(file, row, Table("cases", "case_id", CASE_COLUMNS))
    fields["outcome_json"] = fields.pop("outcome", None)
    return CaseRow(**_known(CaseRow, fields))


def bucket_row(file: str, row: sqlite3.Row) -> Bucket:
    fields = _read(file, row, Table("buckets", "bucket", BUCKET_COLUMNS))
    return Bucket(**_known(Bucket, fields))


def minimisation_row(file: str, row: sqlite3.Row) -> MinimisationRow:
    return MinimisationRow(**_known(MinimisationRow, _read(file, row, _MINIMISATIONS)))


def module_tests_row(file: str, row: sqlite3.Row) -> ModuleTestsRow:
    return ModuleTestsRow(**_known(ModuleTestsRow, _read(file, row, _MODULE_TESTS)))


def blame_row(file: str, row: sqlite3.Row) -> BlameRow:
    return BlameRow(**_known(BlameRow, _read(file, row, _BLAMES)))


class CheckedRow:
    """A row whose columns its readers checked: each column read back as the type its reader gives."""

    __slots__ = ("_values",)

    def __init__(self, values: Mapping[str, object]) -> None:
        self._values = values

    def text(self, column: str) -> str:
        value = self._values[column]
        assert isinstance(value, str), column  # a text column's reader gives text
        return value

    def whole(self, column: str) -> int:
        value = self._values[column]
        assert isinstance(value, int) and not isinstance(value, bool), column
        return value

    def number(self, column: str) -> float:
        value = self._values[column]
        assert isinstance(value, (int, float)) and not isinstance(value, bool), column
        return float(value)

    def flag(self, column: str) -> bool | None:
        value = self._values[column]
        assert value is None or isinstance(value, bool), column  # an optional flag column's reader
        return value


def checked_columns(file: str, row: sqlite3.Row, table: Table) -> CheckedRow:
    """A row of a table another module owns (``verifications``) read by its columns' readers."""
    return CheckedRow(_read(file, row, table))


def note_row(file: str, row: sqlite3.Row) -> NoteRow:
    return NoteRow(**_known(NoteRow, _read(file, row, Table("notes", None, NOTE_COLUMNS))))


def _timing(r: StateReader) -> Any:
    if r.value is None:
        return None
    _only(r, ("anchor", "live"))
    anchor, live = r.fields("anchor", "live")
    anchor.text(1000, optional=True)
    live.real(0.0)
    return r.value


META_KEYS: dict[str, Read] = {
    "spec": _text(True), "seed": _signed(True), "strategy": _text(True),
    "params": lambda r: None if r.value is None else r.map(lambda v: v.each(lambda i: i.string(10_000), 100_000),
                                                           10_000),
    "horizon": lambda r: r.number(0.0, MAX_WINDOW_S, optional=True), "cases": _integer(True),
    "budget": lambda r: r.number(0.0, optional=True), "calibrated": lambda r: r.flag(optional=True),
    "workers": _integer(True, 1, MAX_PROCESSES), "timing": _timing,
    "overloaded_runs": lambda r: r.each(lambda i: i.string(1000), 10_000_000),
}


def meta_of(file: str, rows: Iterable[sqlite3.Row]) -> CampaignMeta:
    """The campaign's settings from the meta table's (key, JSON text) rows."""
    values: dict[str, Any] = {}
    for row in rows:
        key, text = row["key"], row["value"]
        field = f"meta[{str(key)[:60]}]"
        r = StateReader(file, text, FIX, field=field)
        r.string(MAX_JSON_CELL)
        value = load_json(text, file, field, FIX, max_chars=MAX_JSON_CELL)
        read = META_KEYS.get(str(key))
        if read is not None:
            read(StateReader(file, value, FIX, field=field))
        values[str(key)] = value
    for optional in ("calibrated", "overloaded_runs"):  # null as absent: the record's default
        if values.get(optional) is None:
            values.pop(optional, None)
    return CampaignMeta.from_json(values)


def check_columns(db: sqlite3.Connection, file: str, schema: str, added: Mapping[str, Iterable[tuple[str, str]]]
                  ) -> None:
    """InputError when a table the journal already has lacks a column ``schema`` declares (other than the
    ``added`` ones, which an older journal gains when it is opened): a damaged journal, not a new one."""
    model = sqlite3.connect(":memory:")
    try:
        model.executescript(schema)
        tables = [r[0] for r in model.execute("SELECT name FROM sqlite_master WHERE type='table'")]
        declared = {t: [r[1] for r in model.execute(f"PRAGMA table_info({t})")] for t in tables}
    finally:
        model.close()
    quick = db.execute("PRAGMA quick_check").fetchone()  # pages cut off or overwritten: damaged, not empty
    if quick is None or quick[0] != "ok":
        raise InputError(Problem(file, None, None, f"the journal is damaged ({str(quick[0] if quick else '?')[:200]})",
                                 FIX))
    present = {t for t in declared if db.execute(f"PRAGMA table_info({t})").fetchone() is not None}
    lost = [t for t in CORE_TABLES if t not in present]
    if present and lost:  # a journal lacking the tables every journal has had: they were removed
        raise InputError(Problem(file, None, None, f"the journal has no table {', '.join(repr(t) for t in lost)}: it "
                                 "is damaged, or not a campaign journal", FIX))
    for table, columns in declared.items():
        have = {r[1] for r in db.execute(f"PRAGMA table_info({table})")}
        if not have:
            continue  # not there yet: created as declared
        later = {name for name, _ in added.get(table, ())}
        missing = [c for c in columns if c not in have and c not in later]
        if missing:
            raise InputError(Problem(file, None, None, f"the journal's table '{table}' has no column "
                                     f"{', '.join(repr(c) for c in missing)}: it is damaged, or not a campaign "
                                     f"journal", FIX))
