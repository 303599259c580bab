"""The relay and the paced relay as registered worlds (:class:`~cpmp.worlds.protocol.World`).

:class:`RelayWorld` is the hand-over of :mod:`cpmp.worlds.relay.world` with its options;
:class:`PacedRelayWorld` the same task with MPs at varied speeds (:mod:`cpmp.worlds.relay.
varied`): paced demonstrations (varied speeds and holds mid-MP) and a paced robot (varied
speeds). Both score an episode by its start and its goal state.
"""

from __future__ import annotations

from collections.abc import Mapping

from typing_extensions import override

from cpmp.config.task import Pacing
from cpmp.config.validation import OptionValue
from cpmp.data import Demonstration
from cpmp.errors import ConfigError
from cpmp.records import Policy
from cpmp.worlds.protocol import SteppedRun, SteppedWorld
from cpmp.worlds.relay import varied
from cpmp.worlds.relay.demonstrator import demonstrate, make_demonstrations
from cpmp.worlds.relay.world import FEATURE_NAMES, STRATEGIES, VARIABLES, RelayEpisode, RelayTask


class RelayWorld(SteppedWorld):
    r"""The relay world; ``RelayWorld(**options)`` takes :class:`RelayTask`'s fields.

    Contexts are :class:`RelayEpisode`\ s alternating the strategies (``meet`` first).
    """

    name = "relay"
    variables = tuple(VARIABLES)
    feature_names = tuple(FEATURE_NAMES)
    strategies: tuple[str, ...] = STRATEGIES

    def __init__(self, **options: OptionValue) -> None:
        super().__init__(RelayTask(**options))

    @override
    def demonstrations(self, n: int, seed: int) -> list[Demonstration]:
        return make_demonstrations(n, seed=seed, task=self.task)

    @override
    def demonstrate(self, context: RelayEpisode, name: str | None = None) -> Demonstration:
        return demonstrate(self.task, context, name)

    @override
    def scripted_policy(self) -> Policy:
        from cpmp.worlds.relay.policy import RelayFeaturePolicy  # lazy: tables stay cheap

        return RelayFeaturePolicy(self.task)


def pacing(value: Pacing | Mapping[str, OptionValue] | None, default: Pacing, what: str) -> Pacing:
    """A :class:`Pacing` from itself or a mapping of its fields (``None``: ``default``).

    Raises:
        ConfigError: not a mapping, or a bad field.
    """
    if value is None:
        return default
    if isinstance(value, Pacing):
        return value
    if not isinstance(value, Mapping):
        raise ConfigError(f"the paced_relay world's {what} must be a mapping of Pacing's fields")
    fields = {k: tuple(v) if isinstance(v, (list, tuple)) else v for k, v in value.items()}
    try:
        return Pacing(**fields)
    except TypeError as err:
        raise ConfigError(
            f"bad option of the paced_relay world's {what} ({err}); its options are the fields "
            "of cpmp.config.task.Pacing"
        ) from err


class PacedRelayWorld(RelayWorld):
    """The paced relay (:func:`cpmp.worlds.relay.varied.paced_relay`).

    Args:
        demo: the demonstrator's pacing (:data:`~cpmp.worlds.relay.varied.DEMO_PACING`).
        robot: the closed-loop robot's pacing (:data:`~cpmp.worlds.relay.varied.ROBOT_PACING`).
        relay: the relay task's options (default: its defaults with
            :data:`~cpmp.worlds.relay.varied.MAX_TIME`).
    """

    name = "paced_relay"

    def __init__(
        self,
        demo: Pacing | Mapping[str, OptionValue] | None = None,
        robot: Pacing | Mapping[str, OptionValue] | None = None,
        relay: Mapping[str, OptionValue] | None = None,
    ) -> None:
        super().__init__(**{"max_time": varied.MAX_TIME, **dict(relay or {})})
        self.demo_task = varied.PacedRelayTask(self.task, pacing(demo, varied.DEMO_PACING, "demo"))
        self.robot_task = varied.PacedRelayTask(
            self.task, pacing(robot, varied.ROBOT_PACING, "robot")
        )

    @override
    def demonstrations(self, n: int, seed: int) -> list[Demonstration]:
        return varied.make_demonstrations(n, seed, self.demo_task)

    @override
    def contexts(self, n: int, seed: int) -> list[varied.PacedEpisode]:
        return self.robot_task.episodes(n, seed, varied.ROBOT_STREAM)

    @override
    def demonstrate(  # type: ignore[override]
        self, context: varied.PacedEpisode, name: str | None = None
    ) -> Demonstration:
        return varied.demonstrate(self.robot_task, context, name)

    @override
    def start(self, context: varied.PacedEpisode) -> SteppedRun:
        return SteppedRun(self.robot_task, context)

    @override
    def initial_mps(self, context: varied.PacedEpisode) -> dict[str, str]:
        return self.robot_task.initial_mps(context)
