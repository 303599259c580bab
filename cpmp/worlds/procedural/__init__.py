"""The procedural world: a family of random concurrent tasks, one per generator seed.

``generator`` (:func:`generate`: the task spec of a seed, decidable by construction),
``world`` (its dynamics and contexts), ``demonstrator`` (the scripted demonstrator),
``policy`` (the feature-only scripted policy) and ``registered`` (:class:`ProceduralWorld`,
member ``task=i`` of the family).
"""

from cpmp.worlds.procedural.generator import TaskSpec, generate
from cpmp.worlds.procedural.policy import FeaturePolicy
from cpmp.worlds.procedural.registered import ProceduralWorld
from cpmp.worlds.procedural.world import ProceduralContext, ProceduralRun

__all__ = [
    "FeaturePolicy",
    "ProceduralContext",
    "ProceduralRun",
    "ProceduralWorld",
    "TaskSpec",
    "generate",
]
