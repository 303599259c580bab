"""Analysis of finished runs, and worked examples.

``aggregate`` tables and plots a Hydra sweep of the main job; ``progress_field`` draws the
worked progress-field example (paper Fig. 3) on synthetic data.
"""
