"""Rows, pairs and claims pooled with intervals from fake per-seed results."""

from __future__ import annotations

import pytest
from fake_runs import EPISODES, SEEDS, fake_inputs, result, spec, world

from cpmp.compare.pooling import pool, pooled_rows, row_record, units
from cpmp.compare.runs import RowResult
from cpmp.compare.stats import BootstrapOptions

OPTIONS = BootstrapOptions(samples=200, seed=0)


def test_rates_and_mae_pool_every_episode_and_sample():
    out = pool(**fake_inputs())
    rows = {(r["name"], r["D"]): r for r in out["rows"]}
    assert set(rows) == {(n, d) for n in "abc" for d in (3, 6)}
    a = rows[("a", 3)]
    assert a["C"]["estimate"] == pytest.approx(30 / EPISODES, abs=1e-12)  # abs: rounding
    assert a["W"]["estimate"] == pytest.approx(2 / EPISODES, abs=1e-12)
    assert a["I"]["estimate"] == pytest.approx(8 / EPISODES, abs=1e-12)
    # demos of 100 and 300 samples at 0.04 and 0.06: 0.055 over all samples
    assert a["mae"]["estimate"] == pytest.approx(0.055, abs=1e-12)
    assert a["C"]["units"] == EPISODES * len(SEEDS) and a["C"]["seeds"] == len(SEEDS)
    assert 0.0 < a["C"]["low"] < a["C"]["estimate"] < a["C"]["high"] < 1.0  # episodes resampled
    # one fit time per seed, all 1.0 s: resampling seeds cannot move it
    assert a["fit_s"]["low"] == a["fit_s"]["high"] == 1.0
    assert a["per_seed"]["C"] == [30, 30, 30] and a["per_seed"]["seed"] == list(SEEDS)
    assert a["supports"]["units"] == len(SEEDS)


def test_pairs_are_significant_only_where_rows_differ():
    out = pool(**fake_inputs())
    pairs = {(p["a"], p["b"], p["D"]): p for p in out["pairs"]}
    assert set(pairs) == {
        (x, y, d) for x, y in (("a", "b"), ("a", "c"), ("b", "c")) for d in (3, 6)
    }
    ab, ac = pairs[("a", "b", 3)], pairs[("a", "c", 3)]
    assert ab["C"]["estimate"] == pytest.approx(0.5, abs=1e-12)  # 30 - 10 of 40
    assert ab["C"]["significant"] and ab["mae"]["significant"]
    assert ab["mae"]["estimate"] == pytest.approx(-0.1, abs=1e-12)
    assert not ab["W"]["significant"]  # the same wrong starts in both
    for key in ("W", "I", "C", "mae"):
        assert not ac[key]["significant"]  # identical rows
        assert ac[key]["estimate"] == 0.0 and ac[key]["p"] == 1.0


def test_claims_per_d_and_over_every_d():
    claims = pool(**fake_inputs())["claims"]
    assert [(c["claim"], c["D"]) for c in claims] == [
        ("a beats b", 3),
        ("a beats b", 6),
        ("a beats b", "all"),
    ]
    pooled = claims[-1]
    assert pooled["C"]["units"] == 2 * EPISODES * len(SEEDS)  # both D's episodes, per seed
    assert pooled["C"]["estimate"] == pytest.approx(0.5, abs=1e-12)
    assert pooled["C"]["significant"]


def test_a_refused_seed_leaves_the_rows_seeds_and_the_pairs_seeds():
    """Seed 1 of ``b`` refused its fit: ``b`` pools seeds 0 and 2, the pair too."""
    w = world(sizes=(3,))
    a, b = spec("a", sizes=(3,)), spec("b", sizes=(3,))
    results = {}
    for seed in SEEDS:
        results[a.fit_key(seed, 3)] = result(20)
        results[b.fit_key(seed, 3)] = result(20) if seed != 1 else RowResult(error="DataError: x")
    rows = pooled_rows([a, b], {"w": w}, results)
    record = row_record(rows[1], OPTIONS)
    assert record["seeds"] == [0, 2] and record["C"]["seeds"] == 2
    assert record["errors"] == ["seed 1: DataError: x"]
    assert record["per_seed"]["C"] == [20, None, 20]
    (pair,) = pool([a, b], {"w": w}, results, [], OPTIONS)["pairs"]
    assert pair["C"]["seeds"] == 2 and pair["C"]["units"] == 2 * EPISODES


def test_units_of_each_number():
    r = result(3, wrong=1)
    c = units(r, "C")
    assert c is not None and c.values.sum() == 3 and len(c) == EPISODES
    mae = units(r, "mae")
    assert mae is not None and list(mae.weights) == [100, 300]
    tick = units(r, "tick_ms")
    assert tick is not None and list(tick.values) == [0.5]
    assert units(RowResult(error="x"), "C") is None
    assert units(RowResult(outcomes=["diverged"]), "I").values.tolist() == [1.0]  # diverged is I


def test_support_points_differ_from_the_reference_row_paired():
    """A support point of ``a`` that completes 20 of 40 where ``a`` itself completes 30: its
    ``vs_reference`` is a 25-point drop, significant; a point equal to ``a`` differs by 0."""
    inputs = fake_inputs()
    low = spec("a", group="support_sweep", option="support_scale", value=0.5)
    same = spec("a", group="support_sweep", option="support_scale", value=4.0)
    for seed in SEEDS:
        for d in low.train_sizes:
            inputs["results"][low.fit_key(seed, d)] = result(20, wrong=2)
            inputs["results"][same.fit_key(seed, d)] = result(30, wrong=2, mae=0.05)
    inputs["specs"] = [*inputs["specs"], low, same]
    rows = pool(**inputs, reference="a")["rows"]
    points = {(r["value"], r["D"]): r for r in rows if r["group"] == "support_sweep"}
    drop = points[(0.5, 3)]["vs_reference"]
    assert drop["reference"] == "a"
    assert drop["C"]["estimate"] == pytest.approx(-0.25, abs=1e-12) and drop["C"]["significant"]
    assert points[(4.0, 6)]["vs_reference"]["C"]["estimate"] == 0.0
    assert all("vs_reference" not in r for r in rows if r["group"] != "support_sweep")
    assert all("vs_reference" not in r for r in pool(**inputs)["rows"])  # no reference named
