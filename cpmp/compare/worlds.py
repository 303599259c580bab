"""The worlds of the comparison: the simulator's variants and the synthetic worlds.

A compared *world* is one entry of ``compare.worlds`` (:class:`~cpmp.compare.settings.
WorldSettings`), resolved into a :class:`World`:

* ``kind: sim``: the MuJoCo pick-and-place task with the entry's ``task`` options over the
  job's ``task`` group (``settle_time: 0``, a pacing of the demonstrator, ...) and its
  ``feature_noise`` on the training demonstrations; its seeds are collected and reproduced by
  the main job's stages (:mod:`cpmp.compare.runs`), ``episodes`` random boxes per D and seed;
* ``kind: synthetic``: a world of :mod:`cpmp.worlds.registry` (:data:`SYNTHETIC_WORLDS`),
  built from the entry's ``task`` options. Per seed it gives the training demonstrations, the
  held-out ones (for the progress MAE) and ``episodes`` closed-loop episodes, each scored.

A registered world needs no code here; a simulator variant needs none either, only a
``compare.worlds`` entry with its ``task`` options.

Importing this module costs NumPy and the synthetic worlds only (the command line checks the
``compare`` node with it before torch or MuJoCo are loaded).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Literal, get_args

from cpmp.data import Demonstration
from cpmp.errors import ConfigError
from cpmp.records import JsonValue, Policy
from cpmp.worlds.outcomes import Outcome
from cpmp.worlds.protocol import evaluate as evaluate_world
from cpmp.worlds.registry import make_world, world_names

WorldKind = Literal["sim", "synthetic"]
"""A compared world's kind: the MuJoCo simulator (a variant of the job's ``task``) or a
synthetic world of :data:`SYNTHETIC_WORLDS`."""
WORLD_KINDS: tuple[WorldKind, ...] = get_args(WorldKind)
"""Every :data:`WorldKind`."""

EPISODE_SEED_OFFSET = 1000
"""A synthetic world's closed-loop episodes of seed ``s`` are drawn from ``s + 1000`` (the
demonstrations from ``s``), as the simulator's reproduction boxes are."""
TEST_SEED_OFFSET = 500
"""Its held-out demonstrations of seed ``s`` are those of seed ``s + 500``."""


@dataclass(frozen=True)
class EpisodeResult:
    """One scored closed-loop episode of a synthetic world.

    Attributes:
        outcome: ``complete``, ``wrong_start`` or ``incomplete``.
        strategy: the episode's strategy.
    """

    outcome: Outcome
    strategy: str


Evaluate = Callable[[Policy, int, int], list[EpisodeResult]]
"""``evaluate(policy, n_episodes, seed)``: one :class:`EpisodeResult` per episode, drawn from
``seed``."""


@dataclass(frozen=True)
class SyntheticRun:
    """A synthetic world at one seed, as the comparison uses it.

    Attributes:
        demonstrations: the training demonstrations (the first ``D`` of them train a row of
            training size ``D``; every world alternates its strategies, so they are balanced).
        evaluate: the closed loop (:data:`Evaluate`).
    """

    demonstrations: list[Demonstration]
    evaluate: Evaluate


# --------------------------------------------------------------------------- the registry
SYNTHETIC_WORLDS: tuple[str, ...] = world_names()
"""The synthetic worlds a ``compare.worlds`` entry of ``kind: synthetic`` may name: every
world of :mod:`cpmp.worlds.registry`."""


def synthetic_run(
    name: str, options: Mapping[str, JsonValue], seed: int, n_demos: int
) -> SyntheticRun:
    """The synthetic world ``name`` at ``seed`` with ``n_demos`` demonstrations.

    Its closed loop is :func:`cpmp.worlds.protocol.evaluate` (batched where the policy
    batches); a family world's ``task`` option picks the member.

    Raises:
        ConfigError: an unknown world or a bad option.
    """
    if name not in SYNTHETIC_WORLDS:
        raise ConfigError(
            f"compare.worlds: unknown synthetic world {name!r}; known: "
            f"{', '.join(SYNTHETIC_WORLDS)}"
        )
    try:
        world = make_world(name, options)
    except ConfigError as err:
        raise ConfigError(f"compare.worlds: {err}") from err

    def evaluate(policy: Policy, n: int, episode_seed: int) -> list[EpisodeResult]:
        runs = evaluate_world(world, policy, n, episode_seed).episodes
        return [EpisodeResult(e.outcome, e.strategy) for e in runs]

    return SyntheticRun(world.demonstrations(n_demos, seed), evaluate)


# ------------------------------------------------------------------------- resolved worlds
@dataclass(frozen=True)
class World:
    """One compared world, resolved against the job's ``experiment`` group.

    Attributes:
        name: its key in ``compare.worlds`` (rows, files and tables are labelled with it).
        kind: ``sim`` or ``synthetic``.
        world: the synthetic world's :data:`SYNTHETIC_WORLDS` name (``None`` for ``sim``).
        options: ``sim``: task options over the job's ``task`` group; ``synthetic``: the
            world's own options.
        feature_noise: noise on the training demonstrations' features (fraction of each
            feature's range; :func:`cpmp.data.augment.add_feature_noise`).
        seeds: the seeds (demonstrations, fits, episodes).
        train_sizes: the training sizes D.
        episodes: closed-loop episodes (``sim``: random boxes) per D and seed.
        test_demos: ``synthetic``: held-out demonstrations per seed (``sim``: the
            ``experiment`` group's split).
        predictors: the ``predictor`` options of its rows: ``all`` or their names
            (``compare.predictors`` unless the entry names its own).
        baselines: the ``sequencer`` baselines of its rows.
    """

    name: str
    kind: WorldKind
    world: str | None
    options: dict[str, JsonValue]
    feature_noise: float
    seeds: tuple[int, ...]
    train_sizes: tuple[int, ...]
    episodes: int
    test_demos: int
    predictors: str | list[str]
    baselines: tuple[str, ...]

    def label(self) -> str:
        """The world's name and what differs from its defaults, for tables (one line)."""
        what = ", ".join(f"{k}={v}" for k, v in self.options.items())
        if self.feature_noise:
            what = ", ".join(filter(None, [what, f"feature_noise={self.feature_noise:g}"]))
        base = "simulator" if self.kind == "sim" else f"synthetic {self.world}"
        return f"{self.name} ({base}{': ' + what if what else ''})"
