"""Scripted policies that read only the features: the proof that each synthetic world is fair.

Each world's demonstrator knows its episode (goals that are not features); its feature policy
must decide the same switches from the feature stream alone. Replaying a demonstration's
features through ``reset``/``step`` (no world, no episode anywhere) must give the
demonstrator's MPs tick for tick; closed loop it must complete >= 99 of 100 episodes.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import NamedTuple

import numpy as np
import pytest

from cpmp.data.demonstration import Demonstration, mp_sequences
from cpmp.records import Policy
from cpmp.worlds import relay, repetition, two_point
from cpmp.worlds.attractor import AttractorGoal
from cpmp.worlds.relay import varied
from cpmp.worlds.relay.policy import RelayFeaturePolicy
from cpmp.worlds.relay.world import RelayTask
from cpmp.worlds.repetition.policy import RepetitionFeaturePolicy
from cpmp.worlds.repetition.world import RepetitionTask
from cpmp.worlds.two_point import SyntheticTask
from cpmp.worlds.two_point.policy import TwoPointFeaturePolicy

N_EPISODES = 100
N_DEMOS = 10
SEED = 1000


class Case(NamedTuple):
    """One world's feature policy and where it runs.

    Attributes:
        policy: a fresh feature policy.
        demos: ``n`` demonstrations of the world from a seed.
        complete: the number of complete closed-loop episodes of a policy (100, seed 1000).
    """

    policy: Callable[[], Policy]
    demos: Callable[[int, int], list[Demonstration]]
    complete: Callable[[Policy], int]


def _relay_complete(policy: Policy) -> int:
    return relay.evaluate(policy, RelayTask(), n_episodes=N_EPISODES, seed=SEED)["complete"]


def _paced_complete(policy: Policy) -> int:
    scores = varied.evaluate(policy, None, N_EPISODES, SEED)
    return sum(s.outcome == "complete" for s in scores)


def _repetition_complete(policy: Policy) -> int:
    task = RepetitionTask()
    return repetition.evaluate(policy, task, n_episodes=N_EPISODES, seed=SEED)["complete"]


def _two_point_complete(task: SyntheticTask) -> Callable[[Policy], int]:
    def complete(policy: Policy) -> int:
        return two_point.evaluate(policy, task, n_episodes=N_EPISODES, seed=SEED)["complete"]

    return complete


JITTERED = SyntheticTask(goal_jitter=0.1)
CASES = {
    "two_point": Case(
        lambda: TwoPointFeaturePolicy(SyntheticTask()),
        lambda n, seed: two_point.make_demonstrations(n, seed),
        _two_point_complete(SyntheticTask()),
    ),
    "two_point_goal_jitter": Case(
        lambda: TwoPointFeaturePolicy(JITTERED),
        lambda n, seed: two_point.make_demonstrations(n, seed, JITTERED),
        _two_point_complete(JITTERED),
    ),
    "relay": Case(
        lambda: RelayFeaturePolicy(RelayTask()),
        lambda n, seed: relay.make_demonstrations(n, seed),
        _relay_complete,
    ),
    "paced_relay": Case(
        lambda: RelayFeaturePolicy(RelayTask()),
        lambda n, seed: varied.make_demonstrations(n, seed),  # varied speeds and holds
        _paced_complete,
    ),
    "repetition": Case(
        lambda: RepetitionFeaturePolicy(RepetitionTask()),
        lambda n, seed: repetition.make_demonstrations(n, seed),
        _repetition_complete,
    ),
}


def replay(policy: Policy, demo: Demonstration, stop: int | None = None) -> list[dict[str, str]]:
    """The policy's MPs after each sample of ``demo``'s features (``reset`` on the first).

    The demonstrator decides at sample ``i`` what becomes the label of sample ``i + 1``; the
    last sample (the goal state) decides nothing. ``stop`` ends the replay early.
    """
    end = demo.n_samples - 1 if stop is None else stop
    out = [dict(policy.reset(float(demo.time[0]), demo.features[0]))]
    for i in range(1, end):
        out.append(dict(policy.step(float(demo.time[i]), demo.features[i])))
    return out


def sequences(decisions: list[dict[str, str]]) -> dict[str, list[str]]:
    """Variable -> the MPs of ``decisions`` in order (one entry per activation)."""
    seqs = {v: [mp] for v, mp in decisions[0].items()}
    for d in decisions[1:]:
        for v, seq in seqs.items():
            if d[v] != seq[-1]:
                seq.append(d[v])
    return seqs


def labels_after(demo: Demonstration) -> list[Mapping[str, str]]:
    """The demonstrator's MPs after each sample but the last (the labels of samples 1, 2, …)."""
    return [
        {v: str(demo.labels[v][i + 1]) for v in demo.variables} for i in range(demo.n_samples - 1)
    ]


