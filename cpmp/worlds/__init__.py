"""Synthetic concurrent tasks without MuJoCo: demonstrators and closed-loop worlds.

* ``two_point``: two points on a line, two strategies chosen by a context feature;
* ``relay``: a carrier and a receiver hand an object over (three strategies, a
  cross-variable wait), with its scripted demonstrator and closed-loop evaluation.
"""

from cpmp.worlds import relay, two_point

__all__ = ["relay", "two_point"]
