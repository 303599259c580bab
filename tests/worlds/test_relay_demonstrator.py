"""The relay task's scripted demonstrator (cpmp.worlds.relay.demonstrator)."""

import numpy as np
import pytest

from cpmp.errors import ConfigError
from cpmp.graph import build_graphs
from cpmp.worlds.relay.demonstrator import ScriptedPolicy, demonstrate, make_demonstrations
from cpmp.worlds.relay.evaluation import rollout
from cpmp.worlds.relay.world import FEATURE_NAMES, STRATEGIES, VARIABLES, RelayTask

MEET = {
    "carrier": ["carry", "retreat", "rest"],
    "gripper": ["open", "close", "hold", "release"],
    "receiver": ["approach", "withdraw"],
}
FETCH = {
    "carrier": ["present", "retreat", "rest"],
    "gripper": ["open", "close", "hold", "release"],
    "receiver": ["approach", "stow"],
}


@pytest.fixture(scope="module")
def demos():
    return make_demonstrations(6, seed=0)


def test_demonstrations_are_reproducible(demos):
    again = make_demonstrations(6, seed=0)
    other = make_demonstrations(6, seed=1)
    for a, b, c in zip(demos, again, other, strict=True):
        assert np.array_equal(a.features, b.features) and np.array_equal(a.time, b.time)
        assert all(np.array_equal(a.labels[v], b.labels[v]) for v in VARIABLES)
        assert a.metadata == b.metadata
        assert not np.array_equal(a.features[:5], c.features[:5])


def test_demonstrations_labelled_as_designed(demos):
    for i, demo in enumerate(demos):
        assert demo.feature_names == FEATURE_NAMES and demo.variables == VARIABLES
        assert demo.name == f"demo_{i}" and demo.metadata["reached_goal"] is True
        strategy = STRATEGIES[i % 2]
        assert demo.metadata["strategy"] == strategy
        expected = MEET if strategy == "meet" else FETCH
        assert {v: [s.mp for s in demo.segments(v)] for v in VARIABLES} == expected
        np.testing.assert_allclose(np.diff(demo.time), 0.01)
        assert 2.0 < demo.duration < 6.0


def test_sequence_graphs(demos):
    graphs = build_graphs(demos)
    carrier, gripper, receiver = (graphs[v] for v in VARIABLES)
    assert carrier.nodes == {"carry", "present", "retreat", "rest"}
    assert carrier.initial_nodes == {"carry", "present"}
    assert carrier.edges == {("carry", "retreat"), ("present", "retreat"), ("retreat", "rest")}
    assert gripper.initial_nodes == {"open"}
    assert gripper.edges == {("open", "close"), ("close", "hold"), ("hold", "release")}
    assert receiver.initial_nodes == {"approach"}
    assert receiver.edges == {("approach", "withdraw"), ("approach", "stow")}


def test_demonstrator_switches_as_soon_as_guards_hold(demos):
    task = RelayTask()
    for demo in demos:
        force = demo.features[:, FEATURE_NAMES.index("grip_force")]
        (close, hold, _) = demo.switch_indices("gripper")
        # the force is flat while the fingers travel to the object (the ambiguous pause) ...
        flat = np.flatnonzero(force[close:] > 0)[0]
        assert flat * task.dt > 0.2
        # ... the gripper holds at the first sample past the contact force ...
        assert force[hold - 1] >= task.contact_force > force[hold - 2]
        # ... and the other hands leave one tick later, still moving.
        assert demo.switch_indices("carrier")[0] == hold + 1
        assert demo.switch_indices("receiver")[0] == hold + 1
        retreat_end = demo.switch_indices("carrier")[1]
        speed = np.linalg.norm(demo.features[retreat_end, :2] - demo.features[retreat_end - 1, :2])
        assert speed > 1e-3  # no settle time: still moving at the switch


def test_scripted_policy_completes_every_episode():
    task = RelayTask()
    rng = np.random.default_rng(11)
    for i in range(8):
        episode = task.sample_episode(rng, STRATEGIES[i % 2])
        result = rollout(task, episode, ScriptedPolicy(task, episode))
        expected = MEET if episode.strategy == "meet" else FETCH
        assert result.outcome == "complete", result
        assert result.sequences == expected
        assert result.time == pytest.approx(demonstrate(task, episode).duration, abs=0.011)


def test_make_demonstrations_rejects_a_bad_count():
    with pytest.raises(ConfigError, match="positive integer"):
        make_demonstrations(0)
