"""The goal-nearest sequencing baseline on toy graphs: nearest entry state, convergence, staying,
start, batching, checkpoints and option errors."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from cpmp.baselines.goal_nearest import GoalNearestSequencer
from cpmp.data.demonstration import Demonstration
from cpmp.errors import ConfigError, CpmpFileError, DataError, NotFittedError
from cpmp.progress import expected_progress

DT = 0.01
MOVE, HOLD = 0.7, 0.3
"""Each toy MP moves feature 0 by one unit in MOVE seconds, then holds still for HOLD."""


def _ramp(start: float, stop: float) -> np.ndarray:
    """Feature 0 over one toy activation: a linear move, then still; (n,)."""
    n = round((MOVE + HOLD) / DT)
    u = np.minimum(np.arange(n) * DT / MOVE, 1.0)
    return start + (stop - start) * u


def toy_demo(size: float, mps: list[str], name: str) -> Demonstration:
    """One variable ``v`` running ``mps`` in turn; feature 0 moves 0 -> 1 under the first MP,
    1 -> 2 under ``b``, 1 -> 0 under ``c`` (and back to 0 under ``a`` after ``z``); feature 1 is
    a constant ``size`` (like a box size)."""
    stops = {"a": 1.0, "z": 1.0, "b": 2.0, "c": 0.0}
    f0, labels, position = [], [], 0.0
    for mp in mps:
        seg = _ramp(position, stops[mp])
        position = stops[mp]
        f0.append(seg)
        labels += [mp] * len(seg)
    f0 = np.concatenate(f0)
    features = np.stack([f0, np.full_like(f0, size)], axis=1)
    return Demonstration(
        time=np.arange(len(f0)) * DT,
        features=features,
        labels={"v": np.asarray(labels)},
        feature_names=["position", "size"],
        name=name,
    )


@pytest.fixture(scope="module")
def two_successors() -> list[Demonstration]:
    """``a -> b`` for small sizes, ``a -> c`` for large ones, and ``a`` alone at 0.5."""
    return [
        toy_demo(0.2, ["a", "b"], "demo_0"),
        toy_demo(0.25, ["a", "b"], "demo_1"),
        toy_demo(0.75, ["a", "c"], "demo_2"),
        toy_demo(0.8, ["a", "c"], "demo_3"),
        toy_demo(0.5, ["a"], "demo_4"),
    ]


def stream(size: float, f0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Times ``(n,)`` and features ``(n, 2)`` of a closed-loop-like stream."""
    return np.arange(len(f0)) * DT, np.stack([f0, np.full_like(f0, size)], axis=1)


def run(seq: GoalNearestSequencer, time: np.ndarray, x: np.ndarray) -> list[tuple[float, str]]:
    seq.reset(time[0], x[0])
    for t, xi in zip(time[1:], x[1:], strict=True):
        seq.step(t, xi)
    return [(e.t, e.target) for e in seq.events]


@pytest.mark.parametrize(("size", "expected"), [(0.3, "b"), (0.7, "c"), (0.1, "b"), (0.9, "c")])
def test_picks_the_successor_with_the_nearest_entry_state(two_successors, size, expected):
    seq = GoalNearestSequencer.fit(two_successors)
    assert seq.graphs["v"].successors("a") == ["b", "c"]
    time, x = stream(size, _ramp(0.0, 1.0))
    events = run(seq, time, x)
    assert [target for _, target in events] == [expected]
    assert seq.active == {"v": expected}


def test_stays_where_demonstrations_ended_when_that_is_nearest(two_successors):
    seq = GoalNearestSequencer.fit(two_successors)
    time, x = stream(0.5, _ramp(0.0, 1.0))
    assert run(seq, time, x) == []
    assert seq.active == {"v": "a"}


def test_does_not_switch_while_the_features_move(two_successors):
    hold = 0.1
    seq = GoalNearestSequencer.fit(two_successors, hold_time=hold, speed_threshold=0.02)
    # 0.2 units/s raw = 0.1 scaled units/s (global scaling by the largest range, 2): above the
    # threshold, so `a` keeps running for the whole 3 s move, then the features stop.
    moving = 0.2 * np.arange(301) * DT
    f0 = np.concatenate([moving, np.full(60, moving[-1])])
    time, x = stream(0.3, f0)
    events = run(seq, time, x)
    stop = 300 * DT
    assert len(events) == 1
    t, target = events[0]
    assert target == "b"
    # converged from the first still tick on; the switch comes after `hold` seconds of it
    assert stop + hold - 1e-9 <= t <= stop + hold + DT + 1e-9


def test_features_the_mp_does_not_move_do_not_hold_it_back(two_successors):
    seq = GoalNearestSequencer.fit(two_successors)
    assert seq.motion["v"]["a"].tolist() == [True, False]  # size never moves during `a`
    time, x = stream(0.25, _ramp(0.0, 1.0))
    x[:, 1] += 0.02 * np.sin(np.arange(len(time)))  # size jitters all the time
    events = run(seq, time, x)
    assert [target for _, target in events] == ["b"]


@pytest.mark.parametrize(("size", "expected"), [(0.3, "a"), (0.7, "z")])
def test_starts_at_the_initial_mp_with_the_nearest_entry_state(size, expected):
    demos = [toy_demo(0.2, ["a", "b"], "demo_0"), toy_demo(0.8, ["z", "b"], "demo_1")]
    seq = GoalNearestSequencer.fit(demos)
    assert seq.graphs["v"].initial_nodes == {"a", "z"}
    assert seq.reset(0.0, np.array([0.0, size])) == {"v": expected}


