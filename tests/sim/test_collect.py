"""Recording demonstrations (cpmp.sim.collect): one box, many boxes together (exactly the data
of one box at a time), seeded box sampling and the HDF5 collection."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from cpmp.data.datafile import load_demonstrations, save_demonstrations
from cpmp.data.demonstration import Demonstration
from cpmp.sim import (
    STRATEGIES,
    Box,
    ScriptedDemonstrator,
    Simulation,
    TaskConfig,
    correct_strategy,
    record_demonstration,
    record_demonstrations,
    sample_box,
)
from cpmp.sim.collect import collect_demonstrations, sample_boxes


def test_same_box_gives_identical_demo(cfg, demos):
    again = record_demonstration(Box(0.15, 0.12, 0.10), cfg, name="demo_right")
    first = demos["right"]
    assert np.array_equal(again.features, first.features)
    for variable in first.variables:
        assert np.array_equal(again.labels[variable], first.labels[variable])


def test_hdf5_round_trip(tmp_path, demos):
    path = tmp_path / "demos.h5"
    save_demonstrations(path, list(demos.values()))
    loaded = {d.name: d for d in load_demonstrations(path)}
    for demo in demos.values():
        back = loaded[demo.name]
        assert np.array_equal(back.features, demo.features)
        assert np.array_equal(back.time, demo.time)
        assert back.feature_names == demo.feature_names
        assert back.metadata["strategy"] == demo.metadata["strategy"]
        for variable in demo.variables:
            assert list(back.labels[variable]) == list(demo.labels[variable])


def test_balanced_box_sampling_is_seeded(cfg):
    a = sample_boxes(np.random.default_rng(7), cfg, 6, balanced=True)
    b = sample_boxes(np.random.default_rng(7), cfg, 6, balanced=True)
    assert a == b
    assert [correct_strategy(box, cfg) for box in a] == list(STRATEGIES) * 2
    box = sample_box(np.random.default_rng(0), cfg)
    assert cfg.width_range[0] <= box.width <= cfg.width_range[1]


def test_collect_writes_seeded_file(tmp_path):
    cfg = TaskConfig()
    path, demos = collect_demonstrations(cfg, 1, seed=3, path=tmp_path / "d.h5")
    loaded = load_demonstrations(path)
    assert len(loaded) == 1 and loaded[0].metadata["strategy"] == "both"
    assert np.array_equal(loaded[0].features, demos[0].features)


def _one_at_a_time(box: Box, cfg: TaskConfig) -> tuple[np.ndarray, dict[str, list[str]], bool]:
    """The demonstrator's loop on one simulation that computes its own control every tick
    (no batching anywhere): features (n, d), labels per variable, diverged."""
    sim = Simulation(cfg, box)
    policy = ScriptedDemonstrator(sim)
    x = sim.features()
    active = policy.reset(0.0, x)
    features, labels = [], {v: [] for v in sim.variables}
    n_max = round(cfg.max_time / cfg.control_dt)
    for k in range(n_max + 1):
        features.append(x)
        for variable in sim.variables:
            labels[variable].append(active[variable])
        if policy.done or k == n_max:
            break
        sim.set_active(active)
        if not sim.step():
            return np.asarray(features), labels, True
        x = sim.features()
        active = policy.step((k + 1) * cfg.control_dt, x)
    return np.asarray(features), labels, False


def _same_demo(got: Demonstration, want: Demonstration) -> None:
    """Every array equal to the last bit, the names and the metadata equal."""
    assert (got.name, got.feature_names, got.metadata) == (
        want.name,
        want.feature_names,
        want.metadata,
    )
    assert np.array_equal(got.time, want.time)
    assert np.array_equal(got.features, want.features)
    assert got.labels.keys() == want.labels.keys()
    for variable, labels in want.labels.items():
        assert np.array_equal(got.labels[variable], labels), variable


def _matches_reference(demo: Demonstration, box: Box, cfg: TaskConfig) -> None:
    features, labels, diverged = _one_at_a_time(box, cfg)
    assert np.array_equal(demo.features, features)
    for variable, want in labels.items():
        assert list(demo.labels[variable]) == want, variable
    assert demo.metadata["diverged"] is diverged


@pytest.mark.slow
def test_batched_demonstrations_equal_one_at_a_time(demos, boxes, cfg):
    extra = Box(0.28, 0.11, 0.1)  # a fourth box, bimanual like the first
    run = [boxes["both"], boxes["right"], boxes["left"], extra]
    names = ["demo_both", "demo_right", "demo_left", "extra"]
    ended: list[int] = []
    together = record_demonstrations(run, cfg, names, on_result=lambda i, demo: ended.append(i))
    assert sorted(ended) == [0, 1, 2, 3]
    # recordings end as their demonstrator finishes: shortest first
    lengths = [len(together[i].time) for i in ended]
    assert lengths == sorted(lengths) and len(set(lengths)) > 1
    for strategy, demo in zip(("both", "right", "left"), together, strict=False):
        _same_demo(demo, demos[strategy])
    _same_demo(together[3], record_demonstration(extra, cfg, name="extra"))
    # both paths equal the plain single-simulation loop
    _matches_reference(together[1], boxes["right"], cfg)
    _matches_reference(together[3], extra, cfg)
    assert all(demo.metadata["success"] for demo in together)


def test_time_out_and_divergence_end_only_their_own_recording(demos, boxes, cfg, monkeypatch):
    short = dataclasses.replace(cfg, max_time=1.0)
    original = Simulation.step

    def blow_up(self):
        if self.box == boxes["both"] and self.t > 0.5:
            self.data.qvel[:] = np.nan  # what an unstable integration leaves behind
        return original(self)

    monkeypatch.setattr(Simulation, "step", blow_up)
    broken, cut = record_demonstrations([boxes["both"], boxes["right"]], short)
    assert broken.metadata["diverged"] and not broken.metadata["success"]
    _matches_reference(broken, boxes["both"], short)
    assert len(broken.time) < 101
    # the other box runs on to its time-out: the first second of its full recording
    n = round(short.max_time / short.control_dt) + 1
    assert len(cut.time) == n and cut.metadata["duration"] == demos["right"].time[n - 1]
    assert not cut.metadata["diverged"] and not cut.metadata["success"]
    assert np.array_equal(cut.features, demos["right"].features[:n])
    for variable, labels in demos["right"].labels.items():
        assert np.array_equal(cut.labels[variable], labels[:n]), variable
