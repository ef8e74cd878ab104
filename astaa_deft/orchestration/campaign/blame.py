"""Which module is to blame for a confirmed bucket: the first whose output departed from its unmutated twins'.

A bucket names the mutated channel and the broken invariant; the module
that mishandled the value sits somewhere between. The campaign has already
run the failing case's unmutated twins (same params, same concurrency), so
every channel of the failing run can be compared with the same channel in
the twins, from the first mutation on: the first module whose output
departs from the twins' — beyond the twins' own spread, which is the SUT's
run-to-run noise — is the one to blame (the bus version of message-level
root-cause analysis: DVCA, Poirot). Downstream modules depart later, in the
closed loop's turn.

Runs are compared in bins of :data:`BIN_SECONDS` counted from each run's
first message on the anchor channel (the live stack, as generated windows
are). Per channel and bin: the message count, and per field (array indices
folded) the mean of its finite numbers, how many values were not finite,
arrays' lengths and short strings' shares. A channel departs in a bin when

* non-finite values appear that no twin had (``non-finite``);
* it falls silent where every twin sent at least two messages (``silent``);
* a string value appears that no run without the mutation had (``value``);
  or a number's mean (an array's length, a string's share) leaves the
  twins' range by more than the noise — twice the largest spread seen
  between twins, or between the failing run and the twins before its first
  mutation (at least 5 % of the field's scale) — in two bins in a row (one
  bin of a drifting number is noise).

The mutated channels themselves are left out (they depart by construction).

A module the spec marks ``plant: true`` (a simulator: the vehicle and its
world) is never to blame: it applies what it is sent, so when its output
departs first — no module under test departed before it, nor in the same
bin while consuming a mutated channel — what caused the failure is the
mutated value itself (``Blame.module`` None, ``how`` :data:`MUTATED_VALUE`).
Modules under test departing after it react to the plant's changed world.

Pure logic apart from :func:`run_series`, which reads a log.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path

from astaa_deft.io.codecs import get_codec
from astaa_deft.io.log import layout
from astaa_deft.io.log.reader import LogContents, read_log
from astaa_deft.model.errors import AstaaDeftError
from astaa_deft.model.json import JsonObject
from astaa_deft.model.sut import Spec
from astaa_deft.orchestration.journal.rows import MUTATED_VALUE, root_cause_of

BIN_SECONDS = 0.5
NOISE_FACTOR = 2.0  # a number departs beyond this many times the largest spread seen without the mutation
SCALE_SHARE = 0.05  # … and beyond this share of its scale
MAX_STRING = 32  # longer strings are not compared (ids, free text)
COUNT = "#count"

Features = dict[str, float]
Series = dict[str, dict[int, Features]]  # channel → bin → features


@dataclass(frozen=True)
class RunSeries:
    """One run's channels, binned from its anchor's first message; ``first_mutation_bin`` None: a clean run."""

    bins: Series
    first_mutation_bin: int | None = None
    mutated: tuple[str, ...] = ()  # channels the run's mutations touched


@dataclass(frozen=True, kw_only=True)
class Departure:
    """A channel of the failing run that left its twins' range: in which bin, on which feature, how."""

    channel: str
    bin: int
    feature: str
    how: str  # non-finite, silent, value
    detail: str


@dataclass(frozen=True, kw_only=True)
class Blame:
    """The module to blame for a bucket and the chain that says why (JSON-able: the journal keeps it)."""

    module: str | None  # None: no module under test is to blame (how says why: mutated value, none)
    output: str | None  # the departed channel (None: none departed)
    how: str  # non-finite, silent, value; "finding" when no output departed and the finding names the module;
    # "mutated value" when a plant's output departed first (no module under test mishandled anything); "none"
    chain: str  # mutated channel → module → channel → invariant
    detail: str
    twins: int  # twins compared with

    def to_json(self) -> JsonObject:
        """Its JSON form."""
        return asdict(self)

    @property
    def wrong_output(self) -> str:
        """What went wrong, as bucket identity uses it: the departed channel and how (no values, no bins)."""
        return f"{self.output}:{self.how}" if self.output else self.how

    @property
    def root_cause(self) -> str | None:
        """The root cause it names (:func:`root_cause_of`)."""
        return root_cause_of(self.module, self.how)


RANK = {"non-finite": 0, "silent": 1, "value": 2}


