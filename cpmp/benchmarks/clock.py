"""The clock benchmark (``scripts/bench_clock.py``): the closed loop under a robot's clocks.

Completion and switch-time error of the default sequencer (``ConcurrentSequencer.fit(demos,
seed=s)``) on every registered synthetic world (:mod:`cpmp.worlds.registry`; a family's first
``tasks`` members) and on the simulator (``sim``), under the conditions of
:data:`CONDITIONS`: control rates of 30 to 1000 Hz, ±30 % jitter of the tick period, 10 %
dropped ticks, sensors at 10 / 16.7 / 25 Hz, a 1 s forward step of the clock and NaN bursts.
Written as JSON (atomically); same settings, same JSON. Nothing here asserts a number.

:class:`ClockedPolicy` is the reusable part: a :class:`~cpmp.records.Policy` around a policy
that decides when the inner policy is called and with which time and features
(:class:`ClockCondition`). The synthetic worlds run in :func:`run_synthetic_episode`, whose
world step is each tick's period (integrated in sub-steps no longer than the world's ``dt``),
so jitter changes how far the world moves between ticks; the simulator runs in
:func:`cpmp.sim.run_episodes` at the condition's control rate (for jitter: at 500 Hz with the
policy woken on the jittered schedule, rounded to the 2 ms ticks).

A synthetic episode is scored as the world scores it (:meth:`~cpmp.worlds.protocol.World.score`,
the count of the worlds table): ``complete`` when the goal was reached (for a ``strict`` world,
also with exactly the demonstrator's MP sequences of that episode), ``wrong_start`` when the
initial MPs were not the demonstrator's. ``same_sequences`` counts the complete episodes whose
every variable ran exactly the demonstrator's MP sequence. The switch-time error pairs the k-th
switch of each variable with the demonstrator's k-th switch on the same episode (the
demonstrator at the world's own rate and an ideal clock), in seconds of true time, over those
episodes.
"""

from __future__ import annotations

import argparse
import inspect
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from cpmp.benchmarks.cli import given_options, run_settings_benchmark
from cpmp.config import TaskConfig
from cpmp.data.demonstration import Demonstration, mp_sequences
from cpmp.errors import ConfigError, CpmpError
from cpmp.io import to_builtin
from cpmp.records import JsonValue, Policy
from cpmp.sequencer import ConcurrentSequencer
from cpmp.sim import correct_strategy, record_demonstrations, run_episodes
from cpmp.sim.collect import sample_boxes
from cpmp.worlds.outcomes import OUTCOMES
from cpmp.worlds.protocol import World
from cpmp.worlds.registry import members, world_names

SYNTHETIC_WORLDS = world_names()
"""Every registered synthetic world (:mod:`cpmp.worlds.registry`)."""
WORLDS = (*SYNTHETIC_WORLDS, "sim")
REFERENCE = "rate_100hz"
"""The condition every other one is compared with: the worlds' own 100 Hz loop."""
SCORING = "world"
"""How a synthetic episode is scored: as the world scores it (see the module doc). A result
without ``scoring`` comes from an earlier bench that counted an episode complete only with the
demonstrator's MP sequences, stopping it at the first switch that left them."""
HELD_OUT_SEED = 1000
"""Evaluation episodes of seed ``s`` are drawn with ``HELD_OUT_SEED + s``."""
SIM_BASE_DT = 0.002
"""Tick [s] of the simulator under a jittered policy clock (and its physics step)."""
_EPS_T = 1e-9
"""Slack [s] when comparing tick times."""


