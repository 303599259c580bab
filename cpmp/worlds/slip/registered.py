"""The slip task as a :class:`~cpmp.worlds.protocol.World` (registry name ``slip``).

:class:`SlipWorld` is the task's options (:class:`~cpmp.worlds.slip.world.SlipTask`, every
field an option, checked on construction) with the World protocol on top: contexts and
demonstrations cycling the strategies with the hidden slip counts drawn (the demonstrations'
cycled so that the first three hold a slip), runs, the feature-only scripted policy, and
scoring that asks for the demonstrator's exact MP sequences.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from cpmp.data import Demonstration
from cpmp.worlds.protocol import WorldBase
from cpmp.worlds.slip.demonstrator import demonstrate, make_contexts, make_demonstrations
from cpmp.worlds.slip.policy import ScriptedSlipPolicy
from cpmp.worlds.slip.world import (
    FEATURE_NAMES,
    STRATEGIES,
    VARIABLES,
    SlipContext,
    SlipRun,
    SlipTask,
)


@dataclass
class SlipWorld(SlipTask, WorldBase[SlipContext]):
    """The slip world: pick, maybe slip and retry, place in a drawer the other hand holds open.

    Its fields are :class:`~cpmp.worlds.slip.world.SlipTask`'s options (``SlipWorld(**options)``;
    a bad one raises :class:`~cpmp.errors.ConfigError`).
    """

    strict: ClassVar[bool] = True

    name = "slip"
    variables = VARIABLES
    feature_names = FEATURE_NAMES
    strategies = STRATEGIES

    def demonstrations(self, n: int, seed: int) -> list[Demonstration]:
        """``n`` demonstrations named ``demo_<i>``: item ``i`` has strategy ``i % 4``.

        The slip counts cycle (:func:`~cpmp.worlds.slip.demonstrator.slip_cycle`: the first
        three are 1, 2, 0), the geometry is drawn from ``seed``; metadata holds ``strategy`` and
        ``n_slips``.

        Raises:
            ConfigError: ``n`` is not a positive integer.
        """
        return make_demonstrations(self, n, seed)

    def contexts(self, n: int, seed: int) -> list[SlipContext]:
        """``n`` contexts from ``seed``: item ``i`` has strategy ``i % 4``, slip count drawn.

        Raises:
            ConfigError: ``n`` is not a positive integer.
        """
        return make_contexts(self, n, seed)

    def demonstrate(self, context: SlipContext, name: str | None = None) -> Demonstration:
        """The scripted demonstrator's labelled demonstration of ``context``."""
        return demonstrate(self, context, name)

    def start(self, context: SlipContext) -> SlipRun:
        """A run of ``context`` at ``t = 0``."""
        return SlipRun(self, context)

    def strategy(self, context: SlipContext) -> str:
        """The strategy of ``context``."""
        return context.strategy

    def scripted_policy(self) -> ScriptedSlipPolicy:
        """A fresh feature-only scripted policy."""
        return ScriptedSlipPolicy(self)
