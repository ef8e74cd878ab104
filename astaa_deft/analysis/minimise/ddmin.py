"""Delta debugging (ddmin) as a pure algorithm, apart from any tester.

Zeller & Hildebrandt's ddmin ("Simplifying and Isolating Failure-Inducing
Input", TSE 2002): split the current failing configuration into ``n``
contiguous chunks; if one chunk alone still fails, keep it and restart at
``n = 2`` ("reduce to subset"); else if all-but-one chunk still fails, keep
that and go on at ``n - 1`` ("reduce to complement"); else double ``n`` until
chunks are single items. The result is 1-minimal: removing any one item
makes the failure go away. The tester is any callable from a subset (in the
original order) to a :class:`TestResult`, so the same engine minimises
mutations, frames or fields (the picire model, without picire).

Why not picire (21.8, PyPI): its last release is from August 2021 (classifiers
stop at Python 3.9); it pulls in ``chardet``, ``inators``, ``psutil`` and
``setuptools``/``pkg_resources`` for what is a CLI around files; its parallel
mode forks processes and records the failing index shared between them, so the
chosen subset is whichever test finished last-writing rather than the first in
canonical order, and a tester's state (counters, open handles) lives in forked
children; outcomes are only PASS/FAIL (no UNRESOLVED, detail or failure rate);
and each iteration re-runs the current configuration as an uncached assertion,
which doubles the cost of expensive whole-system re-runs. The algorithm itself
is some fifty lines, so we keep our own: typed, no dependencies, threads or any
``concurrent.futures`` executor, results identical to the sequential run.

Pure logic: no I/O, no logging; ``progress`` receives one-line messages.
"""

from __future__ import annotations

import enum
import time
from collections.abc import Callable, Hashable, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, Executor, Future, ThreadPoolExecutor, wait
from dataclasses import dataclass, field, replace
from typing import Generic, TypeVar

from astaa_deft.model.errors import AstaaDeftError

T = TypeVar("T")
K = TypeVar("K", bound=Hashable)

Config = tuple[int, ...]
"""A configuration: sorted indices into the items being minimised."""


class Outcome(enum.Enum):
    """What a test of a configuration says. Only FAIL reduces: ddmin keeps what still fails."""

    FAIL = "fail"  # the failure still reproduces
    PASS = "pass"  # the failure is gone
    UNRESOLVED = "unresolved"  # the test could not tell (e.g. the system did not start)


@dataclass(frozen=True)
class TestResult:
    """A tester's answer for one configuration.

    ``failure_rate`` is for testers that repeat a flaky test and decide FAIL
    above some threshold; ddmin only reads ``outcome`` but keeps the whole
    result in :attr:`DDResult.results` so the rate reaches the report.
    """

    __test__ = False  # not a pytest test class

    outcome: Outcome
    detail: str = ""
    failure_rate: float | None = None


Tester = Callable[[Sequence[T]], TestResult]
"""Gets a subset of the items, in their original order; must be thread-safe when ``parallel > 1``."""


class MinimiseError(AstaaDeftError):
    """ddmin cannot start; the message says why, for the CLI to print."""

    def __init__(self, message: str, result: TestResult):
        super().__init__(message + (f": {result.detail}" if result.detail else ""))
        self.result = result


class NotReproducible(MinimiseError):
    """The full set of items does not FAIL: there is nothing to minimise."""


class FailsWithoutItems(MinimiseError):
    """The empty set already FAILS: the failure does not depend on the items."""


class OutcomeCache:
    """Test results keyed by configuration, so each configuration is tested at most once.

    Keys are indices into one particular item sequence: share a cache only
    between runs over the same items. Subclass to persist it.
    """

    def __init__(self) -> None:
        self._results: dict[Config, TestResult] = {}

    def get(self, config: Config) -> TestResult | None:
        return self._results.get(config)

    def put(self, config: Config, result: TestResult) -> None:
        self._results[config] = result

    def __len__(self) -> int:
        return len(self._results)


@dataclass(kw_only=True)
class DDResult(Generic[T]):
    """The outcome of one minimisation.

    ``minimal`` always FAILS (it was tested, or is the full set the caller
    vouched for with ``check_full=False``). ``complete`` is False when
    ``max_tests`` stopped the search: ``minimal`` is then the smallest failing
    set found so far, not necessarily 1-minimal. ``history`` lists every test
    actually run (not cache hits) in the order results arrived.
    """

    minimal: list[T]
    tests_run: int
    cache_hits: int
    seconds: float
    history: list[tuple[Config, Outcome]]
    indices: Config = ()
    complete: bool = True
    results: dict[Config, TestResult] = field(default_factory=dict)


