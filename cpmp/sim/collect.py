"""Recording scripted demonstrations, one box or many together, and saving seeded sets.

One box (:func:`record_demonstration`) or many together (:func:`record_demonstrations`, one
batched IK call per tick, the same data as one box at a time); seeded sets of them are
collected into the project's HDF5 format.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np

from cpmp.config.task import Pacing, TaskConfig, as_task_config
from cpmp.config.validation import OptionValue
from cpmp.data.datafile import save_demonstrations
from cpmp.data.demonstration import Demonstration
from cpmp.errors import ConfigError
from cpmp.sim.demonstrator import ScriptedDemonstrator
from cpmp.sim.policies import per_episode
from cpmp.sim.scene import STRATEGIES, Box, correct_strategy, sample_box
from cpmp.sim.simulation import Simulation, prepare_steps
from cpmp.worlds.pacing import Pacer

DEMO_STREAM = 0
ROBOT_STREAM = 1
"""The second word of a run's pacing seed ``(seed, stream, index)``: demonstrations and
closed-loop episodes draw from different streams."""
NO_PAUSE = frozenset({"left_pos/follow_right"})
"""MPs that never hold: the left hand following the right one under a jointly held box (a hold
would pull the hands apart)."""
MIN_PACED_DISTANCE = 1e-3
"""An activation that starts closer than this to its goal [m or rad] never holds."""


def make_pacer(pacing: Pacing, cfg: TaskConfig, seed: tuple[int, ...]) -> Pacer | None:
    """A run's :class:`~cpmp.worlds.pacing.Pacer`, or ``None`` when ``pacing`` varies nothing.

    Args:
        pacing: the task's ``demo_pacing`` or ``robot_pacing``.
        cfg: the task (its control period).
        seed: ``(seed, stream, index)`` of the run.
    """
    if not pacing.varied:
        return None
    return Pacer(pacing, seed, cfg.control_dt, NO_PAUSE, MIN_PACED_DISTANCE)


def record_demonstration(
    box: Box, cfg: TaskConfig | Mapping[str, OptionValue] | None = None, name: str | None = None
) -> Demonstration:
    """Run the scripted demonstrator on ``box`` and record it at the control rate.

    Returns a :class:`~cpmp.data.Demonstration` with ``time`` (n,) [s], ``features`` (n, 33),
    the active MP per variable at each tick, the feature names and metadata (box size,
    strategy, success, duration). Deterministic: the same box and config give identical data.
    :func:`record_demonstrations` with one box (the same loop).
    """
    return record_demonstrations([box], cfg, names=[name])[0]


def record_demonstrations(
    boxes: Sequence[Box],
    cfg: TaskConfig | Mapping[str, OptionValue] | None = None,
    names: Sequence[str | None] | None = None,
    on_result: Callable[[int, Demonstration], None] | None = None,
    pacing_seed: int | None = None,
) -> list[Demonstration]:
    """Run the scripted demonstrator on every box, all together, recording each at control rate.

    Each result equals :func:`record_demonstration` of its box alone, to the last bit.

    Every control tick: one batched pose/Jacobian and IK call over the robots still running
    (:func:`~cpmp.sim.simulation.prepare_steps`), MuJoCo stepping each box's own model and each
    demonstrator reading its own simulation. A recording that ends (demonstrator done, time-out
    or diverged physics) is left out of the following ticks.

    names: per box, the demonstration's name (``None``: unnamed). on_result: called with
    ``(index, demonstration)`` as each recording ends (e.g. a progress bar). pacing_seed: with
    the task's ``demo_*`` pacing options set, box ``i`` is paced from the seed
    ``(pacing_seed, DEMO_STREAM, i)`` (default: the task's ``seed``).
    """
    cfg = as_task_config(cfg)
    boxes = list(boxes)
    names = per_episode(names, len(boxes), "names")
    base = cfg.seed if pacing_seed is None else int(pacing_seed)
    runs = [_Recording(box, cfg, (base, DEMO_STREAM, i)) for i, box in enumerate(boxes)]
    out: list[Demonstration | None] = [None] * len(runs)

    def finish(index: int) -> None:
        out[index] = runs[index].demonstration(names[index])
        if on_result is not None:
            on_result(index, out[index])

    running = list(range(len(runs)))
    n_max = round(cfg.max_time / cfg.control_dt)
    for k in range(n_max + 1):
        for i in running:
            runs[i].append()
        ended = [i for i in running if runs[i].policy.done or k == n_max]
        for i in ended:
            finish(i)
        running = [i for i in running if i not in ended]
        if not running:
            break
        for i in running:
            runs[i].sim.set_active(runs[i].active)
        prepare_steps([runs[i].sim for i in running])
        diverged = [i for i in running if not runs[i].sim.step()]
        for i in diverged:
            runs[i].diverged = True
            finish(i)
        running = [i for i in running if i not in diverged]
        t = (k + 1) * cfg.control_dt
        for i in running:
            runs[i].observe(t)
    return [demo for demo in out if demo is not None]


class _Recording:
    """One box of :func:`record_demonstrations`: its simulation, demonstrator and samples so far.

    The loop of :func:`record_demonstration`, one tick at a time.
    """

    def __init__(self, box: Box, cfg: TaskConfig, pacing_seed: tuple[int, ...]) -> None:
        self.box = box
        self.cfg = cfg
        self.sim = Simulation(cfg, box)
        self.pacer = make_pacer(cfg.demo_pacing, cfg, pacing_seed)
        self.policy = ScriptedDemonstrator(self.sim, self.pacer)
        self.x = self.sim.features()
        self.active = self.policy.reset(0.0, self.x)
        self.features: list[np.ndarray] = []
        self.labels: dict[str, list[str]] = {v: [] for v in self.sim.variables}
        self.diverged = False

    def append(self) -> None:
        """Keep the current sample: features and the active MP per variable."""
        self.features.append(self.x)
        for variable, labels in self.labels.items():
            labels.append(self.active[variable])

    def observe(self, t: float) -> None:
        """After a tick of physics at time ``t`` [s]: new features, the demonstrator's MPs."""
        self.x = self.sim.features()
        self.active = self.policy.step(t, self.x)

    def demonstration(self, name: str | None) -> Demonstration:
        """The recording so far as a :class:`~cpmp.data.Demonstration`."""
        sim, policy, box, cfg = self.sim, self.policy, self.box, self.cfg
        n = len(self.features)
        success = bool(
            policy.done and sim.box_in_container() and sim.hands_home() and not self.diverged
        )
        return Demonstration(
            time=np.arange(n) * cfg.control_dt,
            features=np.asarray(self.features),
            labels={v: np.asarray(self.labels[v]) for v in sim.variables},
            feature_names=list(sim.feature_names),
            name=name,
            metadata={
                "box_width": box.width,
                "box_depth": box.depth,
                "box_height": box.height,
                "strategy": policy.strategy,
                "success": success,
                "diverged": self.diverged,
                "duration": float((n - 1) * cfg.control_dt),
                "control_dt": cfg.control_dt,
                **({} if self.pacer is None else {"holds": len(self.pacer.holds)}),
            },
        )


MAX_DRAWS_PER_BOX = 10_000
"""Rejection-sampling budget per box when balancing strategies."""


def sample_boxes(rng: np.random.Generator, cfg: TaskConfig, n: int, balanced: bool) -> list[Box]:
    """``n`` boxes from the configured ranges.

    With ``balanced``, strategies cycle round-robin over :data:`STRATEGIES` (rejection
    sampling, deterministic given ``rng``).
    """
    if n < 0:
        raise ConfigError(f"n_demos must be >= 0, got {n}")
    boxes = []
    for i in range(n):
        want = STRATEGIES[i % len(STRATEGIES)] if balanced else None
        for _ in range(MAX_DRAWS_PER_BOX):
            box = sample_box(rng, cfg)
            if want is None or correct_strategy(box, cfg) == want:
                break
        else:
            raise ConfigError(
                f"no box with strategy {want!r} in width {cfg.width_range} x depth "
                f"{cfg.depth_range}; widen the ranges or set balanced=false"
            )
        boxes.append(box)
    return boxes


def collect_demonstrations(
    cfg: TaskConfig, n_demos: int, seed: int, path: str | os.PathLike[str], balanced: bool = True
) -> tuple[Path, list[Demonstration]]:
    """Record ``n_demos`` scripted demonstrations with boxes drawn from ``seed`` and save them.

    Demos are named ``demo_<i>_<strategy>``; all boxes run together
    (:func:`record_demonstrations`, paced from ``seed`` where the task says). Returns the
    written path and the demonstrations.
    """
    rng = np.random.default_rng(seed)
    boxes = sample_boxes(rng, cfg, n_demos, balanced)
    names = [f"demo_{i:03d}_{correct_strategy(box, cfg)}" for i, box in enumerate(boxes)]
    demos = record_demonstrations(boxes, cfg, names=names, pacing_seed=seed)
    failed = [d.name for d in demos if not (d.metadata or {}).get("success")]
    if failed:
        raise RuntimeError(f"the scripted demonstrator failed on {failed}; this is a bug")
    out = Path(path)
    save_demonstrations(out, demos)
    return out, demos