@dataclass(frozen=True)
class ClockCondition:
    """How the policy's clock and sensor differ from an ideal loop.

    Attributes:
        name: the condition's key in the JSON.
        rate: control rate [Hz]: the policy is due every ``1 / rate`` seconds.
        jitter: each period is ``(1 + u) / rate`` with ``u`` uniform in ``[-jitter, jitter]``.
        drop: probability that a due tick is dropped (the policy is not called; the MPs keep
            running).
        sensor_period: the features the policy sees refresh every ``sensor_period`` [s]
            (zero-order hold, the measurement time known); ``None``: fresh every tick.
        clock_step: the policy's clock steps forward by this much [s] at half the episode's
            demonstrated duration (time jumps, the state does not).
        nan_ticks: length of each NaN burst (due ticks whose features are all NaN).
        nan_bursts: number of bursts, spread evenly over the demonstrated duration.
    """

    name: str
    rate: float = 100.0
    jitter: float = 0.0
    drop: float = 0.0
    sensor_period: float | None = None
    clock_step: float = 0.0
    nan_ticks: int = 0
    nan_bursts: int = 0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.rate) and self.rate > 0):
            raise ConfigError(f"{self.name}: rate must be > 0 Hz, got {self.rate}")
        if not 0.0 <= self.jitter < 1.0 or not 0.0 <= self.drop < 1.0:
            raise ConfigError(f"{self.name}: jitter and drop must be in [0, 1)")
        if self.sensor_period is not None and not self.sensor_period > 0:
            raise ConfigError(f"{self.name}: sensor_period must be > 0 s or None")
        if self.clock_step < 0 or self.nan_ticks < 0 or self.nan_bursts < 0:
            raise ConfigError(f"{self.name}: clock_step, nan_ticks and nan_bursts must be >= 0")


CONDITIONS: tuple[ClockCondition, ...] = (
    ClockCondition("rate_30hz", rate=30.0),
    ClockCondition("rate_50hz", rate=50.0),
    ClockCondition(REFERENCE, rate=100.0),
    ClockCondition("rate_250hz", rate=250.0),
    ClockCondition("rate_1000hz", rate=1000.0),
    ClockCondition("jitter_30pct", jitter=0.3),
    ClockCondition("drop_10pct", drop=0.1),
    ClockCondition("sensor_10hz", sensor_period=0.1),
    ClockCondition("sensor_16.7hz", sensor_period=0.06),
    ClockCondition("sensor_25hz", sensor_period=0.04),
    ClockCondition("clock_step_1s", clock_step=1.0),
    ClockCondition("nan_burst", nan_ticks=3, nan_bursts=2),
)
"""Every condition of the benchmark; all but the rate conditions tick at 100 Hz."""
CONDITION_NAMES = tuple(c.name for c in CONDITIONS)


