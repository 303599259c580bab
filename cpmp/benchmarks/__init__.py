"""Benchmarks (``scripts/bench*.py``): speed and quality measurements written as JSON.

They are measurements, never timed unit tests.

``suite`` runs the sections of ``scripts/bench.py`` (``fit``, ``sequencer``, ``sim``, the main
job's stages) picked in ``settings``; ``report`` renders them; ``start`` scores the start
decision against classifiers; ``sim`` holds the simulator's real-time factor and the suite's
simulator sections; ``executors`` times the job backends; ``cli`` holds the command lines.
"""
