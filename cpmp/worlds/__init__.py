"""Synthetic concurrent tasks without MuJoCo: demonstrators and closed-loop worlds.

Every world implements one interface (:mod:`cpmp.worlds.protocol`: :class:`World`, driven by
:func:`evaluate` / :func:`run_episodes`) and is found by name in :mod:`cpmp.worlds.registry`
(:func:`make_world`, :data:`WORLDS`); the benchmarks, the comparison and the tests read that
table. The worlds:

* ``two_point``: two points on a line, two strategies chosen by a context feature;
* ``relay``: a carrier and a receiver hand an object over (three strategies, a
  cross-variable wait), with its scripted demonstrator and closed-loop evaluation;
* ``repetition``: a ladling cycle repeated as often as a quantity in the state says;
* ``peg`` (reactive): a peg inserted, retracted and re-aligned after jams read only from a
  force, 1-3 tries decided during execution, while the other arm holds the base;
* ``slip`` (reactive): a pick that slips mid-lift (read from contact and grip width) and is
  lowered and re-grasped, while the other hand holds a drawer open across the tries;
* ``procedural``: a generator of random concurrent tasks (a family: ``task=i``);
* ``attractor``: an attractor's goal inferred from its motion (the scripted policies');
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
