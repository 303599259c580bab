"""Fixtures of the simulation tests (defined in ``tests/sim_fixtures.py``)."""

from sim_fixtures import boxes, cfg, demos  # noqa: F401 (fixtures)