def features(message: object, ignore: frozenset[str] = frozenset()) -> Features:
    """A message's comparable numbers: per field path (array indices folded to ``[]``), the mean of its finite
    numbers, ``path#nonfinite`` values that are not finite, ``path#len`` array lengths, ``path=s`` short strings.
    Fields named in ``ignore`` (the spec's brittle stamps and sequence numbers: clocks and counters differ
    between any two runs) are left out."""
    sums: dict[str, list[float]] = defaultdict(list)
    out: Features = {}

    def walk(value: object, path: str) -> None:
        if isinstance(value, bool):
            sums[path].append(1.0 if value else 0.0)
        elif isinstance(value, (int, float)):
            if isinstance(value, float) and not math.isfinite(value):
                out[f"{path}#nonfinite"] = out.get(f"{path}#nonfinite", 0.0) + 1.0
            else:
                sums[path].append(float(value))
        elif isinstance(value, str):
            if len(value) <= MAX_STRING:
                out[f"{path}={value}"] = 1.0
        elif isinstance(value, Mapping):
            for key, item in value.items():
                if str(key) not in ignore:
                    walk(item, f"{path}.{key}" if path else str(key))
        elif isinstance(value, (list, tuple)):
            sums[f"{path}#len"].append(float(len(value)))
            for item in value:
                walk(item, f"{path}[]")

    walk(message, "")
    for path, values in sums.items():
        out[path] = sum(values) / len(values)
    return out


def bin_features(messages: Iterable[tuple[float, object]], ignore: frozenset[str] = frozenset()) -> dict[int, Features]:
    """(seconds from the anchor, decoded message) → bin → features: counts summed, the rest averaged over the
    bin's messages (absent string and non-finite features count as 0)."""
    grouped: dict[int, list[Features]] = defaultdict(list)
    for at, message in messages:
        grouped[math.floor(at / BIN_SECONDS)].append(features(message, ignore))
    out: dict[int, Features] = {}
    for b, items in grouped.items():
        keys = {k for f in items for k in f}
        merged: Features = {COUNT: float(len(items))}
        for key in keys:
            if _absent_is_zero(key):
                merged[key] = sum(f.get(key, 0.0) for f in items) / len(items)
            else:
                values = [f[key] for f in items if key in f]
                merged[key] = sum(values) / len(values)
        out[b] = merged
    return out


def _absent_is_zero(feature: str) -> bool:
    return feature.endswith("#nonfinite") or "=" in feature


def departures(failing: RunSeries, twins: Sequence[RunSeries]) -> list[Departure]:
    """Every channel's first departure from the twins, from the failing run's first mutation on (mutated channels
    left out), earliest first."""
    if failing.first_mutation_bin is None or not twins:
        return []
    start = failing.first_mutation_bin
    # The run's last whole bin: a channel that stops before it fell silent (its last bin may be cut short).
    end = max((max(bins) for bins in failing.bins.values() if bins), default=start) - 1
    found = []
    for channel, bins in failing.bins.items():
        if channel in failing.mutated:
            continue
        theirs = [t.bins.get(channel, {}) for t in twins]
        first = _first_departure(channel, bins, theirs, start, end=end)
        if first is not None:
            found.append(first)
    return sorted(found, key=lambda d: (d.bin, RANK.get(d.how, 9), d.channel))


def _first_departure(channel: str, mine: Mapping[int, Features], theirs: Sequence[Mapping[int, Features]],
                     start: int, *, end: int) -> Departure | None:
    last = max(mine, default=start)
    twin_last = min((max(t, default=-1) for t in theirs), default=-1)
    noise = _noise(mine, theirs, start)
    scale = _scale(theirs)
    seen = {k for t in theirs for f in t.values() for k in f} | {k for b, f in mine.items() if b < start for k in f}
    pending: dict[str, Departure] = {}
    for b in range(start, min(max(last, end), twin_last) + 1):
        here = mine.get(b, {COUNT: 0.0})
        there = [t.get(b, {COUNT: 0.0}) for t in theirs]
        counts = [f.get(COUNT, 0.0) for f in there]
        if here.get(COUNT, 0.0) == 0 and min(counts) >= 2:
            return Departure(channel=channel, bin=b, feature=COUNT, how="silent",
                             detail=f"no message where the twins sent {min(counts):g}+")
        if here.get(COUNT, 0.0) == 0:
            continue
        found: list[Departure] = []
        for key, value in here.items():
            if key == COUNT:
                continue
            if key.endswith("#nonfinite"):
                if value > 0 and all(f.get(key, 0.0) == 0 for f in there):
                    name = key.removesuffix("#nonfinite") or "value"
                    found.append(Departure(channel=channel, bin=b, feature=key, how="non-finite",
                                           detail=f"{name} not finite, finite in every twin"))
                continue
            if "=" in key and key not in seen:  # a string value no run without the mutation ever had
                found.append(Departure(channel=channel, bin=b, feature=key, how="value",
                                       detail=f"{key}: a value the twins never had"))
                continue
            values = [f[key] if key in f else (0.0 if _absent_is_zero(key) else None) for f in there]
            known = [v for v in values if v is not None]
            if not known:
                continue
            lo, hi = min(known), max(known)
            tol = max(NOISE_FACTOR * noise.get(key, 0.0), SCALE_SHARE * scale.get(key, 0.0), 1e-9)
            if lo - tol <= value <= hi + tol:
                pending.pop(key, None)
                continue
            departure = Departure(channel=channel, bin=b, feature=key, how="value",
                                  detail=f"{key} {value:.6g} where the twins had {lo:.6g}…{hi:.6g}")
            if key in pending and pending[key].bin == b - 1:  # two bins in a row: not a drifting number's jitter
                found.append(pending[key])
            else:
                pending[key] = departure
        if found:
            return min(found, key=lambda d: (RANK.get(d.how, 9), d.bin, d.feature))
        for key in list(pending):
            if pending[key].bin < b:
                del pending[key]
    return None