class ClockedPolicy:
    """A :class:`~cpmp.records.Policy` that runs ``inner`` on a :class:`ClockCondition`'s clock.

    The closed loop calls :meth:`reset` and :meth:`step` with the true time and the true
    features. A step is *due* when the condition's schedule says so (every tick of a loop that
    follows :meth:`next_period`; some ticks of a faster loop); otherwise, and on a dropped tick,
    the MPs of the last call are returned without calling ``inner``. On a due tick ``inner``
    gets the time on the policy's clock (true time plus any clock step) and the features of the
    last sensor sample (all NaN during a burst); if its ``step`` takes the keyword
    ``stamp_keyword``, also the sample's measurement time on the policy's clock. A
    :class:`~cpmp.errors.CpmpError` from ``inner`` is kept in :attr:`error` and stops it: the
    MPs of the last call are held from then on.

    Args:
        inner: the policy run on this clock.
        condition: the clock.
        rng: random numbers of this episode's jitter and drops.
        duration: the episode's demonstrated duration [s] (places the clock step and bursts).
        stamp_keyword: the keyword of ``inner.step`` that takes the measurement time.
    """

    def __init__(
        self,
        inner: Policy,
        condition: ClockCondition,
        rng: np.random.Generator,
        duration: float,
        stamp_keyword: str = "stamp",
    ) -> None:
        self.inner = inner
        self.condition = condition
        self.rng = rng
        self.duration = float(duration)
        self.stamp_keyword = (
            stamp_keyword if stamp_keyword in inspect.signature(inner.step).parameters else None
        )
        c = condition
        self.step_at = 0.5 * self.duration if c.clock_step > 0 else math.inf
        self.burst_at = [self.duration * (k + 1) / (c.nan_bursts + 1) for k in range(c.nan_bursts)]
        self.active: dict[str, str] = {}
        self.error: str | None = None
        self.calls = 0
        """Due ticks on which ``inner.step`` was called."""
        self.dropped = 0
        self._due = 0.0
        self._sample: np.ndarray = np.zeros(0)
        self._sample_t = 0.0
        self._next_sample = math.inf
        self._bursts: list[float] = []
        self._nan_left = 0

    def reset(self, t: float, x: np.ndarray) -> dict[str, str]:
        """Start ``inner`` at true time ``t`` [s] with features ``x`` (d,) (a sensor sample)."""
        self.error = None
        self.calls = self.dropped = 0
        self._nan_left = 0
        self._bursts = list(self.burst_at)
        self._sample = np.array(x, dtype=np.float64)
        self._sample_t = float(t)
        period = self.condition.sensor_period
        self._next_sample = math.inf if period is None else round(t + period, 10)
        self._due = round(t + self._period(), 10)
        self.active = dict(self.inner.reset(self._clock(t), self._sample.copy()))
        return dict(self.active)

    def next_period(self, t: float) -> float:
        """Seconds from true time ``t`` to the next due tick (> 0)."""
        return max(round(self._due - t, 10), 1e-6)

    def step(self, t: float, x: np.ndarray) -> dict[str, str]:
        """One tick of the loop at true time ``t`` [s] with true features ``x`` (d,)."""
        if self.error is not None or t < self._due - _EPS_T:
            return dict(self.active)
        while self._due <= t + _EPS_T:
            self._due = round(self._due + self._period(), 10)
        self._sense(t, x)
        seen = self._sample.copy()
        if self._bursts and t >= self._bursts[0] - _EPS_T:
            self._bursts.pop(0)
            self._nan_left = self.condition.nan_ticks
        if self._nan_left > 0:
            self._nan_left -= 1
            seen[:] = np.nan
        if self.condition.drop > 0 and self.rng.random() < self.condition.drop:
            self.dropped += 1
            return dict(self.active)
        options = {}
        if self.stamp_keyword is not None:
            options[self.stamp_keyword] = self._clock(self._sample_t)
        try:
            self.active = dict(self.inner.step(self._clock(t), seen, **options))
        except CpmpError as err:
            self.error = f"t={t:.3f} s: {err}"
        self.calls += 1
        return dict(self.active)

    def _period(self) -> float:
        c = self.condition
        u = self.rng.uniform(-c.jitter, c.jitter) if c.jitter > 0 else 0.0
        return (1.0 + u) / c.rate

    def _clock(self, t: float) -> float:
        """The policy's clock at true time ``t``."""
        return t + self.condition.clock_step if t >= self.step_at - _EPS_T else t

    def _sense(self, t: float, x: np.ndarray) -> None:
        """Take a sensor sample if one is due at true time ``t``."""
        period = self.condition.sensor_period
        if period is None:
            self._sample = np.array(x, dtype=np.float64)
            self._sample_t = t
        elif t >= self._next_sample - _EPS_T:
            self._sample = np.array(x, dtype=np.float64)
            self._sample_t = t
            while self._next_sample <= t + _EPS_T:
                self._next_sample = round(self._next_sample + period, 10)


# --------------------------------------------------------------------------------- episodes
@dataclass
class EpisodeRecord:
    """One closed-loop episode under a condition.

    Attributes:
        outcome: ``complete``, ``wrong_start`` or ``incomplete``.
        strategy: the episode's strategy.
        time: true time [s] the episode ended.
        sequences: variable -> executed MPs; ``expected``: the demonstrator's.
        switch_times: variable -> true times [s] of its switches.
        switch_errors: per paired switch, its time minus the demonstrator's [s].
        error: what the inner policy raised (the episode then stopped), or ``None``.
        calls, dropped: due ticks the inner policy was called on / dropped.
        recoveries, wrong_recoveries: recovery switches of the inner policy (if it reports
            ``events``), and those not the demonstrator's next MP.
        give_ups: stalls the inner policy gave up on (``give_up`` notes, if it reports
            ``notes``).
    """

    outcome: str
    strategy: str
    time: float
    sequences: dict[str, list[str]]
    expected: dict[str, list[str]]
    switch_times: dict[str, list[float]]
    switch_errors: list[float] = field(default_factory=list)
    error: str | None = None
    calls: int = 0
    dropped: int = 0
    recoveries: int = 0
    wrong_recoveries: int = 0
    give_ups: int = 0


def _switch_times(demo: Demonstration) -> dict[str, list[float]]:
    return {v: [float(demo.time[i]) for i in demo.switch_indices(v)] for v in demo.variables}


