"""Builders of hand-made experiment reports (the ``report.json`` of ``run_experiment``), shared
by the tests of the report and of the sweep aggregate. Imported by module name: pytest puts
this folder on ``sys.path`` for the tests in it."""

from __future__ import annotations


def table_one_entry(
    counts: tuple[float, float, float],
    stds: tuple[float, float, float],
    distance: float | None,
    distance_std: float,
    n_boxes: int,
    **extra: float,
) -> dict:
    """One training size's entry of a report's ``reproduction`` (a row of the paper's Table I).

    Args:
        counts: the mean counts of boxes (W, I, C) over the seeds.
        stds: their standard deviations over the seeds, in the same order.
        distance: the mean switch distance; None when no episode was complete.
        distance_std: its standard deviation, written as None when ``distance`` is None.
        n_boxes: boxes per seed.
        **extra: further fields (e.g. ``diverged``), placed after the counts.

    Returns:
        The entry, keyed as ``run_experiment`` writes it.
    """
    (w, i, c), (w_std, i_std, c_std) = counts, stds
    return {
        "W": w,
        "W_std": w_std,
        "I": i,
        "I_std": i_std,
        "C": c,
        "C_std": c_std,
        **extra,
        "distance_mean": distance,
        "distance_std": None if distance is None else distance_std,
        "n_boxes": n_boxes,
    }
