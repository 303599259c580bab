"""Synthetic concurrent tasks without MuJoCo: demonstrators and closed-loop worlds.

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

__all__ = ["OUTCOMES", "Outcome", "count_outcomes", "episode_outcome", "relay", "two_point"]