def _finish(
    record: EpisodeRecord, policy: ClockedPolicy, reference: Demonstration
) -> EpisodeRecord:
    """Fill ``record``'s errors, recoveries and call counts from the run and the reference."""
    if policy.error is not None:
        record.error = policy.error
        if record.outcome == "complete":
            record.outcome = "incomplete"
    record.calls, record.dropped = policy.calls, policy.dropped
    if record.outcome == "complete" and record.sequences == record.expected:
        ref = _switch_times(reference)
        record.switch_errors = [
            got - want
            for v in sorted(ref)
            for got, want in zip(record.switch_times.get(v, []), ref[v], strict=False)
        ]
    notes = getattr(policy.inner, "notes", None) or []
    record.give_ups = sum(note.kind == "give_up" for note in notes)
    seen: dict[str, int] = {}
    for event in getattr(policy.inner, "events", None) or []:
        k = seen.get(event.variable, 0) + 1
        seen[event.variable] = k
        if event.kind == "recovery":
            record.recoveries += 1
            want = record.expected.get(event.variable, [])
            if k >= len(want) or want[k] != event.target:
                record.wrong_recoveries += 1
    return record


def run_synthetic_episode(
    world: World, episode: object, policy: ClockedPolicy, reference: Demonstration
) -> EpisodeRecord:
    """One episode of a synthetic world with ``policy`` in the loop.

    Every tick lasts ``policy.next_period(t)``; the world integrates it in sub-steps of at most
    its own ``dt``. The episode ends when the run is done (the goal state, or a failure), at
    ``max_time``, or when the inner policy raised; it is scored by ``world.score``.

    Args:
        world: the world (:class:`~cpmp.worlds.protocol.World`).
        episode: one of ``world.contexts``.
        policy: the clocked policy (reset here).
        reference: the demonstrator's demonstration of ``episode``.

    Returns:
        The episode's record.
    """
    run = world.start(episode)
    want = mp_sequences(reference)
    active = dict(policy.reset(0.0, run.features()))
    seqs = {v: [active[v]] for v in want}
    times: dict[str, list[float]] = {v: [] for v in want}
    t = 0.0
    initial = dict(active)
    over = run.done(active)
    while not over and policy.error is None and t < world.max_time - 1e-9:
        h = policy.next_period(t)
        run.advance(active, h)
        t = round(t + h, 10)
        new = dict(policy.step(t, run.features()))
        for v in want:
            if new[v] != active[v]:
                seqs[v].append(new[v])
                times[v].append(t)
        active = new
        over = run.done(active)
    outcome = world.score(episode, initial, seqs, run.complete(active))
    record = EpisodeRecord(outcome, world.strategy(episode), t, seqs, want, times)
    return _finish(record, policy, reference)


def _rng(seed: int, condition: str, episode: int) -> np.random.Generator:
    """The clock's random numbers of one episode: from the seed, condition and episode."""
    return np.random.default_rng([seed, CONDITION_NAMES.index(condition), episode])


def synthetic_condition(
    world: World,
    seq: Policy,
    episodes: Sequence[object],
    references: Sequence[Demonstration],
    condition: ClockCondition,
    seed: int,
) -> list[EpisodeRecord]:
    """``seq`` on every episode of a synthetic world under ``condition``.

    Args:
        world: the world.
        seq: the fitted sequencer, or any policy (one episode at a time).
        episodes: the held-out episodes.
        references: the demonstrator's demonstration of each episode.
        condition: the clock.
        seed: the seed of the clock's random numbers (with the episode's index).

    Returns:
        One record per episode, in order.
    """
    return [
        run_synthetic_episode(
            world,
            episode,
            ClockedPolicy(seq, condition, _rng(seed, condition.name, i), ref.duration),
            ref,
        )
        for i, (episode, ref) in enumerate(zip(episodes, references, strict=True))
    ]


def sim_task(condition: ClockCondition, base: TaskConfig | None = None) -> TaskConfig:
    """The simulator's options under ``condition``.

    The control period is ``1 / rate`` with a physics step that divides it and is at most the
    default's; a jittered condition runs at :data:`SIM_BASE_DT` (the policy then wakes on its
    own schedule).
    """
    base = base or TaskConfig()
    control = SIM_BASE_DT if condition.jitter > 0 else 1.0 / condition.rate
    physics = control / max(1, round(control / base.physics_dt))
    return replace(base, control_dt=control, physics_dt=physics)


