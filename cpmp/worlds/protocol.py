"""The one interface every synthetic world implements, and the closed loop that drives it.

A *world* (:class:`World`) is a concurrent task without MuJoCo: it draws *contexts* (the random
parameters of one episode: goals, sizes, hidden events), records the scripted demonstrator's
labelled demonstration of a context, starts a *run* of a context (:class:`WorldRun`: features
now, advance under the active MPs for any time step, done and complete), names the strategy of
a context, and offers a scripted policy that reads only the features (the proof that the world
is fair: its switches can be decided from what a learned sequencer sees).

Every consumer (the benchmarks, the comparison, the tests) drives a world through
:func:`run_episodes` / :func:`evaluate` and finds it by name in :mod:`cpmp.worlds.registry`;
nothing outside a world's own module knows its state.

Scoring (:meth:`World.score`, :class:`WorldBase`): ``wrong_start`` when the policy's initial
MPs differ from the demonstrator's for the context, else ``complete`` when the run reached the
goal (:meth:`WorldRun.complete`; for a ``strict`` world also running exactly the
demonstrator's MP sequences of the same context, hidden events included), else
``incomplete``; an incomplete episode names its cause (:attr:`EpisodeRun.cause`: the
demonstrated switch that never came and why, :func:`~cpmp.records.episode_cause`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, ClassVar, Generic, Protocol, TypeVar, runtime_checkable

import numpy as np
from typing_extensions import override

from cpmp.data import Demonstration
from cpmp.errors import ConfigError
from cpmp.records import PendingSwitch, Policy, TickInfo, episode_cause
from cpmp.worlds.common import (
    Episode,
    State,
    SteppedTask,
    note_switches,
    positive_count,
    seeded_episodes,
)
from cpmp.worlds.outcomes import Outcome, count_outcomes, episode_outcome

_EPS_T = 1e-9
"""Slack [s] when comparing times (ticks are rounded sums of periods)."""

Context = TypeVar("Context")
"""A world's context type (its own record: ``RelayEpisode``, ``PegContext``, ...)."""


class StrategicEpisode(Protocol):
    """A stepped task's episode, the context of a :class:`SteppedWorld`: it names its strategy."""

    @property
    def strategy(self) -> str:
        """The episode's strategy (one of the world's ``strategies``)."""
        ...


Strategic = TypeVar("Strategic", bound=StrategicEpisode)
"""The episode type of a :class:`SteppedWorld`."""


@runtime_checkable
class WorldRun(Protocol):
    """One episode of a world in progress: its state behind features, advance and checks.

    A run may also have ``failure() -> str``: at the end of an episode that is not complete,
    what went wrong in the world, in words (a failure nothing undoes and when, or the goal
    conditions not met); ``""`` when it has nothing to say. :func:`run_episode` puts it into
    an incomplete episode's cause (:func:`run_failure`). It is optional, so that a world
    written without it still runs.
    """

    def features(self) -> np.ndarray:
        """The true features ``(d,)`` now, in the world's ``feature_names`` order."""
        ...

    def advance(self, active: Mapping[str, str], h: float) -> None:
        """Run the ``active`` MPs for ``h`` [s] (in sub-steps of at most the world's ``dt``)."""
        ...

    def done(self, active: Mapping[str, str]) -> bool:
        """Whether the episode is over: the goal reached, or a failure nothing can undo."""
        ...

    def complete(self, active: Mapping[str, str]) -> bool:
        """Whether the goal state is reached (with the MPs ``active`` now)."""
        ...


@runtime_checkable
class World(Protocol[Context]):
    """A synthetic concurrent task (see the module doc), with contexts of type ``Context``.

    Attributes:
        name: its registry name.
        variables: the control variables, in the labels' order.
        feature_names: the ``d`` features.
        strategies: the strategies its contexts cycle through (for tables).
        dt: its own step and the demonstrations' sample period [s].
        max_time: an episode's time limit [s].
    """

    name: str
    variables: tuple[str, ...]
    feature_names: tuple[str, ...]
    strategies: tuple[str, ...]
    dt: float
    max_time: float

    def demonstrations(self, n: int, seed: int) -> list[Demonstration]:
        """``n`` training demonstrations, reproducible from ``seed``, named ``demo_<i>``."""
        ...

    def contexts(self, n: int, seed: int) -> list[Context]:
        """``n`` closed-loop contexts drawn from ``seed`` (use another seed than the demos')."""
        ...

    def demonstrate(self, context: Context, name: str | None = None) -> Demonstration:
        """The scripted demonstrator's labelled demonstration of ``context``."""
        ...

    def start(self, context: Context) -> WorldRun:
        """A run of ``context`` at ``t = 0``."""
        ...

    def strategy(self, context: Context) -> str:
        """The strategy of ``context`` (one of :attr:`strategies`)."""
        ...

    def initial_mps(self, context: Context) -> dict[str, str]:
        """The demonstrator's initial MP per variable for ``context``."""
        ...

    def scripted_policy(self) -> Policy:
        """A fresh policy that reads only the features and completes the task."""
        ...

    def score(
        self,
        context: Context,
        initial: Mapping[str, str],
        sequences: Mapping[str, Sequence[str]],
        completed: bool,
    ) -> Outcome:
        """The outcome of a run of ``context`` (see the module doc)."""
        ...


