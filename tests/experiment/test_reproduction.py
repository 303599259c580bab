"""Reproduction: a paced robot is paced from the run's seed."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cpmp.data import Demonstration
from cpmp.experiment.collection import SeedData
from cpmp.experiment.reproduction import reproduce_seed, summarize_episodes
from cpmp.records import SequencerNote, TransitionEvent
from cpmp.sim import Box, Simulation, TaskConfig
from cpmp.sim.policies import PolicyList

RIGHT_BOX = Box(0.15, 0.12, 0.10)
REACH = {
    "left_pos": "idle",
    "left_rot": "idle",
    "left_fingers": "relax",
    "right_pos": "reach_top",
    "right_rot": "down",
    "right_fingers": "relax",
}
"""The right-hand strategy's initial MPs: the right arm reaches for the box, nothing else."""
PACED = TaskConfig(max_time=0.6, robot_speed=(0.5, 2.0))
"""0.6 s of a robot whose MPs run at x0.5-2 (experiment=varied's robot), drawn per activation."""


@dataclass
class Reach:
    """One episode that keeps :data:`REACH` and keeps every feature vector it is given."""

    seen: list[np.ndarray] = field(default_factory=list)
    events: list[TransitionEvent] = field(default_factory=list)
    notes: list[SequencerNote] = field(default_factory=list)

    def reset(self, t: float, x: np.ndarray) -> dict[str, str]:
        self.seen.append(np.array(x))
        return dict(REACH)

    def step(self, t: float, x: np.ndarray) -> dict[str, str]:
        self.seen.append(np.array(x))
        return dict(REACH)


class ReachBatch(PolicyList):
    """:class:`Reach` episodes batched, read back as a batched sequencer's ``episodes``."""

    @property
    def episodes(self) -> list[Reach]:
        return self.policies


@dataclass
class ReachSequencer:
    """What :func:`reproduce_seed` reads of a sequencer, driving :class:`ReachBatch`."""

    feature_names: list[str]
    graphs: dict = field(default_factory=dict)
    batches: list[ReachBatch] = field(default_factory=list)

    def batched(self, n: int) -> ReachBatch:
        self.batches.append(ReachBatch([Reach() for _ in range(n)]))
        return self.batches[-1]


def reach_features(task: TaskConfig, seed: int) -> np.ndarray:
    """The features ``(n, d)`` the policy saw in the one reproduction episode of seed ``seed``."""
    names = Simulation(task, RIGHT_BOX).feature_names
    expected = Demonstration(
        time=np.array([0.0, 0.01]),
        features=np.zeros((2, len(names))),
        labels={v: np.array([mp, mp]) for v, mp in REACH.items()},
        feature_names=names,
        name="demo_right",
    )
    data = SeedData(seed, [], [], [RIGHT_BOX], [expected], {})
    seq = ReachSequencer(names)
    (episode,) = reproduce_seed(seq, data, task, record="none")  # type: ignore[arg-type]
    assert episode.outcome == "incomplete" and "time-out" in episode.reason
    # its only MPs are the demonstrator's: no switch was due, the task did not finish
    assert episode.cause is not None and episode.cause["reason"] == "task_unfinished"
    assert summarize_episodes([episode])["causes"] == {"task_unfinished": 1}
    return np.stack(seq.batches[0].episodes[0].seen)


def test_the_paced_robot_is_paced_from_the_runs_seed() -> None:
    a, again, other = (reach_features(PACED, s) for s in (0, 0, 1))
    assert a.shape == other.shape and len(a) > 50
    np.testing.assert_array_equal(a, again)  # the same seed: the same pace, to the bit
    assert not np.allclose(a[-1], other[-1], atol=1e-3)  # another seed: another pace


def test_an_unpaced_robot_does_not_depend_on_the_seed() -> None:
    unpaced = TaskConfig(max_time=0.6)
    np.testing.assert_array_equal(reach_features(unpaced, 0), reach_features(unpaced, 1))