def sim_condition(
    seq: ConcurrentSequencer,
    boxes: Sequence[object],
    references: Sequence[Demonstration],
    condition: ClockCondition,
    seed: int,
) -> list[EpisodeRecord]:
    """``seq`` on every box of the simulator under ``condition`` (all boxes together).

    Args:
        seq: the fitted sequencer (one copy per box).
        boxes: the held-out boxes.
        references: the demonstrator's recording of each box (default options).
        condition: the clock.
        seed: the seed of the clock's random numbers (with the box's index).

    Returns:
        One record per box, in order.
    """
    cfg = sim_task(condition)
    policies = [
        ClockedPolicy(seq.with_config(), condition, _rng(seed, condition.name, i), ref.duration)
        for i, ref in enumerate(references)
    ]
    results = run_episodes(boxes, policies, cfg, expected=list(references))
    records = []
    for box, policy, ref, result in zip(boxes, policies, references, results, strict=True):
        times: dict[str, list[float]] = {v: [] for v in ref.variables}
        for event in result.transitions:
            times[event.variable].append(event.t)
        outcome = result.outcome if result.outcome != "diverged" else "incomplete"
        record = EpisodeRecord(
            outcome,
            correct_strategy(box, cfg),
            result.duration,
            result.sequences,
            result.expected,
            times,
        )
        records.append(_finish(record, policy, ref))
    return records


# --------------------------------------------------------------------------------- summary
def summarise(records: Sequence[EpisodeRecord]) -> dict[str, JsonValue]:
    """Counts and switch-time error of a condition's episodes (JSON-ready)."""
    counts = {o: sum(r.outcome == o for r in records) for o in OUTCOMES}
    errors = np.array([e for r in records for e in r.switch_errors])
    strategies = sorted({r.strategy for r in records})
    return {
        **counts,
        "same_sequences": sum(
            r.outcome == "complete" and r.sequences == r.expected for r in records
        ),
        "n_episodes": len(records),
        "errors": sum(r.error is not None for r in records),
        "dropped_ticks": sum(r.dropped for r in records),
        "recoveries": sum(r.recoveries for r in records),
        "wrong_recoveries": sum(r.wrong_recoveries for r in records),
        "give_ups": sum(r.give_ups for r in records),
        "switch_error": {
            "n": int(errors.size),
            "mean": float(errors.mean()) if errors.size else None,
            "mean_abs": float(np.abs(errors).mean()) if errors.size else None,
            "max_abs": float(np.abs(errors).max()) if errors.size else None,
        },
        "by_strategy": {
            s: {
                "complete": sum(r.outcome == "complete" for r in records if r.strategy == s),
                "n_episodes": sum(r.strategy == s for r in records),
            }
            for s in strategies
        },
    }


def _episode_row(r: EpisodeRecord) -> dict[str, JsonValue]:
    return {
        "strategy": r.strategy,
        "outcome": r.outcome,
        "time": round(r.time, 6),
        "sequences": r.sequences,
        "switch_errors": [round(e, 6) for e in r.switch_errors],
        "error": r.error,
        "recoveries": r.recoveries,
        "wrong_recoveries": r.wrong_recoveries,
        "give_ups": r.give_ups,
    }