def _noise(mine: Mapping[int, Features], theirs: Sequence[Mapping[int, Features]], start: int) -> Features:
    """Per feature, the largest spread seen without the mutation: between twins (every bin), and between the
    failing run and the twins before its first mutation."""
    noise: Features = {}

    def widen(key: str, spread: float) -> None:
        noise[key] = max(noise.get(key, 0.0), spread)

    bins = {b for t in theirs for b in t}
    for b in bins:
        present = [t[b] for t in theirs if b in t]
        for key in {k for f in present for k in f}:
            values = [f[key] for f in present if key in f]
            if len(values) >= 2:
                widen(key, max(values) - min(values))
        if b < start and b in mine:
            for key, value in mine[b].items():
                values = [f[key] for f in present if key in f]
                if values:
                    widen(key, max(abs(value - v) for v in values))
    return noise


def _scale(theirs: Sequence[Mapping[int, Features]]) -> Features:
    scale: Features = {}
    for t in theirs:
        for f in t.values():
            for key, value in f.items():
                scale[key] = max(scale.get(key, 0.0), abs(value))
    return scale


def blame(spec: Spec, failing: RunSeries, twins: Sequence[RunSeries], *, invariant: str,
          finding_module: str | None) -> Blame:
    """The module to blame: the producer of the earliest departing channel (on a tie: a consumer of a mutated
    channel first, a module under test before a plant, then the strongest sign); without any departure, the module
    the finding names. A plant is never to blame: when it is chosen, the mutated value itself is (module None)."""
    mutated = ", ".join(failing.mutated) or "?"
    found = departures(failing, twins)
    if found:
        first_bin = found[0].bin
        consumers = {c for name in failing.mutated for c in _consumers(spec, name)}
        tied = [d for d in found if d.bin == first_bin]
        chosen = min(tied, key=lambda d: (_producer(spec, d.channel) not in consumers,
                                          spec.is_plant(_producer(spec, d.channel)), RANK.get(d.how, 9), d.channel))
        module = _producer(spec, chosen.channel)
        departed = f"{chosen.channel} ({chosen.how}: {chosen.feature}) → {invariant}"
        at = (first_bin - (failing.first_mutation_bin or 0)) * BIN_SECONDS
        detail = f"{chosen.detail}, {at:g}–{at + BIN_SECONDS:g} s after the first mutation"
        if spec.is_plant(module):
            return Blame(module=None, output=chosen.channel, how=MUTATED_VALUE,
                         chain=f"{_into_plant(spec, failing, module)} → {departed}",
                         detail=f"{detail}; no module under test departed before the plant {module}", twins=len(twins))
        return Blame(module=module, output=chosen.channel, how=chosen.how, chain=f"{mutated} → {module} → {departed}",
                     detail=detail, twins=len(twins))
    nothing = "no channel departed from the twins' range"
    if finding_module and spec.is_plant(finding_module):
        why = f"({invariant} names it; no output departed from the twins)"
        if any(finding_module in _consumers(spec, name) for name in failing.mutated):
            return Blame(module=None, output=None, how=MUTATED_VALUE,
                         chain=f"{_into_plant(spec, failing, finding_module)} → {why}", detail=nothing,
                         twins=len(twins))
        return Blame(module=None, output=None, how="none",
                     chain=f"{mutated} → ? → {invariant} (names {finding_module}, the plant)", detail=nothing,
                     twins=len(twins))
    if finding_module:
        chain = f"{mutated} → {finding_module} → ({invariant} names it; no output departed from the twins)"
        return Blame(module=finding_module, output=None, how="finding", chain=chain, detail=nothing, twins=len(twins))
    return Blame(module=None, output=None, how="none", chain=f"{mutated} → ? → {invariant}", detail=nothing,
                 twins=len(twins))


