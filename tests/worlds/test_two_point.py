"""The two-point synthetic task (cpmp.worlds.two_point): demonstrator, closed loop, Fig. 3 paths."""

import numpy as np
import pytest

from cpmp.errors import ConfigError
from cpmp.worlds.two_point import (
    SyntheticTask,
    curved_trajectories,
    evaluate,
    make_demonstrations,
)

SEQUENTIAL = {"a": ["a_go", "a_wait", "a_back"], "b": ["b_wait", "b_go", "b_back"]}
PARALLEL = {"a": ["a_go", "a_back"], "b": ["b_go", "b_back"]}


class Replay:
    """Replays a demonstration's labels by time (the sample at or before ``t``)."""

    def __init__(self, demo) -> None:
        self.demo = demo

    def _at(self, t):
        i = int(np.searchsorted(self.demo.time, t + 1e-9) - 1)
        return {v: str(lab[min(i, len(lab) - 1)]) for v, lab in self.demo.labels.items()}

    def reset(self, t, x):
        return self._at(t)

    def step(self, t, x):
        return self._at(t)


def test_demonstrations_alternate_the_strategies():
    demos = make_demonstrations(4, seed=0)
    for i, demo in enumerate(demos):
        sequential = i % 2 == 0
        assert demo.metadata["strategy"] == ("sequential" if sequential else "parallel")
        assert (demo.metadata["context"] < 0.5) == sequential
        expected = SEQUENTIAL if sequential else PARALLEL
        assert {v: [s.mp for s in demo.segments(v)] for v in ("a", "b")} == expected
        # the demonstration ends with both points home
        assert np.all(np.abs(demo.features[-1, :2]) < 0.01)
        np.testing.assert_allclose(demo.features[:, 2], demo.metadata["context"])


def test_replaying_the_demonstration_completes_the_episode():
    task = SyntheticTask()
    rng = np.random.default_rng(4)
    for context in (0.2, 0.8):
        episode = task.sample_episode(rng, context)
        demo = task.demonstrate(episode)
        sequences, done = task.rollout(episode, Replay(demo))
        assert done
        assert sequences == {v: [s.mp for s in demo.segments(v)] for v in ("a", "b")}


def test_bad_options_and_arguments_raise():
    with pytest.raises(ConfigError, match="must all be > 0"):
        SyntheticTask(dt=0.0)
    with pytest.raises(ConfigError, match="positive integer"):
        evaluate(Replay(make_demonstrations(1)[0]), n_episodes=0)


def test_curved_trajectories_run_from_the_start_to_the_end_region():
    demos = curved_trajectories(n=3, seed=1, n_samples=50)
    for demo in demos:
        assert demo.features.shape == (50, 2) and demo.variables == ["var"]
        assert set(demo.labels["var"]) == {"move"}
        # start and end are jittered by at most 0.06 per axis around (0.1, 0.1) and (0.9, 0.9)
        assert np.max(np.abs(demo.features[0] - 0.1)) <= 0.06
        assert np.max(np.abs(demo.features[-1] - 0.9)) <= 0.06
    assert not np.array_equal(demos[0].features, demos[1].features)


def test_rollouts_of_a_fitted_sequencer_equal_its_rollouts_one_at_a_time(fitted_klr):
    """A fitted sequencer runs every episode at once (its ``batched``); each episode's run is
    the one :meth:`SyntheticTask.rollout` gives it, and :func:`evaluate` counts them."""
    task = SyntheticTask(max_time=3.0)  # short: some episodes end home, others at the limit
    rng = np.random.default_rng(3)
    episodes = [task.sample_episode(rng) for _ in range(10)]
    # the joint start on the nodes' φ starts some episodes wrongly: every outcome occurs
    seq = fitted_klr.with_config(start_rule="joint")
    batched = task.rollouts(episodes, seq)
    single = [task.rollout(e, seq) for e in episodes]
    assert batched == single
    outcomes = [task.outcome(e, r) for e, r in zip(episodes, batched, strict=True)]
    assert {"complete", "incomplete", "wrong_start"} <= set(outcomes)
    counts = evaluate(seq, task, n_episodes=10, seed=3)
    assert counts == {o: outcomes.count(o) for o in counts}
    assert task.rollouts(episodes[:2], Replay(make_demonstrations(1)[0])) == [
        task.rollout(e, Replay(make_demonstrations(1)[0])) for e in episodes[:2]
    ]