@dataclass(frozen=True)
class ClockSettings:
    """What :func:`run_clock_benchmark` measures.

    Attributes:
        worlds: any of :data:`WORLDS`.
        conditions: any of :data:`CONDITION_NAMES` (the reference is always included).
        seeds: seeds of the synthetic worlds (demonstrations, fit, held-out episodes).
        demos: demonstrations per synthetic fit.
        episodes: held-out episodes per synthetic world and seed.
        sim_seeds: seeds of the simulator.
        sim_demos: simulated demonstrations per fit.
        sim_boxes: held-out boxes per simulator seed.
        tasks: members run of a family world (the procedural one), pooled with the seeds.
    """

    worlds: tuple[str, ...] = WORLDS
    conditions: tuple[str, ...] = CONDITION_NAMES
    seeds: tuple[int, ...] = (0, 1, 2)
    demos: int = 6
    episodes: int = 20
    sim_seeds: tuple[int, ...] = (0,)
    sim_demos: int = 6
    sim_boxes: int = 6
    tasks: int = 10

    def __post_init__(self) -> None:
        unknown = [w for w in self.worlds if w not in WORLDS]
        unknown += [c for c in self.conditions if c not in CONDITION_NAMES]
        if unknown:
            raise ConfigError(
                f"unknown worlds or conditions {unknown}; worlds: {', '.join(WORLDS)}; "
                f"conditions: {', '.join(CONDITION_NAMES)}"
            )
        for name in ("demos", "episodes", "sim_demos", "sim_boxes", "tasks"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ConfigError(f"{name} must be a positive integer, got {value!r}")

    @classmethod
    def quick(cls, **options: object) -> ClockSettings:
        """Small sizes for a test: the synthetic worlds, seed 0, 2 episodes, one family member."""
        quick = {"worlds": SYNTHETIC_WORLDS, "seeds": (0,), "episodes": 2, "tasks": 1}
        return cls(**{**quick, **options})


def _conditions(settings: ClockSettings) -> list[ClockCondition]:
    names = set(settings.conditions) | {REFERENCE}
    return [c for c in CONDITIONS if c.name in names]


def _fit(demos: Sequence[Demonstration], seed: int) -> ConcurrentSequencer:
    """The current default sequencer, as the tests fit it."""
    return ConcurrentSequencer.fit(demos, seed=seed, logger=None)


def bench_synthetic_world(
    name: str, settings: ClockSettings, log: Callable[[str], None] | None = None
) -> dict[str, JsonValue]:
    """Every condition of ``settings`` on the synthetic world ``name``, pooled over seeds.

    A family world (the procedural one) pools its first ``settings.tasks`` members too.

    The world's feature-only scripted policy runs the same episodes under every condition
    beside the sequencer (``scripted``): how far the world stays fair on that clock.

    Returns:
        ``{"conditions": {condition: summary}, "per_seed": {seed: {condition: summary}},
        "per_episode": {condition: [row, ...]}, "scripted": {condition: summary}}``
        (summaries: :func:`summarise`).
    """
    pooled: dict[str, list[EpisodeRecord]] = {}
    scripted: dict[str, list[EpisodeRecord]] = {}
    per_seed: dict[str, dict[str, JsonValue]] = {}
    for seed in settings.seeds:
        by_condition: dict[str, list[EpisodeRecord]] = {}
        for world in members(name, settings.tasks):
            seq = _fit(world.demonstrations(settings.demos, seed), seed)
            episodes = world.contexts(settings.episodes, HELD_OUT_SEED + seed)
            references = [world.demonstrate(e) for e in episodes]
            for condition in _conditions(settings):
                records = synthetic_condition(world, seq, episodes, references, condition, seed)
                by_condition.setdefault(condition.name, []).extend(records)
                fair = world.scripted_policy()
                scripted.setdefault(condition.name, []).extend(
                    synthetic_condition(world, fair, episodes, references, condition, seed)
                )
        per_seed[str(seed)] = {}
        for condition, records in by_condition.items():
            pooled.setdefault(condition, []).extend(records)
            summary = summarise(records)
            per_seed[str(seed)][condition] = summary
            if log is not None:
                log(f"{name} seed {seed} {condition}: {summary['complete']}/{len(records)}")
    result = _world_result(pooled, per_seed)
    result["scripted"] = {c: summarise(records) for c, records in scripted.items()}
    return result


def bench_sim(
    settings: ClockSettings, log: Callable[[str], None] | None = None
) -> dict[str, JsonValue]:
    """Every condition of ``settings`` on the simulator, pooled over ``sim_seeds``.

    Returns:
        As :func:`bench_synthetic_world`.
    """
    cfg = TaskConfig()
    pooled: dict[str, list[EpisodeRecord]] = {}
    per_seed: dict[str, dict[str, JsonValue]] = {}
    for seed in settings.sim_seeds:
        train_boxes = sample_boxes(np.random.default_rng(seed), cfg, settings.sim_demos, True)
        names = [f"demo_{i:03d}" for i in range(len(train_boxes))]
        seq = _fit(record_demonstrations(train_boxes, cfg, names=names), seed)
        boxes = sample_boxes(
            np.random.default_rng(HELD_OUT_SEED + seed), cfg, settings.sim_boxes, True
        )
        references = record_demonstrations(boxes, cfg)
        per_seed[str(seed)] = {}
        for condition in _conditions(settings):
            records = sim_condition(seq, boxes, references, condition, seed)
            pooled.setdefault(condition.name, []).extend(records)
            summary = summarise(records)
            per_seed[str(seed)][condition.name] = summary
            if log is not None:
                log(f"sim seed {seed} {condition.name}: {summary['complete']}/{len(records)}")
    return _world_result(pooled, per_seed)


def _world_result(
    pooled: Mapping[str, list[EpisodeRecord]], per_seed: dict[str, dict[str, JsonValue]]
) -> dict[str, JsonValue]:
    return {
        "conditions": {name: summarise(records) for name, records in pooled.items()},
        "per_seed": per_seed,
        "per_episode": {
            name: [_episode_row(r) for r in records] for name, records in pooled.items()
        },
    }


def run_clock_benchmark(
    settings: ClockSettings, log: Callable[[str], None] | None = None
) -> dict[str, JsonValue]:
    """The clock benchmark of ``settings`` (JSON-ready; the same settings give the same dict).

    Args:
        settings: worlds, conditions, seeds and sizes.
        log: called with a line per world, seed and condition as each is done.

    Returns:
        ``{"settings", "conditions": {name: ClockCondition fields}, "reference", "scoring",
        "worlds": {world: ...}}`` (per world: :func:`bench_synthetic_world`; ``scoring``:
        :data:`SCORING`).
    """
    result: dict[str, JsonValue] = {
        "settings": asdict(settings),
        "conditions": {c.name: asdict(c) for c in _conditions(settings)},
        "reference": REFERENCE,
        "scoring": SCORING,
        "worlds": {},
    }
    for name in settings.worlds:
        if name == "sim":
            result["worlds"][name] = bench_sim(settings, log)
        else:
            result["worlds"][name] = bench_synthetic_world(name, settings, log)
    return to_builtin(result)


def markdown(result: Mapping[str, JsonValue]) -> str:
    """Completion per world and condition as a Markdown table.

    Each cell: ``complete / episodes``, then the mean absolute switch-time error in ms; a
    synthetic world's scripted policy on the same episodes in the row below it.
    """
    names = list(result["conditions"])
    lines = [
        "| world | " + " | ".join(names) + " |",
        "| --- |" + " --- |" * len(names),
    ]
    for world, data in result["worlds"].items():
        cells = []
        for name in names:
            s = data["conditions"][name]
            err = s["switch_error"]["mean_abs"]
            ms = "-" if err is None else f"{1000 * err:.0f} ms"
            cells.append(f"{s['complete']}/{s['n_episodes']} ({ms})")
        lines.append(f"| {world} | " + " | ".join(cells) + " |")
        if "scripted" in data:
            fair = [
                f"{data['scripted'][n]['complete']}/{data['scripted'][n]['n_episodes']}"
                for n in names
            ]
            lines.append(f"| {world} (scripted) | " + " | ".join(fair) + " |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """``scripts/bench_clock.py``: run the clock benchmark, write its JSON, print the table.

    Args:
        argv: the command line (default ``sys.argv[1:]``).

    Returns:
        The exit status: 0, or 2 after a :class:`~cpmp.errors.CpmpError` (a bad option).
    """
    parser = argparse.ArgumentParser(
        description=(
            "Completion and switch-time error of the default sequencer on every synthetic "
            "world and the simulator under control rates, jitter, dropped ticks, slow "
            "sensors, a clock step and NaN bursts. Writes JSON, prints a Markdown table."
        )
    )
    parser.add_argument("--out", default="logs/bench_clock.json", help="the JSON file")
    parser.add_argument("--quick", action="store_true", help="ClockSettings.quick (a test)")
    parser.add_argument("--worlds", nargs="+", choices=WORLDS, help=f"default: {WORLDS}")
    parser.add_argument("--conditions", nargs="+", choices=CONDITION_NAMES, help="default: all")
    parser.add_argument("--seeds", type=int, nargs="+", help="synthetic seeds (0 1 2)")
    parser.add_argument("--demos", type=int, help="demonstrations per synthetic fit (6)")
    parser.add_argument("--episodes", type=int, help="held-out episodes per world, seed (20)")
    parser.add_argument("--sim-seeds", type=int, nargs="+", help="simulator seeds (0)")
    parser.add_argument("--sim-demos", type=int, help="simulated demonstrations per fit (6)")
    parser.add_argument("--sim-boxes", type=int, help="held-out boxes per simulator seed (6)")
    parser.add_argument("--tasks", type=int, help="members of a family world (10)")
    args = parser.parse_args(argv)
    names = ("worlds", "conditions", "seeds", "demos", "episodes", "sim_seeds", "sim_demos")
    options = given_options(args, (*names, "sim_boxes", "tasks"))
    return run_settings_benchmark(
        "bench_clock", args, ClockSettings, options, run_clock_benchmark, markdown
    )
