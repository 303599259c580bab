"""The repetition task as a registered world (:class:`~cpmp.worlds.protocol.World`).

An episode is complete when it reaches the goal state running exactly the demonstrator's MP
sequences (spilt soup scooped again is another route, and ``incomplete``).
"""

from __future__ import annotations

from typing_extensions import override

from cpmp.config.validation import OptionValue
from cpmp.data import Demonstration
from cpmp.records import Policy
from cpmp.worlds.protocol import SteppedWorld
from cpmp.worlds.repetition.demonstrator import demonstrate, make_demonstrations
from cpmp.worlds.repetition.world import (
    FEATURE_NAMES,
    STRATEGIES,
    VARIABLES,
    RepetitionEpisode,
    RepetitionTask,
)


class RepetitionWorld(SteppedWorld[RepetitionEpisode]):
    r"""The repetition world; ``RepetitionWorld(**options)`` takes :class:`RepetitionTask`'s fields.

    Contexts are :class:`RepetitionEpisode`\ s cycling ``once``, ``twice``, ``thrice``.
    """

    name = "repetition"
    variables = tuple(VARIABLES)
    feature_names = tuple(FEATURE_NAMES)
    strategies: tuple[str, ...] = STRATEGIES
    strict = True

    def __init__(self, **options: OptionValue) -> None:
        super().__init__(RepetitionTask(**options))

    @override
    def demonstrations(self, n: int, seed: int) -> list[Demonstration]:
        return make_demonstrations(n, seed=seed, task=self.task)

    @override
    def demonstrate(self, context: RepetitionEpisode, name: str | None = None) -> Demonstration:
        return demonstrate(self.task, context, name)

    @override
    def scripted_policy(self) -> Policy:
        from cpmp.worlds.repetition.policy import RepetitionFeaturePolicy  # lazy

        return RepetitionFeaturePolicy(self.task)

    @override
    def expected_sequences(self, context: RepetitionEpisode) -> dict[str, list[str]]:
        return self.task.expected_sequences(context)
