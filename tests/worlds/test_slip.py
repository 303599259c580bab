"""The slip world: a reactive retry loop decided mid-lift, behind the World protocol."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from cpmp.data.demonstration import mp_sequences
from cpmp.errors import ConfigError, UnknownMPError
from cpmp.graph import build_graphs
from cpmp.worlds.protocol import World, evaluate
from cpmp.worlds.slip import FEATURE_NAMES, STRATEGIES, SlipWorld, make_contexts
from cpmp.worlds.slip.world import CARRY_Z


@pytest.fixture(scope="module")
def world() -> SlipWorld:
    return SlipWorld()


@pytest.fixture(scope="module")
def demos(world):
    return world.demonstrations(12, 0)


def _run_policy(world, context, override=None, limit=None):
    """Run the scripted policy on ``context``; ``override(run, active)`` may change the MPs."""
    run = world.start(context)
    policy = world.scripted_policy()
    active = policy.reset(0.0, run.features())
    t = 0.0
    while not run.done(active) and t < (limit or world.max_time):
        run.advance(active, world.dt)
        t += world.dt
        active = policy.step(t, run.features())
        if override is not None:
            active = override(run, active)
            policy.active = dict(active)
    return run, active


def test_is_a_world_with_scaled_features(world, demos):
    assert isinstance(world, World)
    assert world.name == "slip" and world.dt == 0.01
    assert 8 <= len(world.feature_names) <= 14
    x = np.concatenate([d.features for d in demos])
    assert x.min() >= -0.05 and x.max() <= 2.0
    assert list(demos[0].feature_names) == list(FEATURE_NAMES)


def test_scripted_policy_completes(world):
    counts = evaluate(world, world.scripted_policy(), 100, seed=1000).counts
    assert counts["complete"] >= 99


def test_demonstrator_reaches_the_goal_with_the_expected_sequences(world, demos):
    contexts = world.contexts(12, 0)
    for i, d in enumerate(demos):
        assert d.name == f"demo_{i}"
        assert d.metadata["reached_goal"] is True
        assert d.metadata["strategy"] == STRATEGIES[i % len(STRATEGIES)]
        run = world.start(contexts[i])
        assert not run.complete({"arm": "retreat", "gripper": "open", "drawer": "push_shut"})
    for c in contexts:
        demo = world.demonstrate(c)
        assert demo.metadata["reached_goal"] is True
        assert mp_sequences(demo) == world.expected_sequences(c)


def test_graphs_of_three_demos(world):
    demos = world.demonstrations(3, 0)
    assert any(d.metadata["n_slips"] > 0 for d in demos)
    g = build_graphs(demos)
    arm, gripper, drawer = g["arm"], g["gripper"], g["drawer"]
    assert arm.nodes == {"reach", "lift", "lower", "place", "retreat"}
    assert arm.successors("lift") == ["lower", "place"]  # the slip decides
    assert ("lower", "lift") in arm.edges  # the retry loop
    assert arm.initial_nodes == {"reach"}
    assert gripper.nodes == {"open", "close", "release"}
    assert gripper.successors("close") == ["open", "release"]
    assert ("open", "close") in gripper.edges
    assert gripper.initial_nodes == {"open"}
    assert drawer.initial_nodes == {"pull_open", "hold_open"}
    assert drawer.edges == {("pull_open", "hold_open"), ("hold_open", "push_shut")}


def test_demonstrations_are_reproducible(world):
    a, b = world.demonstrations(4, 7), world.demonstrations(4, 7)
    c = world.demonstrations(4, 8)
    for da, db in zip(a, b, strict=True):
        np.testing.assert_array_equal(da.features, db.features)
        assert mp_sequences(da) == mp_sequences(db)
    assert not np.array_equal(a[0].features[0], c[0].features[0])


def test_slip_count_is_not_decided_by_the_start(world, demos):
    by_strategy: dict[str, set[int]] = {}
    for d in demos:
        by_strategy.setdefault(d.metadata["strategy"], set()).add(d.metadata["n_slips"])
    assert all(counts == {0, 1, 2} for counts in by_strategy.values())
    base = world.contexts(1, 3)[0]
    variants = [dataclasses.replace(base, n_slips=k) for k in range(3)]
    runs = [world.demonstrate(c) for c in variants]
    for r in runs[1:]:
        np.testing.assert_array_equal(r.features[0], runs[0].features[0])
    assert [mp_sequences(r)["arm"].count("lower") for r in runs] == [0, 1, 2]
    assert {world.strategy(c) for c in variants} == {base.strategy}
    assert len({tuple(world.initial_mps(c).items()) for c in variants}) == 1


def test_start_is_decided_by_the_drawer(world):
    shut, opened = world.contexts(2, 0)
    assert world.initial_mps(shut)["drawer"] == "pull_open"
    assert world.initial_mps(opened)["drawer"] == "hold_open"
    for c in (shut, opened):
        assert world.scripted_policy().reset(0.0, world.start(c).features()) == world.initial_mps(c)


def test_slip_is_seen_mid_lift_in_grip_and_contact(world):
    context = dataclasses.replace(world.contexts(1, 0)[0], n_slips=1)
    demo = world.demonstrate(context)
    lift = demo.segments("arm")[1]
    assert lift.mp == "lift"
    z = demo.features[lift.stop - 1, 1]
    assert z < CARRY_Z - 0.2  # it slipped well below the carry height
    contact, grip = demo.features[:, 3], demo.features[:, 2]
    assert contact[lift.stop - 2] == 1.0 and contact[lift.stop - 1] == 0.0
    assert grip[lift.stop - 1] < grip[lift.stop - 2] - 0.01  # the fingers close on past it
    assert grip[lift.stop + 5] > grip[lift.stop - 2]  # and the gripper opens again at once


def test_advancing_three_ticks_at_once_equals_three_steps(world):
    context = world.contexts(1, 5)[0]
    active = {"arm": "reach", "gripper": "open", "drawer": world.initial_mps(context)["drawer"]}
    a, b = world.start(context), world.start(context)
    for _ in range(40):
        a.advance(active, 0.03)
        for _ in range(3):
            b.advance(active, 0.01)
    np.testing.assert_allclose(a.features(), b.features(), rtol=0, atol=1e-12)
    c = world.start(context)
    c.advance(active, 0.005)
    assert c.features()[1] != a.features()[1]


def test_release_at_carry_height_breaks_the_object(world):
    context = dataclasses.replace(world.contexts(1, 2)[0], n_slips=0)

    def early_release(run, active):
        if active["arm"] == "lift" and run.features()[1] > CARRY_Z - 0.05:
            return {**active, "gripper": "release"}
        return active

    run, active = _run_policy(world, context, early_release)
    assert run.done(active) and not run.complete(active)
    assert run.state.failure == "broken"
    assert run.failed_at is not None and 0 < run.failed_at <= run.t
    assert run.failure() == (
        f"the object fell from too high onto the table and broke at {run.failed_at:.2f} s"
    )


def test_shutting_the_drawer_on_the_arm_fails(world):
    context = world.contexts(2, 4)[1]

    def early_shut(run, active):
        if active["gripper"] == "release":
            return {**active, "drawer": "push_shut"}
        return active

    run, active = _run_policy(world, context, early_shut)
    assert run.done(active) and not run.complete(active)
    assert run.state.failure == "hit"
    assert run.failure().startswith("the arm hit the cabinet front")


def test_place_on_a_wrong_slip_guess_does_not_complete(world):
    # lifting on after a slip (no lower) carries nothing: the goal is never reached
    context = dataclasses.replace(world.contexts(1, 6)[0], n_slips=1)

    def ignore_slip(run, active):
        return {**active, "arm": "place" if active["arm"] == "lower" else active["arm"]}

    run, active = _run_policy(world, context, ignore_slip, limit=12.0)
    assert not run.complete(active)
    assert run.state.holder == "table"
    assert run.failed_at is None
    assert run.failure().startswith("the object is not in the drawer (it is on the table)")


@pytest.mark.parametrize(
    "options",
    [
        {"dt": 0.0},
        {"dt": 0.2},
        {"tolerance": 0.1},
        {"max_slips": 4},
        {"max_slips": 1.5},
        {"slip_low": 0.5, "slip_high": 0.3},
        {"slip_high": 0.68},
        {"drop_limit": 0.8},
        {"width_noise": -1.0},
        {"max_time": float("nan")},
        {"gain_arm": True},
    ],
)
def test_bad_options_raise(options):
    with pytest.raises(ConfigError):
        SlipWorld(**options)


def test_bad_arguments_raise(world):
    with pytest.raises(ConfigError):
        world.contexts(0, 0)
    with pytest.raises(ConfigError):
        world.sample_context(np.random.default_rng(0), "sideways")
    with pytest.raises(ConfigError):
        world.sample_context(np.random.default_rng(0), "open_low", n_slips=3)
    run = world.start(world.contexts(1, 0)[0])
    with pytest.raises(UnknownMPError):
        run.advance({"arm": "jump", "gripper": "open", "drawer": "pull_open"}, 0.01)
    with pytest.raises(ConfigError):
        run.advance({"arm": "reach", "gripper": "open", "drawer": "pull_open"}, 0.0)


@pytest.mark.parametrize("max_slips", [0, 1, 3])
def test_every_strategy_meets_every_slip_count(max_slips):
    world = SlipWorld(max_slips=max_slips, max_time=25.0)
    n = 4 * (max_slips + 1)
    seen: dict[str, set[int]] = {}
    for c in make_contexts(world, n, 0, cycle_slips=True):
        seen.setdefault(c.strategy, set()).add(c.n_slips)
    assert seen == {s: set(range(max_slips + 1)) for s in STRATEGIES}
    assert world.max_time == 25.0


@pytest.mark.slow
def test_the_arm_takes_the_gripper_along_after_a_slip(world):
    """After a slip the arm's ``lift -> lower`` is timed by the lost contact; the gripper's
    ``close -> open``, demonstrated in the same sample, has a ``p`` that never reaches the
    threshold there (its ``close`` ended early). The fit marks the gripper carried, and
    without that the arm waits for it until the stall recovery takes the pair, a stall time
    or more later at every slip."""
    from cpmp.sequencer import ConcurrentSequencer

    seq = ConcurrentSequencer.fit(list(world.demonstrations(6, 0)), seed=0, logger=None)
    partner = seq.coupling.joint[("arm", "lift", "lower")]["gripper"]
    assert partner.carried
    assert "together with gripper: close -> open (taken along)" in seq.describe()
    assert not seq.coupling.joint[("gripper", "close", "open")]["arm"].carried
    joint = {
        edge: {u: p._replace(carried=False) for u, p in partners.items()}
        for edge, partners in seq.coupling.joint.items()
    }
    waiting = seq._with_branches(seq.branches, dataclasses.replace(seq.coupling, joint=joint))
    carried, waited = evaluate(world, seq, 10, 1000), evaluate(world, waiting, 10, 1000)
    assert carried.counts["complete"] >= 8
    assert carried.counts["complete"] >= waited.counts["complete"]
    late = [b.time - a.time for a, b in zip(carried.episodes, waited.episodes, strict=True)]
    assert min(late) > -1e-9  # never sooner
    slipped = [d for d in late if d > 1e-9]
    assert len(slipped) >= 5 and min(slipped) >= seq.config.stall_time