@dataclass
class EpisodeRun:
    """One closed-loop episode of a world (:func:`run_episodes`).

    Attributes:
        outcome: ``complete``, ``wrong_start`` or ``incomplete`` (:meth:`World.score`).
        strategy: the context's strategy.
        initial: the policy's initial MPs.
        sequences: variable -> the MPs it ran, in order.
        time: when the episode ended [s] (done, or the time limit).
        completed: whether the goal state was reached (also after a wrong start).
        cause: an ``incomplete`` episode's missing switch against the demonstrator's MP
            sequences of the context (:func:`~cpmp.records.episode_cause`: explained by a
            fitted sequencer, ``unknown`` why for other policies); ``None`` otherwise.
    """

    outcome: Outcome
    strategy: str
    initial: dict[str, str]
    sequences: dict[str, list[str]]
    time: float
    completed: bool
    cause: PendingSwitch | None = None


@dataclass
class Evaluation:
    """A policy's closed-loop episodes on one world (:func:`evaluate`).

    Attributes:
        world: the world's name.
        episodes: one run per context, in order.
        counts: outcome -> episodes (every outcome present).
    """

    world: str
    episodes: list[EpisodeRun]
    counts: dict[Outcome, int] = field(init=False)

    def __post_init__(self) -> None:
        self.counts = count_outcomes(e.outcome for e in self.episodes)

    @property
    def complete(self) -> int:
        """Complete episodes."""
        return self.counts["complete"]


class WorldBase(Generic[Context]):
    """What the registered worlds share: the score, and a stepped task's contexts and runs.

    A subclass is a :class:`World` of contexts ``Context``: it gives ``variables``,
    :meth:`~World.demonstrate` and :meth:`~World.initial_mps`, which these methods call.

    Attributes:
        strict: ``complete`` also needs the demonstrator's exact MP sequences
            (:meth:`expected_sequences`); otherwise the start and the goal state decide.
    """

    strict: ClassVar[bool] = False
    variables: tuple[str, ...]

    if TYPE_CHECKING:  # given by the subclass (a stub here would shadow a mixin's)

        def demonstrate(self, context: Context, name: str | None = None) -> Demonstration:
            """The demonstrator's demonstration of ``context`` (:meth:`World.demonstrate`)."""
            ...

        def initial_mps(self, context: Context) -> dict[str, str]:
            """The demonstrator's initial MPs for ``context`` (:meth:`World.initial_mps`)."""
            ...

    def expected_sequences(self, context: Context) -> dict[str, list[str]]:
        """The demonstrator's MPs per variable in ``context`` (of :meth:`World.demonstrate`)."""
        from cpmp.data.demonstration import mp_sequences  # the demonstration only when scoring

        return mp_sequences(self.demonstrate(context))

    def score(
        self,
        context: Context,
        initial: Mapping[str, str],
        sequences: Mapping[str, Sequence[str]],
        completed: bool,
    ) -> Outcome:
        """``wrong_start`` / ``complete`` / ``incomplete`` (see the module doc)."""
        started = dict(initial) == self.initial_mps(context)
        if not (self.strict and started and completed):
            return episode_outcome(started, completed)
        want = self.expected_sequences(context)
        return episode_outcome(True, all(list(sequences[v]) == want[v] for v in self.variables))


class SteppedRun(Generic[State, Episode]):
    """One episode of a stepped task in progress (a :class:`WorldRun`).

    The task is a :class:`~cpmp.worlds.common.SteppedTask` whose ``features(state, episode)``
    gives the features and whose ``advance`` takes a step ``dt`` (the relay's and the
    repetition's); done and complete at its goal state.
    """

    def __init__(self, task: SteppedTask[State, Episode], episode: Episode) -> None:
        self.task, self.episode = task, episode
        self.state = task.initial_state(episode)

    @override
    def features(self) -> np.ndarray:
        return self.task.features(self.state, self.episode)  # type: ignore[attr-defined]

    @override
    def advance(self, active: Mapping[str, str], h: float) -> None:
        n, hs = substeps(h, self.task.dt)
        for _ in range(n):
            self.task.advance(self.state, self.episode, dict(active), dt=hs)  # type: ignore[call-arg]

    @override
    def done(self, active: Mapping[str, str]) -> bool:
        return self.complete(active)

    @override
    def complete(self, active: Mapping[str, str]) -> bool:
        return self.task.at_goal(self.state, self.episode)

    def failure(self) -> str:
        """Why the run is not complete, in words.

        The task's ``shortfall(state, episode)``; ``""`` for a task without one, or at the goal.
        """
        shortfall = getattr(self.task, "shortfall", None)
        return str(shortfall(self.state, self.episode)) if callable(shortfall) else ""


