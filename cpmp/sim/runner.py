"""Recording scripted demonstrations and running policies closed-loop."""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from cpmp.data import Demonstration
from cpmp.errors import UnknownMPError
from cpmp.sim.config import TaskConfig
from cpmp.sim.demonstrator import ScriptedDemonstrator
from cpmp.sim.scene import Box, correct_strategy
from cpmp.sim.simulation import Simulation

OUTCOMES: tuple[str, ...] = ("complete", "wrong_start", "incomplete", "diverged")
STILL_SPEED = 0.02
"""Joint speed [rad/s] below which the robot counts as standing still (deadlock detection)."""


class Policy(Protocol):
    """What :func:`run_episode` drives: the core sequencer's interface."""

    def reset(self, t: float, x: np.ndarray) -> Mapping[str, str]: ...

    def step(self, t: float, x: np.ndarray) -> Mapping[str, str]: ...


@dataclass(frozen=True)
class Transition:
    """One MP switch: at time ``t`` [s] ``variable`` went ``source`` -> ``target``.

    ``features`` (d,) is the state on which the switch was decided.
    """

    t: float
    variable: str
    source: str
    target: str
    features: np.ndarray


@dataclass(frozen=True)
class TickInfo:
    """Passed to ``on_tick`` every control tick (before the tick's physics)."""

    t: float
    features: np.ndarray
    active: dict[str, str]
    body_poses: dict[str, tuple[np.ndarray, np.ndarray]]


@dataclass
class EpisodeResult:
    """Outcome of :func:`run_episode`.

    ``outcome``: "complete" (box in container, hands home, MP sequences equal the
    demonstrator's), "wrong_start" (initial MPs differ from the correct strategy's),
    "incomplete" (wrong transition, deadlock or time-out) or "diverged" (NaN/unstable physics).
    """

    outcome: str
    reason: str
    sequences: dict[str, list[str]]
    transitions: list[Transition]
    initial: dict[str, str]
    duration: float
    box_in_container: bool
    hands_home: bool
    expected: dict[str, list[str]] = field(default_factory=dict)
    timing: dict[str, float] = field(default_factory=dict)


def _as_config(cfg: TaskConfig | Mapping[str, Any] | None) -> TaskConfig:
    return cfg if isinstance(cfg, TaskConfig) else TaskConfig.from_dict(cfg)


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


class ReplayPolicy:
    """Replays a demonstration's labels by time (open-loop); a reference policy for tests and
    benchmarks. ``reset``/``step`` return the labels of the sample at or before ``t``."""

    def __init__(self, demo: Demonstration) -> None:
        self.time = np.asarray(demo.time)
        self.labels = {v: np.asarray(lab) for v, lab in demo.labels.items()}

    def _at(self, t: float) -> dict[str, str]:
        i = int(np.clip(np.searchsorted(self.time, t + 1e-9) - 1, 0, len(self.time) - 1))
        return {v: str(lab[i]) for v, lab in self.labels.items()}

    def reset(self, t: float, x: np.ndarray) -> dict[str, str]:
        return self._at(t)

    def step(self, t: float, x: np.ndarray) -> dict[str, str]:
        return self._at(t)


def record_demonstration(
    box: Box, cfg: TaskConfig | Mapping[str, Any] | None = None, name: str | None = None
) -> Demonstration:
    """Run the scripted demonstrator on ``box`` and record it at the control rate.

    Returns a :class:`~cpmp.data.Demonstration` with ``time`` (n,) [s], ``features`` (n, 33),
    the active MP per variable at each tick, the feature names and metadata (box size,
    strategy, success, duration). Deterministic: the same box and config give identical data.
    """
    cfg = _as_config(cfg)
    sim = Simulation(cfg, box)
    policy = ScriptedDemonstrator(sim)
    features, labels = [], {v: [] for v in sim.variables}
    x = sim.features()
    active = policy.reset(0.0, x)
    n_max = round(cfg.max_time / cfg.control_dt)
    diverged = False
    for k in range(n_max + 1):
        features.append(x)
        for variable in sim.variables:
            labels[variable].append(active[variable])
        if policy.done or k == n_max:
            break
        sim.set_active(active)
        if not sim.step():
            diverged = True
            break
        x = sim.features()
        active = policy.step((k + 1) * cfg.control_dt, x)
    n = len(features)
    success = bool(policy.done and sim.box_in_container() and sim.hands_home() and not diverged)
    return Demonstration(
        time=np.arange(n) * cfg.control_dt,
        features=np.asarray(features),
        labels={v: np.asarray(labels[v]) for v in sim.variables},
        feature_names=list(sim.feature_names),
        name=name,
        metadata={
            "box_width": box.width,
            "box_depth": box.depth,
            "box_height": box.height,
            "strategy": policy.strategy,
            "success": success,
            "diverged": diverged,
            "duration": float((n - 1) * cfg.control_dt),
            "control_dt": cfg.control_dt,
        },
    )