class _OutOfBudget(AstaaDeftError):
    """max_tests is spent before a round could be decided."""


def split(config: Config, n: int) -> list[Config]:
    """Cut ``config`` into ``n`` contiguous, non-empty chunks whose sizes differ by at most one."""
    size, extra = divmod(len(config), n)
    chunks, start = [], 0
    for i in range(n):
        stop = start + size + (1 if i < extra else 0)
        chunks.append(config[start:stop])
        start = stop
    return chunks


def _without(config: Config, chunk: Config) -> Config:
    drop = set(chunk)
    return tuple(i for i in config if i not in drop)


class _Search(Generic[T]):
    """The state of one ddmin run: tests, cache, in-flight futures, budget."""

    def __init__(
        self,
        items: Sequence[T],
        tester: Tester[T],
        cache: OutcomeCache,
        executor: Executor | None,
        *, window: int,
        max_tests: int | None,
    ):
        self.items = items
        self.tester = tester
        self.cache = cache
        self.executor = executor
        self.window = window  # at most this many tests in flight
        self.max_tests = max_tests
        # Tests started but not yet collected; may outlive a round (speculative
        # tests whose answer was not needed) and be reused by a later one.
        self.inflight: dict[Config, Future[TestResult]] = {}
        self.tests_run = 0
        self.cache_hits = 0
        self.history: list[tuple[Config, Outcome]] = []
        self.results: dict[Config, TestResult] = {}

    def _start(self, config: Config, budgeted: bool = True) -> Future[TestResult] | None:
        """A future for ``config``: already in flight, newly submitted, or None when the budget is spent."""
        if config in self.inflight:
            return self.inflight[config]
        if budgeted and self.max_tests is not None and self.tests_run + len(self.inflight) >= self.max_tests:
            return None
        subset = [self.items[i] for i in config]
        if self.executor is None:  # sequential: run now, in this thread
            future: Future[TestResult] = Future()
            try:
                future.set_result(self.tester(subset))
            except Exception as exc:  # re-raised by _collect, as a pool's future would
                future.set_exception(exc)
        else:
            future = self.executor.submit(self.tester, subset)
        self.inflight[config] = future
        return future

    def _collect(self, config: Config, future: Future[TestResult]) -> TestResult:
        result = future.result()  # a tester's exception propagates: it is a bug, not an outcome
        if not isinstance(result, TestResult):
            raise TypeError(f"tester returned {result!r}, expected a TestResult")
        del self.inflight[config]
        self.tests_run += 1
        self.history.append((config, result.outcome))
        self.results[config] = result
        self.cache.put(config, result)
        return result

    def _cached(self, config: Config) -> TestResult | None:
        result = self.cache.get(config)
        if result is not None:
            self.cache_hits += 1
        return result

    def result_of(self, config: Config) -> TestResult:
        """Test one configuration now, ignoring the budget (used for the start-up checks)."""
        cached = self._cached(config)
        if cached is not None:
            return cached
        future = self._start(config, budgeted=False)
        assert future is not None
        return self._collect(config, future)

    def first_failing(self, configs: Sequence[Config]) -> int | None:
        """Index of the first FAILing configuration in the given order, or None if none fails.

        Up to ``window`` tests run at once, started in order. The answer is
        the one a sequential scan gives: a FAIL at ``i`` only decides once
        every configuration before ``i`` has answered; configurations after
        the first known FAIL are not started, and queued ones are cancelled.
        Raises _OutOfBudget if ``max_tests`` runs out before that.
        """
        known: dict[int, Outcome] = {}
        running: dict[int, Future[TestResult]] = {}
        limit = len(configs)  # only indices below this can still change the answer
        next_i = 0
        while True:
            while next_i < limit and len(running) < self.window:
                cached = self._cached(configs[next_i])
                if cached is not None:
                    known[next_i] = cached.outcome
                    if cached.outcome is Outcome.FAIL:
                        limit = next_i
                else:
                    future = self._start(configs[next_i])
                    if future is None:
                        break
                    running[next_i] = future
                next_i += 1
            for i in [i for i in running if i >= limit]:
                self._abandon(configs[i], running.pop(i))
            if not running:
                break
            finished, _ = wait(running.values(), return_when=FIRST_COMPLETED)
            for i, future in list(running.items()):
                if future in finished:
                    del running[i]
                    known[i] = self._collect(configs[i], future).outcome
                    if known[i] is Outcome.FAIL:
                        limit = min(limit, i)
        if any(i not in known for i in range(limit)):
            raise _OutOfBudget
        return limit if limit < len(configs) else None

    def _abandon(self, config: Config, future: Future[TestResult]) -> None:
        """Drop a test whose answer is no longer needed: cancel it if it has not started."""
        if future.cancel():
            del self.inflight[config]
        # A running one stays in flight: a later round may need it, close() collects it.

    def close(self, collect: bool) -> None:
        """Cancel queued tests; if ``collect``, wait for running ones and keep their results.

        Collecting means no test of ours still runs when ddmin returns, and a
        shared cache gains the speculative answers.
        """
        for config, future in list(self.inflight.items()):
            if future.cancel():
                del self.inflight[config]
        if not collect:
            return
        for config, future in list(self.inflight.items()):
            if future.exception() is None:
                self._collect(config, future)
            # A speculative test that raised is dropped: no answer depended on it.


