"""The procedural family as a registered world (:class:`~cpmp.worlds.protocol.World`).

``ProceduralWorld(task=i)`` is member ``i``: the task :func:`~cpmp.worlds.procedural.
generator.generate` draws from seed ``i``. An episode is scored by its start, its goal state
and the demonstrator's MP sequences (:func:`~cpmp.worlds.protocol.sequence_score`): a run that
skips or repeats a try is ``incomplete``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

from cpmp.config.validation import finite_number
from cpmp.data import Demonstration
from cpmp.errors import ConfigError
from cpmp.records import Policy
from cpmp.worlds.common import positive_count
from cpmp.worlds.procedural.demonstrator import Switches, demonstrate, make_contexts
from cpmp.worlds.procedural.generator import (
    MAX_GOAL_JITTER,
    MAX_START_JITTER,
    STRATEGIES,
    TaskSpec,
    check_strategy,
    generate,
)
from cpmp.worlds.procedural.policy import FeaturePolicy
from cpmp.worlds.procedural.world import ProceduralContext, ProceduralRun
from cpmp.worlds.protocol import WorldBase

DT = 0.01
"""The step and sample period of every member [s]."""


@dataclass
class ProceduralWorld(WorldBase[ProceduralContext]):
    """Member ``task`` of the procedural family.

    Attributes:
        task: the generator seed (a non-negative integer).
        goal_jitter: half-width of the per-context goal jitter per axis, in
            ``[0, MAX_GOAL_JITTER]`` (the guards' tolerance leaves no room for more).
        start_jitter: half-width of the per-context start jitter per axis, in
            ``[0, MAX_START_JITTER]``.
        max_time: an episode's time limit [s], at least 5.
        spec: the task (derived from ``task``).
    """

    strict: ClassVar[bool] = True

    task: int = 0
    goal_jitter: float = 0.03
    start_jitter: float = 0.04
    max_time: float = 20.0
    spec: TaskSpec = field(init=False, repr=False)

    name: ClassVar[str] = "procedural"
    strategies: ClassVar[tuple[str, ...]] = STRATEGIES
    dt: ClassVar[float] = DT

    def __post_init__(self) -> None:
        bounds = {"goal_jitter": MAX_GOAL_JITTER, "start_jitter": MAX_START_JITTER}
        for option, most in bounds.items():
            value = finite_number(getattr(self, option), f"ProceduralWorld.{option}")
            if not 0.0 <= value <= most:
                raise ConfigError(f"ProceduralWorld.{option} must be in [0, {most}], got {value}")
        self.max_time = finite_number(self.max_time, "ProceduralWorld.max_time")
        if self.max_time < 5.0:
            raise ConfigError(f"ProceduralWorld.max_time must be >= 5 s, got {self.max_time}")
        self.spec = generate(self.task)
        self._switches = Switches(self.spec)

    @property
    def variables(self) -> tuple[str, ...]:
        """The task's control variables, in the labels' order."""
        return self.spec.variable_names

    @property
    def feature_names(self) -> tuple[str, ...]:
        """The task's features."""
        return self.spec.feature_names

    def describe(self) -> list[str]:
        """A few readable lines of the task (variables, MPs, branch, loop, waits)."""
        return self.spec.describe()

    def demonstrations(self, n: int, seed: int) -> list[Demonstration]:
        """``n`` demonstrations of the contexts :meth:`contexts` draws, named ``demo_<i>``."""
        return [self.demonstrate(c, f"demo_{i}") for i, c in enumerate(self.contexts(n, seed))]

    def contexts(self, n: int, seed: int) -> list[ProceduralContext]:
        """``n`` contexts from ``seed``, cycling strategies and failures.

        Item ``i`` has strategy ``"ab"[i % 2]`` and ``(i + 1) % 3`` hidden failures where the
        task has a loop.

        Raises:
            ConfigError: ``n`` is not a positive integer or ``seed`` not a non-negative one.
        """
        positive_count(n, "n")
        return make_contexts(self.spec, n, seed, self.goal_jitter, self.start_jitter)

    def demonstrate(self, context: ProceduralContext, name: str | None = None) -> Demonstration:
        """The scripted demonstrator's labelled demonstration of ``context``."""
        return demonstrate(self.spec, context, self.dt, self.max_time, name, self._switches)

    def start(self, context: ProceduralContext) -> ProceduralRun:
        """A run of ``context`` at ``t = 0``."""
        return ProceduralRun(self.spec, context, self.dt)

    def strategy(self, context: ProceduralContext) -> str:
        """The strategy of ``context``."""
        return check_strategy(context.strategy)

    def initial_mps(self, context: ProceduralContext) -> dict[str, str]:
        """The demonstrator's initial MP per variable for ``context``."""
        return self.spec.initial_mps(context.strategy)

    def scripted_policy(self) -> Policy:
        """A fresh feature-only policy (:class:`~cpmp.worlds.procedural.policy.FeaturePolicy`)."""
        return FeaturePolicy(self.spec)
