"""Running policies closed-loop on the simulator, and the checks that decide each outcome.

One episode (:func:`run_episode`) or many boxes together (:func:`run_episodes`, one batched IK
and one batched policy call per tick, the same results as one box at a time); each episode
ends with an :data:`Outcome`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Literal, get_args

import numpy as np

from cpmp.config.task import TaskConfig, as_task_config
from cpmp.config.validation import OptionValue
from cpmp.data.demonstration import Demonstration, mp_sequences
from cpmp.errors import UnknownMPError
from cpmp.records import (
    BatchedPolicy,
    PendingSwitch,
    Policy,
    TickInfo,
    TransitionEvent,
    episode_cause,
)
from cpmp.sim.collect import ROBOT_STREAM, make_pacer, record_demonstrations
from cpmp.sim.policies import PolicyList, as_batched, per_episode
from cpmp.sim.scene import Box, correct_strategy
from cpmp.sim.simulation import Simulation, prepare_steps
from cpmp.worlds.outcomes import Outcome as WorldOutcome

Outcome = Literal[WorldOutcome, "diverged"]
"""How a closed-loop episode in the simulator ended: a world's outcome, or ``diverged``.

``complete``: box in the container, hands home, MP sequences equal to the demonstrator's;
``wrong_start``: the initial MPs differ from the correct strategy's; ``incomplete``: a wrong
transition, a deadlock or a time-out; ``diverged``: NaN or unstable physics (counted as
incomplete in Table I).
"""
OUTCOMES: tuple[Outcome, ...] = get_args(Outcome)
"""Every :data:`Outcome`."""
STILL_SPEED = 0.02
"""Joint speed [rad/s] below which the robot counts as standing still (deadlock detection)."""


@dataclass
class EpisodeResult:
    """Outcome of :func:`run_episode`.

    ``outcome``: how it ended (:data:`Outcome`), ``reason`` says why in words.
    ``transitions``: every MP switch the policy made, in order; the runner sees only the active
    MPs, so each has ``probability`` nan and ``kind`` ``switch``, and ``state`` is the feature
    vector (d,) the policy switched on. ``cause``: for an ``incomplete`` or ``diverged``
    episode, the demonstrated switch that never came (:class:`~cpmp.records.PendingSwitch`,
    explained by a fitted sequencer, ``unknown`` why for other policies; its words end
    ``reason``); ``None`` otherwise.
    """

    outcome: Outcome
    reason: str
    sequences: dict[str, list[str]]
    transitions: list[TransitionEvent]
    initial: dict[str, str]
    duration: float
    box_in_container: bool
    hands_home: bool
    expected: dict[str, list[str]] = field(default_factory=dict)
    timing: dict[str, float] = field(default_factory=dict)
    cause: PendingSwitch | None = None


def _normalise(active: Mapping[str, str], variables: list[str]) -> dict[str, str]:
    """Accept short (``lift``) or qualified (``right_pos.lift``) MP names."""
    out = {}
    for variable in variables:
        if variable not in active:
            raise UnknownMPError(f"policy gave no MP for control variable {variable!r}")
        name = str(active[variable])
        prefix = f"{variable}."
        out[variable] = name[len(prefix) :] if name.startswith(prefix) else name
    return out


def run_episode(
    box: Box,
    policy: Policy,
    cfg: TaskConfig | Mapping[str, OptionValue] | None = None,
    max_time: float | None = None,
    expected: Demonstration | None = None,
    on_tick: Callable[[TickInfo], None] | None = None,
) -> EpisodeResult:
    """Execute ``policy`` closed-loop on ``box`` and classify the outcome.

    policy: ``reset(t, x)`` / ``step(t, x)`` -> dict variable -> MP name, called every control
    tick with the feature vector ``x`` (d,). expected: the demonstrator's recording for ``box``
    (recorded here if None). Physics divergence ends the episode with outcome "diverged"; it
    never raises. An unknown MP name raises :class:`~cpmp.errors.UnknownMPError`.
    :func:`run_episodes` with one box (the same loop).
    """
    return run_episodes(
        [box],
        PolicyList([policy]),
        cfg,
        expected=[expected],
        max_time=max_time,
        on_tick=[on_tick],
    )[0]


def run_episodes(
    boxes: Sequence[Box],
    policy: Policy | BatchedPolicy | Sequence[Policy],
    cfg: TaskConfig | Mapping[str, OptionValue] | None = None,
    expected: Sequence[Demonstration | None] | None = None,
    max_time: float | None = None,
    on_tick: Sequence[Callable[[TickInfo], None] | None] | None = None,
    on_result: Callable[[int, EpisodeResult], None] | None = None,
    pacing_seed: int | None = None,
) -> list[EpisodeResult]:
    """Execute one closed-loop episode per box, all together.

    The results are those of :func:`run_episode` on each box alone (same outcomes,
    transitions and times).

    Every control tick: one batched pose/Jacobian and IK call over the running episodes'
    robots, MuJoCo stepping each episode's own model, and one batched policy call ``(N, d)``
    with the running episodes marked ``live``. An episode that ends (outcome decided) is left
    out of the following ticks.

    policy: a policy with ``batched(N)`` (a fitted :class:`~cpmp.sequencer.ConcurrentSequencer`,
        batched here), a :class:`BatchedPolicy` of ``N`` episodes (e.g. your own
        ``seq.batched(N)``, to read each episode's events and notes afterwards), a sequence of
        ``N`` single :class:`Policy` objects (one per box, e.g. scripted baselines), or, for one
        box, a single :class:`Policy`.
    expected: per box, the demonstrator's recording (recorded here where ``None``).
    on_tick: per box, a callback as in :func:`run_episode` (or ``None``).
    on_result: called with ``(index, result)`` as each episode ends (e.g. a progress bar).
    pacing_seed: with the task's ``robot_*`` pacing options set, the robot's MPs in episode ``i``
        are paced from the seed ``(pacing_seed, ROBOT_STREAM, i)`` (default: the task's
        ``seed``); the policy is not told.
    """
    cfg = as_task_config(cfg)
    boxes = list(boxes)
    n = len(boxes)
    if n == 0:
        return []
    max_time = cfg.max_time if max_time is None else float(max_time)
    batch = as_batched(policy, n)
    expected = per_episode(expected, n, "expected")
    callbacks = per_episode(on_tick, n, "on_tick")
    missing = [i for i, demo in enumerate(expected) if demo is None]
    recorded = record_demonstrations([boxes[i] for i in missing], cfg)
    for i, demo in zip(missing, recorded, strict=True):
        expected[i] = demo
    base = cfg.seed if pacing_seed is None else int(pacing_seed)
    runs = [
        _Rollout(i, box, cfg, demo, tick, on_result, (base, ROBOT_STREAM, i))
        for i, (box, demo, tick) in enumerate(zip(boxes, expected, callbacks, strict=True))
    ]
    for run in runs:
        run.explainer = _explainer(batch, run.index)
    x = np.stack([run.x for run in runs])
    start = time.perf_counter()
    initial = batch.reset(0.0, x)
    share = (time.perf_counter() - start) / n
    for run in runs:
        run.policy_time += share
        run.start(initial[run.index])
    live = np.zeros(n, dtype=bool)
    for k in range(round(max_time / cfg.control_dt)):
        running = [run for run in runs if run.result is None]
        if not running:
            break
        for run in running:
            run.before_tick()
        prepare_steps([run.sim for run in running])
        stepped = [run for run in running if run.physics_step()]
        if not stepped:
            continue
        t = (k + 1) * cfg.control_dt
        live[:] = False
        for run in stepped:
            run.x = run.sim.features()
            x[run.index] = run.x
            live[run.index] = True
        start = time.perf_counter()
        new = batch.step(t, x, live=live)
        share = (time.perf_counter() - start) / len(stepped)
        for run in stepped:
            run.policy_time += share
            run.after_tick(t, new[run.index])
    for run in runs:
        if run.result is None:
            run.finish("incomplete", f"time-out after {max_time:.1f} s")
    return [run.result for run in runs]


def _explainer(batch: BatchedPolicy, index: int) -> tuple[object, int | None]:
    """What explains episode ``index``'s missing switch: ``(policy, index in it or None)``."""
    if isinstance(batch, PolicyList):
        return batch.policies[index], None
    return batch, index


class _Rollout:
    """One episode of :func:`run_episodes`: its simulation, MP sequences and ending checks.

    The closed loop of :func:`run_episode`, one tick at a time.
    """

    def __init__(
        self,
        index: int,
        box: Box,
        cfg: TaskConfig,
        expected: Demonstration,
        on_tick: Callable[[TickInfo], None] | None,
        on_result: Callable[[int, EpisodeResult], None] | None,
        pacing_seed: tuple[int, ...],
    ) -> None:
        self.index = index
        self.on_result = on_result
        self.box = box
        self.cfg = cfg
        self.want = mp_sequences(expected)
        self.on_tick = on_tick
        self.sim = Simulation(cfg, box)
        self.pacer = make_pacer(cfg.robot_pacing, cfg, pacing_seed)
        self.x = self.sim.features()
        self.active: dict[str, str] = {}
        self.initial: dict[str, str] = {}
        self.sequences: dict[str, list[str]] = {}
        self.transitions: list[TransitionEvent] = []
        self.last_switch = 0.0
        self.policy_time = 0.0
        self.result: EpisodeResult | None = None
        self.explainer: tuple[object, int | None] = (None, None)
        """The policy that explains a missing switch, and the episode's index in it."""

    def finish(self, outcome: Outcome, reason: str) -> None:
        """End the episode with ``outcome`` (the state of the simulation now)."""
        sim = self.sim
        ok = outcome != "diverged"
        cause = None
        if outcome in ("incomplete", "diverged"):
            policy, index = self.explainer
            cause = episode_cause(policy, self.sequences, self.want, index, self.transitions)
            if cause is not None:
                reason = f"{reason}; {cause.describe()}"
        self.result = EpisodeResult(
            outcome=outcome,
            reason=reason,
            sequences=self.sequences,
            transitions=self.transitions,
            initial=self.initial,
            duration=sim.t,
            box_in_container=sim.box_in_container() if ok else False,
            hands_home=sim.hands_home() if ok else False,
            expected=self.want,
            timing=dict(sim.timing, policy=self.policy_time),
            cause=cause,
        )
        if self.on_result is not None:
            self.on_result(self.index, self.result)

    def start(self, active: Mapping[str, str]) -> None:
        """Take the policy's initial MPs; a wrong start ends the episode.

        A wrong start still reaches the ``on_tick`` callback once (the state at ``t = 0`` and
        the MPs chosen), so that a recording of it shows the scene it was decided in.
        """
        sim, want = self.sim, self.want
        self.active = _normalise(active, sim.variables)
        sim.set_active(self.active)
        self.initial = dict(self.active)
        self.sequences = {v: [m] for v, m in self.active.items()}
        wrong = [v for v in sim.variables if self.active[v] != want[v][0]]
        if wrong:
            got = {v: self.active[v] for v in wrong}
            exp = {v: want[v][0] for v in wrong}
            strategy = correct_strategy(self.box, self.cfg)
            reason = f"initial MPs {got} differ from strategy {strategy!r}: {exp}"
            self._report_tick()
            self.finish("wrong_start", reason)

    def _report_tick(self) -> None:
        """The ``on_tick`` callback with the state now (before the tick's physics)."""
        sim = self.sim
        if self.on_tick is not None:
            tick = TickInfo(
                sim.t, active=dict(self.active), features=self.x, body_poses=sim.body_poses()
            )
            self.on_tick(tick)

    def before_tick(self) -> None:
        """The ``on_tick`` callback, then the active MPs (and their pace) to the simulation."""
        self._report_tick()
        self.sim.set_active(self.active)
        if self.pacer is not None:
            self.sim.set_speeds(self.pacer.speeds(self.active, self.sim.goal_distances()))

    def physics_step(self) -> bool:
        """One control tick of physics; False (and the episode ended) if it diverged."""
        if self.sim.step():
            return True
        reason = f"physics diverged at t={self.sim.t:.2f} s (NaN or unstable)"
        self.finish("diverged", reason)
        return False

    def after_tick(self, t: float, active: Mapping[str, str]) -> None:
        """Record the policy's MPs at time ``t`` [s]; end on a wrong transition, done, deadlock."""
        sim, want, old = self.sim, self.want, self.active
        new = _normalise(active, sim.variables)
        for variable in sim.variables:
            if new[variable] == old[variable]:
                continue
            self.transitions.append(
                TransitionEvent(t, variable, old[variable], new[variable], state=self.x.copy())
            )
            sequence = self.sequences[variable]
            sequence.append(new[variable])
            self.last_switch = t
            n = len(sequence)
            if sequence != want[variable][:n]:
                sim.set_active(new)
                should = want[variable][n - 1] if n <= len(want[variable]) else "no switch"
                reason = (
                    f"wrong transition {variable}: {old[variable]} -> {new[variable]} at "
                    f"t={t:.2f} s (expected {should})"
                )
                self.finish("incomplete", reason)
                return
        self.active = new
        if self.sequences == want and sim.box_in_container() and sim.hands_home():
            sim.set_active(new)
            reason = "box in container, hands home, sequences as demonstrated"
            self.finish("complete", reason)
        elif t - self.last_switch > self.cfg.deadlock_time and sim.robot_speed() < STILL_SPEED:
            reason = f"deadlock: no transition for {t - self.last_switch:.1f} s"
            self.finish("incomplete", reason)