class SteppedWorld(WorldBase[Strategic]):
    """A world around a stepped task (see :class:`SteppedRun`): contexts cycle ``strategies``.

    Its contexts are the task's episodes (``Strategic``: each names its ``strategy``).

    A subclass names its ``strategies`` and gives :meth:`demonstrations`,
    :meth:`demonstrate` and :meth:`scripted_policy`.
    """

    strategies: tuple[str, ...]

    def __init__(self, task: SteppedTask[object, Strategic]) -> None:
        self.task = task
        self.dt = task.dt
        self.max_time = task.max_time

    def contexts(self, n: int, seed: int) -> list[Strategic]:
        """``n`` episodes cycling the strategies (the first is ``strategies[0]``)."""
        return seeded_episodes(self.task.sample_episode, self.strategies, n, seed)  # type: ignore[attr-defined]

    def start(self, context: Strategic) -> WorldRun:
        """A :class:`SteppedRun` of ``context``."""
        return SteppedRun(self.task, context)

    def strategy(self, context: Strategic) -> str:
        """The episode's ``strategy``."""
        return str(context.strategy)

    def initial_mps(self, context: Strategic) -> dict[str, str]:
        """The task's initial MPs of the episode."""
        return self.task.initial_mps(context)


def run_episodes(
    world: World[Context],
    policy: Policy,
    contexts: Sequence[Context],
    observe: Callable[[np.ndarray], np.ndarray] | None = None,
) -> list[EpisodeRun]:
    """Run ``policy`` closed-loop on every context, one tick every ``world.dt``.

    Each episode: ``reset`` at ``t = 0`` on the run's features, then per tick ``advance`` by
    ``dt`` under the active MPs, ``step`` on the new features, until the run is done or
    ``max_time``. A policy with ``batched(n)`` (a fitted
    :class:`~cpmp.sequencer.ConcurrentSequencer`) runs every episode at once, one ``step`` per
    tick over the episodes still running, with the results it gives one episode at a time.

    Args:
        world: the world.
        policy: the policy (a fresh ``reset`` per episode, or one batch of them).
        contexts: the contexts (:meth:`World.contexts`).
        observe: maps the true features ``(d,)`` to what the policy sees (noise, say); the
            episodes then run one at a time, in order. Default: the true features.

    Returns:
        One run per context, in order.
    """
    make_batch = getattr(policy, "batched", None)
    if make_batch is None or observe is not None or not contexts:
        return [run_episode(world, policy, c, observe) for c in contexts]
    n = len(contexts)
    batch = make_batch(n)
    runs = [world.start(c) for c in contexts]
    x = np.stack([r.features() for r in runs])
    active = [dict(a) for a in batch.reset(0.0, x)]
    initial = [dict(a) for a in active]
    seqs = [{v: [a[v]] for v in world.variables} for a in active]
    over = np.array([r.done(a) for r, a in zip(runs, active, strict=True)])
    times = [0.0] * n
    t = 0.0
    while not over.all() and t < world.max_time - _EPS_T:
        live = ~over
        rows = np.flatnonzero(live).tolist()
        for i in rows:
            runs[i].advance(active[i], world.dt)
            x[i] = runs[i].features()
        t = round(t + world.dt, 10)
        stepped = batch.step(t, x, live=live)
        for i in rows:
            active[i] = dict(stepped[i])
            note_switches(seqs[i], active[i])
            over[i] = runs[i].done(active[i])
            times[i] = t
    return [
        score_episode(
            world, contexts[i], initial[i], seqs[i], times[i], runs[i], active[i], batch, i
        )
        for i in range(n)
    ]


def run_episode(
    world: World[Context],
    policy: Policy,
    context: Context,
    observe: Callable[[np.ndarray], np.ndarray] | None = None,
    on_tick: Callable[[TickInfo], None] | None = None,
) -> EpisodeRun:
    """One episode of :func:`run_episodes` on ``context``, one policy call per tick.

    Args:
        world: the world.
        policy: the policy (``reset`` at ``t = 0``, then ``step`` every ``world.dt``).
        context: the episode's context.
        observe: maps the true features ``(d,)`` to what the policy sees (default: them).
        on_tick: called after ``reset`` and after every ``step`` with the time, the active
            MPs and the true features (e.g. a recording,
            :mod:`cpmp.experiment.world_recording`).

    Returns:
        The scored run.
    """
    see = observe or (lambda x: x)
    run = world.start(context)
    x = run.features()
    active = dict(policy.reset(0.0, see(x)))
    if on_tick is not None:
        on_tick(TickInfo(0.0, active=dict(active), features=x))
    initial = dict(active)
    seqs = {v: [active[v]] for v in world.variables}
    t = 0.0
    over = run.done(active)
    while not over and t < world.max_time - _EPS_T:
        run.advance(active, world.dt)
        t = round(t + world.dt, 10)
        x = run.features()
        active = dict(policy.step(t, see(x)))
        if on_tick is not None:
            on_tick(TickInfo(t, active=dict(active), features=x))
        note_switches(seqs, active)
        over = run.done(active)
    return score_episode(world, context, initial, seqs, t, run, active, policy)


