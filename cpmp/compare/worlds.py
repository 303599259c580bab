"""The worlds of the comparison: the simulator's variants and the synthetic worlds.

A compared *world* is one entry of ``compare.worlds`` (:class:`~cpmp.compare.settings.
WorldSettings`), resolved into a :class:`World`:

* ``kind: sim``: the MuJoCo pick-and-place task with the entry's ``task`` options over the
  job's ``task`` group (``settle_time: 0``, a pacing of the demonstrator, ...) and its
  ``feature_noise`` on the training demonstrations; its seeds are collected and reproduced by
  the main job's stages (:mod:`cpmp.compare.runs`), ``episodes`` random boxes per D and seed;
* ``kind: synthetic``: a world of :mod:`cpmp.worlds` registered in :data:`SYNTHETIC_WORLDS`,
  built from the entry's ``task`` options. Per seed it gives the training demonstrations, the
  held-out ones (for the progress MAE) and ``episodes`` closed-loop episodes, each scored.

Adding a synthetic world is one entry of :data:`SYNTHETIC_WORLDS`: a function ``(options,
seed, n_demos) -> SyntheticRun`` (its demonstrations and its closed loop); a simulator variant
needs no code, only a ``compare.worlds`` entry with its ``task`` options.

Importing this module costs NumPy and the synthetic worlds only (the command line checks the
``compare`` node with it before torch or MuJoCo are loaded).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Literal, get_args

import numpy as np

from cpmp.config.task import Pacing
from cpmp.data import Demonstration
from cpmp.errors import ConfigError
from cpmp.records import Policy
from cpmp.worlds import relay, two_point
from cpmp.worlds.outcomes import Outcome
from cpmp.worlds.relay.varied import DEMO_PACING, ROBOT_PACING, paced_relay

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


MakeRun = Callable[[Mapping[str, Any], int, int], SyntheticRun]
"""``make(options, seed, n_demos)``: a synthetic world built from its ``task`` options, its
``n_demos`` demonstrations drawn from ``seed``. Raises :class:`~cpmp.errors.ConfigError` for a
bad option."""


# --------------------------------------------------------------------------- the registry
def _task(cls: type, options: Mapping[str, Any], world: str) -> Any:
    """``cls(**options)``, an unknown option or bad value a :class:`ConfigError` naming it."""
    try:
        return cls(**dict(options))
    except TypeError as err:
        raise ConfigError(
            f"compare.worlds: bad task option for the {world} world ({err}); its options are "
            f"the fields of {cls.__module__}.{cls.__qualname__}"
        ) from err


def _two_point(options: Mapping[str, Any], seed: int, n_demos: int) -> SyntheticRun:
    """The two-point world (:mod:`cpmp.worlds.two_point`) with ``options`` of its task."""
    task = _task(two_point.SyntheticTask, options, "two_point")

    def evaluate(policy: Policy, n: int, episode_seed: int) -> list[EpisodeResult]:
        # two_point.evaluate returns counts only: the same draw and scoring, one per episode
        rng = np.random.default_rng(episode_seed)
        episodes = [task.sample_episode(rng) for _ in range(n)]
        return [
            EpisodeResult(task.outcome(e, run), "parallel" if e.parallel else "sequential")
            for e, run in zip(episodes, task.rollouts(episodes, policy), strict=True)
        ]

    return SyntheticRun(two_point.make_demonstrations(n_demos, seed=seed, task=task), evaluate)


def _relay(options: Mapping[str, Any], seed: int, n_demos: int) -> SyntheticRun:
    """The relay world (:mod:`cpmp.worlds.relay`) with ``options`` of its task."""
    task = _task(relay.RelayTask, options, "relay")

    def evaluate(policy: Policy, n: int, episode_seed: int) -> list[EpisodeResult]:
        result = relay.evaluate(policy, task, n_episodes=n, seed=episode_seed)
        return [EpisodeResult(e["outcome"], e["strategy"]) for e in result["per_episode"]]

    return SyntheticRun(relay.make_demonstrations(n_demos, seed=seed, task=task), evaluate)


def _pacing(options: Mapping[str, Any], key: str, default: Pacing, world: str) -> Pacing:
    """The :class:`Pacing` of option ``key`` (a mapping of its fields; absent: ``default``)."""
    value = options.get(key)
    if value is None:
        return default
    if not isinstance(value, Mapping):
        raise ConfigError(f"compare.worlds: the {world} world's {key} must be a mapping")
    fields = {k: tuple(v) if isinstance(v, (list, tuple)) else v for k, v in value.items()}
    return _task(Pacing, fields, f"{world} ({key})")


def _paced_relay(options: Mapping[str, Any], seed: int, n_demos: int) -> SyntheticRun:
    """The paced relay world (:mod:`cpmp.worlds.relay.varied`).

    Options ``demo`` and ``robot`` (each a :class:`~cpmp.config.task.Pacing`'s fields) and
    ``relay`` (the relay task's).
    """
    unknown = sorted(set(options) - {"demo", "robot", "relay"})
    if unknown:
        raise ConfigError(
            f"compare.worlds: unknown option(s) {', '.join(unknown)} of the paced_relay world; "
            "valid: demo, robot, relay"
        )
    demo = _pacing(options, "demo", DEMO_PACING, "paced_relay")
    robot = _pacing(options, "robot", ROBOT_PACING, "paced_relay")
    task = None
    if options.get("relay"):
        task = _task(relay.RelayTask, options["relay"], "paced_relay (relay)")
    world = paced_relay(seed, n_demos, demo=demo, robot=robot, relay=task)

    def evaluate(policy: Policy, n: int, episode_seed: int) -> list[EpisodeResult]:
        scores = world.evaluate(policy, n, episode_seed)
        return [EpisodeResult(s.outcome, s.strategy) for s in scores]

    return SyntheticRun(world.demonstrations, evaluate)


SYNTHETIC_WORLDS: dict[str, MakeRun] = {
    "two_point": _two_point,
    "relay": _relay,
    "paced_relay": _paced_relay,
}
"""The synthetic worlds a ``compare.worlds`` entry of ``kind: synthetic`` may name."""


def synthetic_run(name: str, options: Mapping[str, Any], seed: int, n_demos: int) -> SyntheticRun:
    """The synthetic world ``name`` at ``seed`` with ``n_demos`` demonstrations.

    Raises:
        ConfigError: an unknown world or a bad option.
    """
    make = SYNTHETIC_WORLDS.get(name)
    if make is None:
        raise ConfigError(
            f"compare.worlds: unknown synthetic world {name!r}; known: "
            f"{', '.join(SYNTHETIC_WORLDS)}"
        )
    return make(options, seed, n_demos)


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
        predictors: the ``predictor`` options of its rows (``None``: ``compare.predictors``).
        baselines: the ``sequencer`` baselines of its rows.
    """

    name: str
    kind: WorldKind
    world: str | None
    options: dict[str, Any]
    feature_noise: float
    seeds: tuple[int, ...]
    train_sizes: tuple[int, ...]
    episodes: int
    test_demos: int
    predictors: Any
    baselines: tuple[str, ...]

    def label(self) -> str:
        """The world's name and what differs from its defaults, for tables (one line)."""
        what = ", ".join(f"{k}={v}" for k, v in self.options.items())
        if self.feature_noise:
            what = ", ".join(filter(None, [what, f"feature_noise={self.feature_noise:g}"]))
        base = "simulator" if self.kind == "sim" else f"synthetic {self.world}"
        return f"{self.name} ({base}{': ' + what if what else ''})"