@dataclass(frozen=True, kw_only=True)
class DDOptions:
    """How :func:`ddmin` searches.

    ``parallel=N`` tests up to N configurations of a round at once; for a
    deterministic tester ``minimal`` is the same as with N = 1, though
    speculative tests may raise ``tests_run``. ``check_full`` first tests
    the full set (must FAIL, else NotReproducible) and the empty set (must
    not FAIL, else FailsWithoutItems); without it both are assumed, as in
    the paper. ``max_tests`` bounds ``tests_run`` (the two checks run even
    past it); once spent, ddmin returns the smallest failing set so far with
    ``complete=False``. ``progress`` hears one line per round.
    """

    parallel: int = 1
    check_full: bool = True
    max_tests: int | None = None
    progress: Callable[[str], None] | None = None


def ddmin(items: Sequence[T], tester: Tester[T], options: DDOptions = DDOptions(), *,
          executor: Executor | None = None, cache: OutcomeCache | None = None) -> DDResult[T]:
    """Minimise ``items`` to a 1-minimal subset that still makes ``tester`` FAIL, as ``options`` say.

    Parallel tests run on ``executor`` if given (the caller owns it), else
    on a thread pool made here. ``cache``: outcomes already known (shared
    between searches over the same items). Cache hits cost nothing and do
    not count.
    """
    parallel, check_full, max_tests, progress = options.parallel, options.check_full, options.max_tests, \
        options.progress
    if parallel < 1:
        raise ValueError(f"parallel must be at least 1, got {parallel}")
    if max_tests is not None and max_tests < 0:
        raise ValueError(f"max_tests must not be negative, got {max_tests}")
    started = time.monotonic()
    own_pool = ThreadPoolExecutor(parallel, thread_name_prefix="ddmin") if executor is None and parallel > 1 else None
    search = _Search(items, tester, cache if cache is not None else OutcomeCache(), executor or own_pool,
                     window=parallel, max_tests=max_tests)
    say = progress or (lambda message: None)
    current: Config = tuple(range(len(items)))
    complete = True
    try:
        if check_full:
            full = search.result_of(current)
            if full.outcome is not Outcome.FAIL:
                raise NotReproducible(f"the full set of {len(items)} items gives {full.outcome.value}, not fail", full)
            empty = search.result_of(())
            if empty.outcome is Outcome.FAIL:
                raise FailsWithoutItems("the empty set already fails: the failure does not depend on the items", empty)
        n = 2
        while len(current) >= 2:
            subsets = split(current, n)
            # At n = 2 the complements are the subsets again.
            complements = [] if n == 2 else [_without(current, s) for s in subsets]
            say(f"{len(current)} items in {n} chunks, {search.tests_run} tests so far")
            try:
                hit = search.first_failing(subsets + complements)
            except _OutOfBudget:
                complete = False
                say(f"stopped after {search.tests_run} tests (max_tests): {len(current)} items")
                break
            if hit is None:
                if n >= len(current):
                    break  # every single-item removal was tried: 1-minimal
                n = min(2 * n, len(current))
            elif hit < n:
                current, n = subsets[hit], 2
            else:
                current, n = complements[hit - n], max(n - 1, 2)
        search.close(collect=True)
    finally:
        search.close(collect=False)
        if own_pool is not None:
            own_pool.shutdown(wait=True, cancel_futures=True)
    say(f"done: {len(current)} items after {search.tests_run} tests ({search.cache_hits} cache hits)")
    return DDResult(
        minimal=[items[i] for i in current],
        tests_run=search.tests_run,
        cache_hits=search.cache_hits,
        seconds=time.monotonic() - started,
        history=search.history,
        indices=current,
        complete=complete,
        results=search.results,
    )


@dataclass
class GroupResult(Generic[K, T]):
    """``minimal`` maps each group that matters to the items of it that matter."""

    minimal: dict[K, list[T]]
    groups: DDResult[K]
    items: DDResult[tuple[K, T]] | None  # None when the group stage did not complete

    @property
    def tests_run(self) -> int:
        return self.groups.tests_run + (self.items.tests_run if self.items else 0)

    @property
    def complete(self) -> bool:
        return self.groups.complete and self.items is not None and self.items.complete


