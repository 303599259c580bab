"""``compare.md`` from pooled fake results: every number with its interval, significance in
bold, the claims, the support axis; the episodes and timings files."""

from __future__ import annotations

import re

from fake_runs import SEEDS, fake_inputs, result, spec

from cpmp.compare.pooling import pool
from cpmp.compare.report import (
    difference_text,
    interval_text,
    job_episodes,
    render_compare,
    seeds_text,
)
from cpmp.compare.rows import FitJob


def test_interval_and_difference_text():
    value = {"estimate": 0.75, "low": 0.6, "high": 0.875}
    assert interval_text(value, 100.0, 0) == "75 [60, 88]"
    assert interval_text(None) == "–"
    assert difference_text({**value, "significant": True}, 100.0, 0) == "**+75 [+60, +88]**"
    low = {"estimate": -0.01, "low": -0.03, "high": 0.01, "significant": False}
    assert difference_text(low, 1.0, 3) == "-0.010 [-0.030, +0.010]"
    tiny = {"estimate": -0.004, "low": -0.02, "high": 0.0, "significant": False}
    assert difference_text(tiny, 100.0, 0) == "+0 [-2, +0]"  # no "-0"


def test_seeds_text_shortens_runs_of_three_or_more():
    assert seeds_text([*range(40), 50, 51]) == "0-39, 50, 51"
    assert seeds_text([4, 0, 2, 1]) == "0-2, 4"
    assert seeds_text([7]) == "7"


def test_every_row_number_has_an_interval_and_significance_is_bold():
    text = render_compare(pool(**fake_inputs()), "fake", 60.0, 2)
    lines = text.splitlines()
    rows = [line for line in lines if line.startswith("| `a` |") or line.startswith("| `b` |")]
    assert len(rows) == 4  # a and b at D = 3 and 6
    for line in rows:
        cells = line.strip("|").split("|")[2:]  # W, I, C, MAE, fit, tick, supports
        assert len(cells) == 7
        assert all(re.fullmatch(r" -?[\d.]+ \[-?[\d.]+, -?[\d.]+\] ", c) for c in cells), line
    claim = next(line for line in lines if line.startswith("| a beats b"))
    assert "**+50 [" in claim  # C: 30 vs 10 of 40, significant
    same = next(line for line in lines if "`a` − `c`" in line)
    assert "**" not in same  # identical rows: nothing significant
    assert "## The paper's claims" in text and "## w (synthetic two_point)" in text
    assert "Wall time 1.0 min on 2 worker(s)" in text


def test_support_axis_table_lists_each_point():
    inputs = fake_inputs()
    point = spec("a", group="support_sweep", option="support_scale", value=0.5)
    default = spec("a", group="support_sweep", option="support_scale", value=None)
    for s, supports in ((point, 40), (default, 100)):
        for seed in SEEDS:
            for d in s.train_sizes:
                inputs["results"][s.fit_key(seed, d)] = result(20, supports=supports)
    inputs["specs"] = [*inputs["specs"], point, default]
    text = render_compare(pool(**inputs, reference="a"), "fake", 60.0, 1)
    assert "## Support-count axis" in text and "own row of the same world and D (`a`)" in text
    assert "| w | 3 | `a` | support_scale=0.5 | 40 [40, 40] |" in text
    assert "| w | 3 | `a` | support_scale=default | 100 [100, 100] |" in text
    point = next(line for line in text.splitlines() if "support_scale=0.5 |" in line)
    assert point.endswith("| **-25 [-33, -17]** | +0.000 [+0.000, +0.000] |")  # 20 vs 30 of 40


def test_episodes_are_labelled_with_world_row_seed_and_d():
    s = spec("a", sizes=(3,))
    jobs = {s.fit_key(0, 3): FitJob(s, 0, 3)}
    results = {s.fit_key(0, 3): result(2)}
    episodes = job_episodes(results, jobs)
    assert len(episodes) == 40
    assert episodes[1] == {
        "world": "w",
        "predictor": "a",
        "sequencer": "coupled",
        "option": None,
        "value": None,
        "seed": 0,
        "D": 3,
        "episode": 1,
        "outcome": "complete",
    }
