"""Synthetic concurrent tasks without MuJoCo: demonstrators and closed-loop worlds.

Every world implements one interface (:mod:`cpmp.worlds.protocol`: :class:`World`, driven by
:func:`evaluate` / :func:`run_episodes`) and is found by name in :mod:`cpmp.worlds.registry`
(:func:`make_world`, :data:`WORLDS`); the benchmarks, the comparison and the tests read that
table. The worlds:

* ``two_point``: two points on a line, two strategies chosen by a context feature;
* ``relay``: a carrier and a receiver hand an object over (three strategies, a
  cross-variable wait), with its scripted demonstrator and closed-loop evaluation;
* ``repetition``: a ladling cycle repeated as often as a quantity in the state says;
* ``pacing``: MPs at varied speeds with holds mid-MP (:class:`~cpmp.worlds.pacing.Pacer`) and
  the face of a paced world (:class:`~cpmp.worlds.pacing.PacedWorld`; the relay's is
  :func:`cpmp.worlds.relay.varied.paced_relay`);
* ``outcomes``: how a closed-loop episode of a world ended (:data:`Outcome`), and the counts;
* ``common``: the checked counts, seeded episodes, scripted recordings and closed-loop runs the
  worlds share.
"""

from cpmp.worlds import relay, two_point
from cpmp.worlds.outcomes import OUTCOMES, Outcome, count_outcomes, episode_outcome
from cpmp.worlds.protocol import EpisodeRun, Evaluation, World, WorldRun, evaluate, run_episodes
from cpmp.worlds.registry import WORLDS, WorldEntry, make_world, members, world_names

__all__ = [
    "OUTCOMES",
    "WORLDS",
    "EpisodeRun",
    "Evaluation",
    "Outcome",
    "World",
    "WorldEntry",
    "WorldRun",
    "count_outcomes",
    "episode_outcome",
    "evaluate",
    "make_world",
    "members",
    "relay",
    "run_episodes",
    "two_point",
    "world_names",
]
