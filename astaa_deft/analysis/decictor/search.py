"""The search (Algorithm 1) and its baselines, independent of how a scene is run.

Ask-and-tell: ``propose(n)`` gives the n-th scene (a tuple of participants),
``observe(scene, observation)`` judges its run against the seed and learns.
The same object drives a live campaign (``campaign/strategies/decictor.py``)
and the in-process closed loop (benchmarks, tests).

* ``decictor``: a population of N = 4 scenes, starting as N copies of the
  seed (no participant); each scene proposed is a non-invasive mutation of a
  population member (add a participant, remove one, change one = remove +
  add, or move one: its placement and motion perturbed); after every N
  observations the next population is the best of population + offspring
  kept, the rest drawn by roulette wheel on fitness (path distance +
  behaviour MMD). Non-optimal scenes are findings and leave the pool (as in
  the paper); so do scenes whose task failed or whose seed path was blocked.
* ``random-delta``: the same non-invasive mutations, selection uniformly at
  random (no feedback: the paper's Random-δ / F-Random).
* ``random``: every scene fresh: 1 to 4 random feasible participants.
"""

from __future__ import annotations

import random
from dataclasses import dataclass, field, replace

from astaa_deft.engine.intercept.actions.participant import Participant
from astaa_deft.analysis.decictor.feasible import Area, ForbiddenRegion, perturb, sample_participant
from astaa_deft.analysis.decictor.oracle import DecisionVerdict, LaneGrid, RunObservation, judge

MODES = ("decictor", "random-delta", "random")
POPULATION = 4
MAX_PARTICIPANTS = 4
FIRST_ID = 901  # participant ids; far from the SUT's own obstacle ids
OPERATORS = ("add", "remove", "change", "move")


@dataclass(frozen=True)
class Scene:
    participants: tuple[Participant, ...] = ()
    operator: str = "seed"  # how it was made from its parent


@dataclass
class Member:
    scene: Scene
    fitness: float


@dataclass(kw_only=True)
class SearchStats:
    observed: int = 0
    findings: int = 0
    task_failed: int = 0
    invalid: int = 0  # the seed path was blocked (the mutation was not harmless after all)
    best_fitness: float = 0.0
    finding_numbers: list[int] = field(default_factory=list)  # which observations were findings


class Search:
    def __init__(self, mode: str, seed: int, seed_run: RunObservation, grid: LaneGrid, *, area: Area,
                 region: ForbiddenRegion, population: int = POPULATION):
        if mode not in MODES:
            raise ValueError(f"unknown Decictor mode {mode!r}; one of {', '.join(MODES)}")
        if not seed_run.goal_reached or seed_run.collision:
            raise ValueError("the seed run must reach its goal without a collision: it is the optimal decision "
                             "every mutated run is compared with")
        self.mode = mode
        self.seed = seed
        self.seed_run = seed_run
        self.grid = grid
        self.area = area
        self.region = region
        self.size = population
        self.population = [Member(Scene(), 0.0) for _ in range(population)]
        self.offspring: list[Member] = []
        self.stats = SearchStats()
        self._selections = 0

    # -- ask -------------------------------------------------------------------
    def propose(self, number: int) -> Scene:
        rng = random.Random(f"decictor/{self.mode}/{self.seed}/{number}")
        if self.mode == "random":
            return self._fresh(rng)
        parent = self.population[(number - 1) % self.size].scene
        for _ in range(8):
            scene = self._mutate(rng, parent)
            if scene is not None:
                return scene
        return self._fresh(rng)

    def _fresh(self, rng: random.Random) -> Scene:
        participants: list[Participant] = []
        for k in range(rng.randint(1, MAX_PARTICIPANTS)):
            p = sample_participant(rng, FIRST_ID + k, self.region, self.area)
            if p is not None:
                participants.append(p)
        return Scene(tuple(participants), "fresh")

    def _mutate(self, rng: random.Random, parent: Scene) -> Scene | None:
        current = list(parent.participants)
        # Removing the only added participant would give back the seed itself: a run that can teach nothing.
        options = [op for op in OPERATORS if (op != "add" or len(current) < MAX_PARTICIPANTS)
                   and (op != "remove" or len(current) >= 2) and (op not in ("change", "move") or current)]
        operator = rng.choice(options)
        if operator in ("remove", "change"):
            current.pop(rng.randrange(len(current)))
        if operator in ("add", "change"):
            new_id = max([p.id for p in current], default=FIRST_ID - 1) + 1
            added = sample_participant(rng, new_id, self.region, self.area)
            if added is None:
                return None
            current.append(added)
        if operator == "move":
            k = rng.randrange(len(current))
            moved = perturb(rng, current[k], self.region, self.area)
            if moved is None:
                return None
            current[k] = moved
        return Scene(tuple(current), operator)

    # -- tell ------------------------------------------------------------------
    def observe(self, scene: Scene, run: RunObservation) -> DecisionVerdict:
        verdict = judge(self.seed_run, run, scene.participants, self.grid)
        stats = self.stats
        stats.observed += 1
        if verdict.non_optimal:
            stats.findings += 1
            stats.finding_numbers.append(stats.observed)
        elif verdict.reason.startswith("task failed"):
            stats.task_failed += 1
        elif verdict.reason.startswith("invalid"):
            stats.invalid += 1
        else:
            self.offspring.append(Member(scene, verdict.fitness))
            stats.best_fitness = max(stats.best_fitness, verdict.fitness)
        if stats.observed % self.size == 0 and self.mode != "random":
            self._select()
        return verdict

    def _select(self) -> None:
        pool = self.population + self.offspring
        self.offspring = []
        self._selections += 1
        rng = random.Random(f"decictor/{self.mode}/{self.seed}/select/{self._selections}")
        if self.mode == "random-delta":
            self.population = [replace(m) for m in rng.sample(pool, self.size)] if len(pool) >= self.size \
                else pool[:]
            return
        best = max(pool, key=lambda m: m.fitness)
        rest = [m for m in pool if m is not best]
        weights = [m.fitness + 1e-6 for m in rest]
        chosen = rng.choices(rest, weights=weights, k=self.size - 1) if rest else []
        self.population = [best, *chosen]