@pytest.fixture(scope="module")
def demos() -> dict[str, list[Demonstration]]:
    return {name: case.demos(N_DEMOS, 7) for name, case in CASES.items()}


@pytest.mark.parametrize("name", list(CASES))
def test_feature_policy_completes_the_closed_loop(name: str) -> None:
    complete = CASES[name].complete(CASES[name].policy())
    assert complete >= 99, f"{name}: {complete} of {N_EPISODES} complete"


@pytest.mark.parametrize("name", list(CASES))
def test_replaying_features_only_reproduces_the_demonstrator(
    name: str, demos: dict[str, list[Demonstration]]
) -> None:
    """No world and no episode: only the recorded features reach the policy."""
    policy = CASES[name].policy()
    for demo in demos[name]:
        decisions = replay(policy, demo)
        assert sequences(decisions) == mp_sequences(demo), demo.name
        assert decisions == labels_after(demo), demo.name  # tick for tick


def test_paced_demonstrations_replayed_hold_mid_mp(demos: dict[str, list[Demonstration]]) -> None:
    """The paced replays above include holds (features standing still mid-MP)."""
    assert sum(d.metadata["holds"] for d in demos["paced_relay"]) > 0


@pytest.mark.parametrize("name", list(CASES))
def test_reset_forgets_the_last_episode(name: str, demos: dict[str, list[Demonstration]]) -> None:
    first, second = demos[name][0], demos[name][1]
    reused = CASES[name].policy()
    replay(reused, first, stop=first.n_samples // 2)  # left mid-episode, memory full
    assert replay(reused, second) == replay(CASES[name].policy(), second)
    replay(reused, first)
    assert replay(reused, second) == replay(CASES[name].policy(), second)


def test_reset_forgets_the_last_closed_loop_episode() -> None:
    """Two closed-loop episodes in a row run as on fresh policies."""
    task = RelayTask()
    episodes = [task.sample_episode(np.random.default_rng(s), "meet") for s in (1, 2)]
    reused = RelayFeaturePolicy(task)
    runs = [relay.rollout(task, e, reused) for e in episodes]
    fresh = [relay.rollout(task, e, RelayFeaturePolicy(task)) for e in episodes]
    for a, b in zip(runs, fresh, strict=True):
        assert (a.outcome, a.sequences, a.time) == (b.outcome, b.sequences, b.time)


def test_attractor_goal_is_exact_at_any_speed_and_through_holds() -> None:
    """Two steps of ``p += c (g - p)`` give ``g``; a still tick (a hold) is skipped."""
    goal = np.array([1.3, -0.4])
    for c in (0.015, 0.04, 0.08):
        est = AttractorGoal()
        assert est.goal() is None
        p = np.array([0.1, 0.2])
        est.observe(p)
        for tick in range(40):
            if tick not in (5, 6, 7):  # held still
                p = p + c * (goal - p)
            est.observe(p)
        found = est.goal()
        assert found is not None
        np.testing.assert_allclose(found, goal, atol=1e-9)
        assert est.distance() == pytest.approx(float(np.linalg.norm(goal - p)), abs=1e-9)
        est.restart()
        assert est.goal() is None and est.distance() == float("inf")


def test_attractor_goal_outside_its_box_is_unknown() -> None:
    est = AttractorGoal(low=[0.9], high=[1.1])
    p = 0.0
    for _ in range(5):
        est.observe([p])
        p += 0.1 * (2.0 - p)  # heads for 2, outside the box
    assert est.goal() is None