def failure_text(shortfall: str, failed_at: float | None) -> str:
    """A run's ``failure()`` from its task's ``shortfall`` and when a failure happened [s].

    ``" at <t> s"`` follows ``shortfall`` after a failure nothing undoes (``failed_at`` set).
    """
    if shortfall and failed_at is not None:
        return f"{shortfall} at {failed_at:.2f} s"
    return shortfall


def run_failure(run: WorldRun) -> str:
    """What went wrong in ``run``, in words: its ``failure()``, ``""`` if it has none."""
    failure = getattr(run, "failure", None)
    return str(failure()) if callable(failure) else ""


def score_episode(
    world: World[Context],
    context: Context,
    initial: dict[str, str],
    sequences: dict[str, list[str]],
    time: float,
    run: WorldRun,
    active: Mapping[str, str],
    policy: object = None,
    index: int | None = None,
) -> EpisodeRun:
    """Score an episode: its outcome, and an incomplete one's cause.

    :func:`run_episodes` and :func:`run_episode` score their episodes with it.

    Args:
        world: the world.
        context: the episode's context.
        initial: the policy's initial MPs.
        sequences: variable -> the MPs it ran, in order.
        time: when the episode ended [s].
        run: the episode's run at its end: whether it completed (with the MPs ``active``
            then), and what went wrong in the world if not (:func:`run_failure`, added to an
            incomplete episode's cause as its ``detail``, after the sequencer's own).
        active: the MPs active at the end.
        policy: the policy that ran it, asked for an incomplete episode's cause
            (:func:`~cpmp.records.episode_cause`: a fitted sequencer explains it; ``None`` or
            another policy: ``unknown`` why).
        index: the episode's index in a batched ``policy`` (``None``: a single policy).

    Returns:
        The scored :class:`EpisodeRun`.
    """
    completed = run.complete(active)
    outcome = world.score(context, initial, sequences, completed)
    cause = None
    if outcome == "incomplete":
        cause = episode_cause(policy, sequences, expected_sequences(world, context), index)
        failure = "" if completed else run_failure(run)
        if cause is not None and failure:
            detail = f"{cause.detail}; {failure}" if cause.detail else failure
            cause = replace(cause, detail=detail)
    return EpisodeRun(outcome, world.strategy(context), initial, sequences, time, completed, cause)


def expected_sequences(world: World[Context], context: Context) -> dict[str, list[str]]:
    """The demonstrator's MPs per variable in ``context`` (from its demonstration)."""
    known = getattr(world, "expected_sequences", None)
    if callable(known):
        return dict(known(context))
    from cpmp.data.demonstration import mp_sequences  # the demonstration only when scoring

    return mp_sequences(world.demonstrate(context))


def evaluate(
    world: World,
    policy: Policy,
    n_episodes: int = 20,
    seed: int = 0,
    observe: Callable[[np.ndarray], np.ndarray] | None = None,
) -> Evaluation:
    """``policy`` on ``n_episodes`` contexts of ``world`` drawn from ``seed``.

    Args:
        world: the world.
        policy: the policy (a fitted sequencer, a baseline, the world's scripted policy).
        n_episodes: the number of episodes.
        seed: seeds the contexts (another than the demonstrations' for held-out ones).
        observe: as in :func:`run_episodes`.

    Returns:
        The episodes and their counts.

    Raises:
        ConfigError: ``n_episodes`` is not a positive integer.
    """
    positive_count(n_episodes, "n_episodes")
    contexts = world.contexts(n_episodes, seed)
    return Evaluation(world.name, run_episodes(world, policy, contexts, observe))


def substeps(h: float, dt: float) -> tuple[int, float]:
    """``h`` [s] as ``n`` equal steps no longer than ``dt`` (one step of ``dt`` if ``h == dt``).

    Raises:
        ConfigError: ``h`` is not a positive finite time.
    """
    if not np.isfinite(h) or h <= 0:
        raise ConfigError(f"a world advances by a positive time step, got {h!r} s")
    n = max(1, int(np.ceil(h / dt - 1e-9)))
    return n, h / n
