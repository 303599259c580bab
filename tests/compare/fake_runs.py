"""Fake comparison results (no fit, no simulator) for the pooling, report and figure tests."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from cpmp.compare.rows import RowSpec
from cpmp.compare.runs import DemoError, RowResult
from cpmp.compare.settings import ClaimSettings
from cpmp.compare.stats import BootstrapOptions
from cpmp.compare.worlds import World

SEEDS = (0, 1, 2)
EPISODES = 40


def world(name: str = "w", sizes: Sequence[int] = (3, 6)) -> World:
    return World(
        name=name,
        kind="synthetic",
        world="two_point",
        options={},
        feature_noise=0.0,
        seeds=SEEDS,
        train_sizes=tuple(sizes),
        episodes=EPISODES,
        test_demos=2,
        predictors=["a", "b", "c"],
        baselines=(),
    )


def spec(
    predictor: str, world_name: str = "w", sizes: Sequence[int] = (3, 6), **more: object
) -> RowSpec:
    group = more.pop("group", "predictors")
    return RowSpec(
        world_name,
        group,  # type: ignore[arg-type]  # a RowGroup
        predictor,
        "coupled",
        {"kind": "klr", "name": predictor, **more},
        {"kind": "learned"},
        tuple(sizes),
        more.get("option"),  # type: ignore[arg-type]
        more.get("value"),  # type: ignore[arg-type]
    )


def result(complete: int, wrong: int = 0, mae: float = 0.05, supports: int = 100) -> RowResult:
    """A seed's result: ``complete`` of :data:`EPISODES` complete (the first ones), ``wrong``
    wrong starts (the last ones), two held-out demos of 100 and 300 samples."""
    outcomes = ["complete"] * complete + ["incomplete"] * (EPISODES - complete - wrong)
    outcomes += ["wrong_start"] * wrong
    return RowResult(
        outcomes=outcomes,
        demo_errors=[DemoError("d0", mae - 0.01, 100), DemoError("d1", mae + 0.01, 300)],
        mae=mae + 0.005,
        fit_s=1.0,
        tick_ms=0.5,
        supports=supports,
        episodes=[{"outcome": o} for o in outcomes],
    )


def fake_inputs() -> dict[str, Any]:
    """Three rows in one world at D = 3 and 6: ``a`` completes 30 of 40 per seed, ``b`` 10 of
    40 with a higher MAE, ``c`` is ``a`` again; the claim ``a`` vs ``b``."""
    specs = [spec("a"), spec("b"), spec("c")]
    numbers = {"a": (30, 0.05), "b": (10, 0.15), "c": (30, 0.05)}
    results = {}
    for s in specs:
        complete, mae = numbers[s.predictor]
        for seed in SEEDS:
            for d in s.train_sizes:
                results[s.fit_key(seed, d)] = result(complete, wrong=2, mae=mae)
    return {
        "specs": specs,
        "worlds": {"w": world()},
        "results": results,
        "claims": [ClaimSettings("a beats b", "a", "b")],
        "options": BootstrapOptions(samples=300, seed=0),
    }