def test_batched_episodes_match_single_runs(two_successors):
    seq = GoalNearestSequencer.fit(two_successors)
    streams = [stream(0.3, _ramp(0.0, 1.0)), stream(0.7, _ramp(0.0, 1.0))]
    single = [run(GoalNearestSequencer.fit(two_successors), t, x) for t, x in streams]
    batch = seq.batched(2)
    time = streams[0][0]
    x = np.stack([s[1] for s in streams], axis=1)  # (n, 2 episodes, d)
    batch.reset(time[0], x[0])
    for k in range(1, len(time)):
        live = np.array([True, k < 80])  # the second episode ends early: left untouched after
        batch.step(time[k], x[k], live=live)
    assert [(e.t, e.target) for e in batch.events[0]] == single[0]
    assert batch.events[1] == []  # it ended before converging
    assert batch.active == [{"v": "b"}, {"v": "a"}]


def test_batch_refuses_bad_inputs_as_the_learned_sequencers_batch_does(two_successors):
    """The same input checks (and messages) as BatchedSequencer (tests/test_batches.py)."""
    seq = GoalNearestSequencer.fit(two_successors)
    batch = seq.batched(2)
    x = np.array([[0.0, 0.3], [0.0, 0.7]])
    batch.reset(0.0, x)
    with pytest.raises(DataError, match=r"shape \(2, 2\)"):
        batch.step(DT, x[:1])
    with pytest.raises(DataError, match="boolean mask"):
        batch.step(DT, x, live=[1, 0])
    with pytest.raises(DataError, match="finite"):
        batch.step(np.nan, x)
    with pytest.raises(DataError, match="one time or 2 times"):
        batch.step(np.array([DT, DT, DT]), x)
    bad = x.copy()
    bad[0, 0] = np.inf
    with pytest.raises(DataError, match=r"episode 0: .*NaN or inf"):
        batch.step(DT, bad)
    for n in (0, -1, 2.5, True):
        with pytest.raises(ConfigError, match="n >= 1"):
            seq.batched(n)


def test_save_load_gives_identical_decisions_and_progress(two_successors, tmp_path):
    seq = GoalNearestSequencer.fit(two_successors, hold_time=0.05, speed_threshold=0.01)
    path = seq.save(tmp_path / "goal_nearest.pt")
    loaded = GoalNearestSequencer.load(path)
    assert loaded.config == seq.config
    time, x = stream(0.7, _ramp(0.0, 1.0))
    assert run(loaded, time, x) == run(seq, time, x)
    np.testing.assert_array_equal(loaded.progress(x), seq.progress(x))


def test_nearest_progress_reproduces_the_training_targets(two_successors):
    seq = GoalNearestSequencer.fit(two_successors)
    demo = two_successors[0]
    phi = seq.progress(demo.features)  # (n, K) with K = nodes a, b, c
    assert phi.shape == (demo.n_samples, 3)
    # every φ is the expected progress of one of its own node's training samples
    targets, node = seq.predictor.targets.numpy(), seq.predictor.node.numpy()
    for k in range(phi.shape[1]):
        assert np.isin(phi[:, k], targets[node == k]).all()
    index = seq.node_keys.index(("v", "b"))
    for segment in demo.segments("v"):
        if segment.mp != "b":
            continue
        sl = slice(segment.start, segment.stop)
        scaled = seq.predictor.scaler.transform(demo.features[sl])
        # every sample of a training activation is its own nearest neighbour, except where
        # the hold repeats a state (equal distances); compare on the moving part
        moving = round(MOVE / DT)
        np.testing.assert_allclose(
            phi[sl, index][:moving], expected_progress(scaled, demo.time[sl])[:moving]
        )


def test_errors_say_what_to_fix(two_successors, tmp_path):
    with pytest.raises(ConfigError, match="speed_threshold must be > 0"):
        GoalNearestSequencer.fit(two_successors, speed_threshold=-1.0)
    with pytest.raises(ConfigError, match="valid options: speed_threshold"):
        GoalNearestSequencer.fit(two_successors, patience=0.05)
    with pytest.raises(DataError, match="at least one demonstration"):
        GoalNearestSequencer.fit([])
    seq = GoalNearestSequencer.fit(two_successors)
    with pytest.raises(NotFittedError, match="reset"):
        seq.step(0.0, np.zeros(2))
    seq.reset(0.0, np.zeros(2))
    with pytest.raises(DataError, match="NaN or inf"):
        seq.step(0.01, np.array([np.nan, 0.0]))
    with pytest.raises(DataError, match="backwards"):
        seq.step(-1.0, np.zeros(2))
    (tmp_path / "junk.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(CpmpFileError, match="goal_nearest checkpoint"):
        GoalNearestSequencer.load(tmp_path / "junk.pt")


def test_load_refuses_untrusted_pickles(tmp_path):
    """A file holding Python objects is refused as untrusted, like a sequencer checkpoint,
    without torch's hint to switch the protection off."""
    torch.save({"format": "x", "obj": GoalNearestSequencer}, tmp_path / "evil.pt")
    with pytest.raises(CpmpFileError, match="not a trusted goal_nearest checkpoint") as info:
        GoalNearestSequencer.load(tmp_path / "evil.pt")
    assert "weights_only=False" not in str(info.value)