def _into_plant(spec: Spec, failing: RunSeries, plant: str) -> str:
    """The start of a chain through a plant: the mutated channels it consumes, which it carries on; else the
    mutated value reached it through modules under test whose outputs did not depart before its own."""
    fed = [name for name in failing.mutated if plant in _consumers(spec, name)]
    if fed:
        return f"{', '.join(fed)} (mutated) → {plant} (plant: carries the value on)"
    return f"{', '.join(failing.mutated) or '?'} (mutated) → … → {plant} (plant: departed before any module under test)"


def _producer(spec: Spec, channel: str) -> str:
    return next((c.producer for c in spec.channels if c.name == channel), "?")


def _consumers(spec: Spec, channel: str) -> tuple[str, ...]:
    return next((c.consumers for c in spec.channels if c.name == channel), ())


# -- reading a log ------------------------------------------------------------------------------------------
class BlameUnavailable(AstaaDeftError):
    """A log cannot be compared (missing, unreadable, no anchor message)."""


def run_series(log_path: Path, spec: Spec, anchor: str | None) -> RunSeries:
    """A run's channels binned from its anchor's first message (BlameUnavailable when the log cannot tell)."""
    try:
        log = read_log(log_path)
    except (AstaaDeftError, OSError, ValueError) as exc:
        raise BlameUnavailable(f"{log_path}: {exc}") from None
    t0 = _origin(log, spec, anchor)
    mutation_times = [m.log_time for m in log.on(layout.MUTATIONS_TOPIC)]
    mutated = sorted({c.name for c in spec.channels if log.on(layout.ORIGINAL_PREFIX + c.key)})
    ignore = frozenset(name.rsplit(".", 1)[-1] for name in spec.brittle)
    bins: Series = {}
    for channel in spec.channels:
        messages = log.on(channel.key)
        if not messages:
            continue
        decoded = []
        try:
            codec = get_codec(channel.encoding)
        except AstaaDeftError:
            codec = None
        for m in messages:
            try:
                body = codec.decode(m.data) if codec is not None else {}
            except Exception:  # noqa: BLE001 — a message that does not decode counts, with no fields
                body = {}
            decoded.append(((m.log_time - t0) / 1e9, body))
        bins[channel.name] = bin_features(decoded, ignore)
    first = math.floor((min(mutation_times) - t0) / 1e9 / BIN_SECONDS) if mutation_times else None
    return RunSeries(bins, first, tuple(mutated))


def _origin(log: LogContents, spec: Spec, anchor: str | None) -> int:
    if anchor is not None:
        key = next((c.key for c in spec.channels if c.name == anchor), None)
        times = [m.log_time for m in log.on(key)] if key else []
        if times:
            return min(times)
    bus = [m.log_time for m in log.messages if not m.topic.startswith("/astaa/")]
    if not bus:
        raise BlameUnavailable(f"{log.path}: no message on the bus")
    return min(bus)


def blame_logs(spec: Spec, failing_logs: Sequence[Path], twin_logs: Sequence[Path], anchor: str | None, *,
               invariant: str, finding_module: str | None) -> Blame:
    """:func:`blame` over the failing runs' logs (the case first, then its re-runs that failed the same way) and
    the twins' logs: the answer most failing runs give (the first run's on a tie), which says how many agreed.
    BlameUnavailable when the first failing log or a twin's cannot be read; a re-run's that cannot is left out."""
    twins = [run_series(p, spec, anchor) for p in twin_logs]
    answers = [blame(spec, run_series(failing_logs[0], spec, anchor), twins, invariant=invariant,
                     finding_module=finding_module)]
    for path in failing_logs[1:]:
        try:
            answers.append(blame(spec, run_series(path, spec, anchor), twins, invariant=invariant,
                                 finding_module=finding_module))
        except BlameUnavailable:
            continue
    keys = [(a.module, a.output, a.how) for a in answers]
    best = max(keys, key=lambda k: (keys.count(k), -keys.index(k)))
    chosen = answers[keys.index(best)]
    if len(answers) == 1:
        return chosen
    return replace(chosen, detail=f"{chosen.detail}; {keys.count(best)} of {len(answers)} failing runs agree")