def minimise_groups(groups: Mapping[K, Sequence[T]], tester: Tester[T], options: DDOptions = DDOptions(), *,
                    executor: Executor | None = None) -> GroupResult[K, T]:
    """Two-level ddmin: first which groups (e.g. messages) matter, then which items (e.g. fields) of them.

    Cheaper than one flat ddmin when whole groups are irrelevant, and the
    answer comes grouped. ``tester`` gets the chosen items flattened in group
    order. ``options`` are those of :func:`ddmin` (no shared ``cache``: each
    stage has its own index space); ``max_tests`` bounds both stages together.
    """
    keys = list(groups)

    def test_groups(chosen: Sequence[K]) -> TestResult:
        return tester([x for k in chosen for x in groups[k]])

    def test_items(chosen: Sequence[tuple[K, T]]) -> TestResult:
        return tester([x for _, x in chosen])

    coarse = ddmin(keys, test_groups, options, executor=executor)
    if not coarse.complete:
        return GroupResult({k: list(groups[k]) for k in coarse.minimal}, coarse, None)
    # The chosen groups together are known to fail (or assumed to, as the full
    # set is without check_full), and the empty set was checked already.
    flat = [(k, x) for k in coarse.minimal for x in groups[k]]
    left = None if options.max_tests is None else max(options.max_tests - coarse.tests_run, 0)
    fine = ddmin(flat, test_items, replace(options, check_full=False, max_tests=left), executor=executor)
    minimal: dict[K, list[T]] = {}
    for k, x in fine.minimal:
        minimal.setdefault(k, []).append(x)
    return GroupResult(minimal, coarse, fine)


@dataclass(kw_only=True)
class ShortenResult(Generic[T]):
    """A contiguous run shortened: ``kept`` (a contiguous slice of the run, tested to FAIL or the whole run the
    caller vouched for), the tests run for it, and every result by slice (start, stop)."""

    kept: list[T]
    tests_run: int
    complete: bool = True
    results: dict[tuple[int, int], TestResult] = field(default_factory=dict)
    span: tuple[int, int] = (0, 0)  # kept = run[span[0]:span[1]]


def shorten(run: Sequence[T], tester: Tester[T], *, max_tests: int | None = None) -> ShortenResult[T]:
    """The shortest contiguous slice of ``run`` that still FAILS, found by shortening it at its ends.

    A held fault (one value on every message of a window) is one cause: its
    messages act together — a planner that bridges two bad inputs and fails
    on the third needs three in a row, and ddmin over single messages would
    break the hold (keep the 1st and 3rd, lose the failure, or keep one that
    fails only in an open-loop replay). So the run is kept contiguous and
    shortened from its end first (what came after the failure did not cause
    it: the slice keeps the original failure's time), then from its start,
    each by bisection over how many messages to cut: ~2·log2(n) tests. The
    full run is assumed to FAIL (the caller tested it). Bisection assumes
    the failure keeps failing as the hold grows; where it does not, the
    answer is still a slice that was tested to FAIL. ``max_tests`` bounds the
    tests; once spent, the shortest failing slice so far is returned with
    ``complete=False``.
    """
    results: dict[tuple[int, int], TestResult] = {}
    tests = 0
    complete = True

    def fails(start: int, stop: int) -> bool | None:
        nonlocal tests
        if (start, stop) not in results:
            if max_tests is not None and tests >= max_tests:
                return None
            tests += 1
            results[(start, stop)] = tester(list(run[start:stop]))
        return results[(start, stop)].outcome is Outcome.FAIL

    start, stop = 0, len(run)
    # The end: the smallest stop that still fails (stop = len(run) fails).
    lo, hi = start + 1, stop
    while lo < hi:
        mid = (lo + hi) // 2
        answer = fails(start, mid)
        if answer is None:
            complete = False
            break
        if answer:
            hi = mid
        else:
            lo = mid + 1
    stop = hi
    # The start: the largest start that still fails with that stop.
    lo, hi = start, stop - 1
    while complete and lo < hi:
        mid = (lo + hi + 1) // 2
        answer = fails(mid, stop)
        if answer is None:
            complete = False
            break
        if answer:
            lo = mid
        else:
            hi = mid - 1
    start = lo if complete else start
    if not complete:  # the shortest slice known to fail
        failing = [(a, b) for (a, b), r in results.items() if r.outcome is Outcome.FAIL]
        start, stop = min(failing, key=lambda s: (s[1] - s[0], s[0]), default=(0, len(run)))
    return ShortenResult(kept=list(run[start:stop]), tests_run=tests, complete=complete, results=results,
                         span=(start, stop))
