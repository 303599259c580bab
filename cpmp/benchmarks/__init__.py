"""Benchmarks (``scripts/bench*.py``): speed and quality measurements written as JSON.

They are measurements, never timed unit tests.

``suite`` runs the sections of ``scripts/bench.py`` (``fit``, ``sequencer``, ``sim``, the main
job's stages) picked in ``settings``; ``report`` renders them; ``start`` scores the start
decision against classifiers; ``sim_speed`` the simulator's real-time factor; ``cli`` holds
the command lines.
"""
