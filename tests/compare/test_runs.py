"""One synthetic job of the comparison end to end, the held-out errors it pools, the noise a
simulated world adds to a shared collection, and which worlds share a collection."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from cpmp.compare.rows import RowSpec
from cpmp.compare.runs import (
    RowResult,
    collection_key,
    demo_errors,
    run_synthetic_row,
    table_outcome,
    world_config,
    world_data,
)
from cpmp.compare.worlds import EPISODE_SEED_OFFSET, TEST_SEED_OFFSET, World
from cpmp.data.augment import add_feature_noise
from cpmp.evaluation.offline import activation_progress, progress_errors
from cpmp.experiment.collection import SeedData
from cpmp.sequencer import ConcurrentSequencer
from cpmp.worlds import two_point

torch.set_num_threads(1)

KLR_PATH = {"kind": "klr"}  # cpmp's default predictor: klr with its defaults


def synthetic(**more: object) -> World:
    options = {
        "name": "tp",
        "kind": "synthetic",
        "world": "two_point",
        "options": {},
        "feature_noise": 0.0,
        "seeds": (0,),
        "train_sizes": (2, 4),
        "episodes": 8,
        "test_demos": 2,
        "predictors": ["x"],
        "baselines": (),
    }
    return World(**{**options, **more})  # type: ignore[arg-type]


def spec(predictor_cfg: dict[str, object]) -> RowSpec:
    return RowSpec("tp", "predictors", "x", "coupled", predictor_cfg, {}, (2, 4))


def test_a_synthetic_job_fits_on_the_first_d_demos_and_scores_the_worlds_episodes():
    out = run_synthetic_row({}, spec(KLR_PATH), synthetic(), seed=0, d=2)
    assert out.error is None and len(out.outcomes) == 8
    # the same fit by hand: the first 2 of the seed's 4 demos (the world's largest D)
    train = two_point.make_demonstrations(4, seed=0)[:2]
    test = two_point.make_demonstrations(2, seed=TEST_SEED_OFFSET)
    seq = ConcurrentSequencer.fit(train, seed=0, logger=None)
    assert out.mae == pytest.approx(
        progress_errors(activation_progress(seq, test))["mae"], rel=1e-9
    )
    counts = two_point.evaluate(seq, n_episodes=8, seed=EPISODE_SEED_OFFSET)
    assert {o: out.outcomes.count(o) for o in counts} == counts
    assert out.supports == seq.fit_summary.n_support_total and out.tick_ms > 0
    assert set(out.seconds) == {"fit", "evaluate", "reproduce"}


def test_a_refused_fit_is_an_error_without_numbers():
    out = run_synthetic_row({}, spec({"kind": "klr", "gamma": -1.0}), synthetic(), 0, 4)
    assert out.error is not None and out.error.startswith("ConfigError: ")
    assert "gamma" in out.error
    assert out.outcomes == [] and out.mae is None and out.fit_s is None


def test_noise_changes_the_training_demos_only():
    clean = run_synthetic_row({}, spec(KLR_PATH), synthetic(), 0, 4)
    noisy = run_synthetic_row({}, spec(KLR_PATH), synthetic(feature_noise=0.05), 0, 4)
    assert noisy.mae != clean.mae
    assert [e.demo for e in noisy.demo_errors] == [e.demo for e in clean.demo_errors]


def test_demo_errors_weight_to_the_pooled_mae():
    demos = two_point.make_demonstrations(4, seed=0)
    seq = ConcurrentSequencer.fit(demos[:2], seed=0, logger=None)
    errors = demo_errors(seq, demos[2:])
    assert [e.demo for e in errors] == [d.name for d in demos[2:]]
    pooled = sum(e.mae * e.samples for e in errors) / sum(e.samples for e in errors)
    # rel 1e-12: the same sums in another order
    assert pooled == pytest.approx(
        progress_errors(activation_progress(seq, demos[2:]))["mae"], rel=1e-12
    )
    assert errors[0].mae != errors[1].mae


def test_a_simulated_world_adds_its_noise_as_the_main_job_does():
    demos = two_point.make_demonstrations(4, seed=0)
    data = SeedData(3, demos[:2], demos[2:], [], [], {})
    noisy = world_data(data, synthetic(kind="sim", world=None, feature_noise=0.05))
    expected = add_feature_noise(demos[:2], 0.05, seed=3)
    for got, want in zip(noisy.train, expected, strict=True):
        assert np.array_equal(got.features, want.features)
    assert noisy.test is data.test
    assert world_data(data, synthetic(kind="sim", world=None)) is data


def test_worlds_share_a_collection_when_only_noise_differs():
    plain = {
        "experiment": {
            "seeds": [0],
            "n_boxes": 4,
            "demos_per_strategy": 2,
            "train_per_strategy": 1,
            "box_seed_offset": 1000,
            "max_time": None,
        },
        "task": {"settle_time": 0.2},
    }
    sim = synthetic(kind="sim", world=None, train_sizes=(3,))
    noisy = dataclasses.replace(sim, name="noisy", feature_noise=0.05)
    settle = dataclasses.replace(sim, name="settle", options={"settle_time": 0.0})
    assert collection_key(plain, sim, 0) == collection_key(plain, noisy, 0)
    assert collection_key(plain, sim, 0) != collection_key(plain, settle, 0)
    assert collection_key(plain, sim, 0) != collection_key(plain, sim, 1)
    cfg = world_config(plain, settle)
    assert cfg["task"]["settle_time"] == 0.0 and cfg["experiment"]["n_boxes"] == 8
    assert cfg["experiment"]["feature_noise"] == 0.0  # the world adds its own after collecting


def test_outcomes_count_as_in_table_one():
    r = RowResult(outcomes=["complete", "wrong_start", "diverged", "incomplete", "complete"])
    assert [table_outcome(o) for o in r.outcomes] == ["C", "W", "I", "I", "C"]
    assert (r.count("W"), r.count("I"), r.count("C")) == (1, 2, 2)