def mp_sequences(demo: Demonstration) -> dict[str, list[str]]:
    """Run-length collapsed MP sequence per variable of a demonstration."""
    out = {}
    for variable, labels in demo.labels.items():
        seq: list[str] = []
        for label in labels:
            if not seq or seq[-1] != label:
                seq.append(str(label))
        out[variable] = seq
    return out


def run_episode(
    box: Box,
    policy: Policy,
    cfg: TaskConfig | Mapping[str, Any] | None = None,
    max_time: float | None = None,
    expected: Demonstration | None = None,
    on_tick: Callable[[TickInfo], None] | None = None,
) -> EpisodeResult:
    """Execute ``policy`` closed-loop on ``box`` and classify the outcome.

    policy: ``reset(t, x)`` / ``step(t, x)`` -> dict variable -> MP name, called every control
    tick with the feature vector ``x`` (d,). expected: the demonstrator's recording for ``box``
    (recorded here if None). Physics divergence ends the episode with outcome "diverged"; it
    never raises. An unknown MP name raises :class:`~cpmp.errors.UnknownMPError`.
    """
    cfg = _as_config(cfg)
    max_time = cfg.max_time if max_time is None else float(max_time)
    if expected is None:
        expected = record_demonstration(box, cfg)
    want = mp_sequences(expected)
    sim = Simulation(cfg, box)
    x = sim.features()
    start = time.perf_counter()
    active = _normalise(policy.reset(0.0, x), sim.variables)
    policy_time = time.perf_counter() - start
    sim.set_active(active)
    initial = dict(active)
    sequences = {v: [m] for v, m in active.items()}
    transitions: list[Transition] = []

    def result(outcome: str, reason: str) -> EpisodeResult:
        timing = dict(sim.timing, policy=policy_time)
        return EpisodeResult(
            outcome=outcome,
            reason=reason,
            sequences=sequences,
            transitions=transitions,
            initial=initial,
            duration=sim.t,
            box_in_container=sim.box_in_container() if outcome != "diverged" else False,
            hands_home=sim.hands_home() if outcome != "diverged" else False,
            expected=want,
            timing=timing,
        )

    wrong = [v for v in sim.variables if active[v] != want[v][0]]
    if wrong:
        got = {v: active[v] for v in wrong}
        exp = {v: want[v][0] for v in wrong}
        strategy = correct_strategy(box, cfg)
        return result("wrong_start", f"initial MPs {got} differ from strategy {strategy!r}: {exp}")

    last_switch = 0.0
    n_max = round(max_time / cfg.control_dt)
    for k in range(n_max):
        if on_tick is not None:
            on_tick(TickInfo(sim.t, x, dict(active), sim.body_poses()))
        sim.set_active(active)
        if not sim.step():
            return result("diverged", f"physics diverged at t={sim.t:.2f} s (NaN or unstable)")
        x = sim.features()
        t = (k + 1) * cfg.control_dt
        start = time.perf_counter()
        new = _normalise(policy.step(t, x), sim.variables)
        policy_time += time.perf_counter() - start
        for variable in sim.variables:
            if new[variable] == active[variable]:
                continue
            transitions.append(Transition(t, variable, active[variable], new[variable], x.copy()))
            sequences[variable].append(new[variable])
            last_switch = t
            n = len(sequences[variable])
            if sequences[variable] != want[variable][:n]:
                sim.set_active(new)
                should = want[variable][n - 1] if n <= len(want[variable]) else "no switch"
                return result(
                    "incomplete",
                    f"wrong transition {variable}: {active[variable]} -> {new[variable]} at "
                    f"t={t:.2f} s (expected {should})",
                )
        active = new
        if sequences == want and sim.box_in_container() and sim.hands_home():
            sim.set_active(active)
            return result("complete", "box in container, hands home, sequences as demonstrated")
        if t - last_switch > cfg.deadlock_time and sim.robot_speed() < STILL_SPEED:
            return result("incomplete", f"deadlock: no transition for {t - last_switch:.1f} s")
    return result("incomplete", f"time-out after {max_time:.1f} s")
