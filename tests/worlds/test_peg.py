"""The peg world: a reactive insertion with hidden jams, a holder across the retries."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from cpmp.data.demonstration import mp_sequences
from cpmp.errors import ConfigError, UnknownMPError
from cpmp.graph import build_graphs
from cpmp.worlds.peg import FEATURE_NAMES, STRATEGIES, VARIABLES, PegWorld
from cpmp.worlds.peg.world import (
    BASE_MASS,
    CLAMP,
    FORCE,
    HOLE_X,
    INSERTER_X,
    INSERTER_Z,
    MOUTH_Z,
    PEG_DEPTH,
)
from cpmp.worlds.protocol import World, WorldRun, evaluate, run_episode


@pytest.fixture(scope="module")
def world() -> PegWorld:
    return PegWorld()


@pytest.fixture(scope="module")
def demos(world):
    return world.demonstrations(8, 0)


def _context(world, strategy, n_jams=0, seed=5):
    return world.sample_context(np.random.default_rng(seed), strategy, n_jams)


def test_protocol_and_features_in_range(world, demos):
    assert isinstance(world, World)
    assert isinstance(world.start(world.contexts(1, 0)[0]), WorldRun)
    assert world.name == "peg" and world.variables == VARIABLES
    assert 8 <= len(world.feature_names) <= 14
    x = np.concatenate([d.features for d in demos])
    assert x.shape[1] == len(FEATURE_NAMES)
    assert x.min() > -0.1 and x.max() < 2.0


def test_scripted_policy_completes(world):
    ev = evaluate(world, world.scripted_policy(), 100, seed=1000)
    assert ev.complete >= 99
    # every strategy and every jam count is in the evaluation
    assert {e.strategy for e in ev.episodes} == set(STRATEGIES)
    retracts = {e.sequences["inserter"].count("retract") for e in ev.episodes}
    assert retracts == {0, 1, 2}


def test_scripted_policy_is_fresh(world):
    a, b = world.scripted_policy(), world.scripted_policy()
    assert a is not b
    light = world.start(_context(world, "light_shallow")).features()
    heavy = world.start(_context(world, "heavy_shallow")).features()
    assert a.reset(0.0, light)["holder"] == "hold"
    assert b.reset(0.0, heavy)["holder"] == "rest"
    assert a.active["holder"] == "hold"


def test_demonstrations_reach_the_goal_with_the_expected_sequences(world, demos):
    assert [d.name for d in demos] == [f"demo_{i}" for i in range(8)]
    for i, d in enumerate(demos):
        assert d.metadata["reached_goal"] is True
        assert d.metadata["strategy"] == STRATEGIES[i % 4]
        seqs = mp_sequences(d)
        k = d.metadata["n_jams"]
        strategy = d.metadata["strategy"]
        end = ["release", "push", "home"] if strategy.endswith("deep") else ["release", "home"]
        assert seqs["inserter"] == ["align", "insert"] + ["retract", "align", "insert"] * k + end
        light = strategy.startswith("light")
        assert seqs["holder"] == (["hold", "retreat"] if light else ["rest"])
        assert world.initial_mps(world.contexts(8, 0)[i]) == {v: s[0] for v, s in seqs.items()}


def test_three_demos_show_a_retry(world):
    counts = [d.metadata["n_jams"] for d in world.demonstrations(3, 0)]
    assert sorted(counts) == [0, 1, 2]


def test_graphs(demos):
    graphs = build_graphs(demos)
    ins, hol = graphs["inserter"], graphs["holder"]
    assert ins.nodes == {"align", "insert", "retract", "release", "push", "home"}
    assert ins.initial_nodes == {"align"}
    assert ins.edges == {
        ("align", "insert"),
        ("insert", "retract"),
        ("retract", "align"),
        ("insert", "release"),
        ("release", "push"),
        ("release", "home"),
        ("push", "home"),
    }
    assert ins.successors("insert") == ["release", "retract"]
    assert hol.nodes == {"hold", "retreat", "rest"}
    assert hol.initial_nodes == {"hold", "rest"}
    assert hol.edges == {("hold", "retreat")}


def test_demonstrations_are_reproducible(world, demos):
    again = world.demonstrations(3, 0)
    for a, b in zip(demos[:3], again, strict=True):
        np.testing.assert_array_equal(a.features, b.features)
        assert mp_sequences(a) == mp_sequences(b)
    other = world.demonstrations(1, 1)[0]
    assert not np.array_equal(other.features[0], demos[0].features[0])


def test_jams_are_not_decided_by_the_start(world):
    ctx = _context(world, "light_deep", n_jams=0)
    jammed = dataclasses.replace(ctx, n_jams=2)
    np.testing.assert_array_equal(world.start(ctx).features(), world.start(jammed).features())
    a, b = world.demonstrate(ctx), world.demonstrate(jammed)
    assert mp_sequences(a)["inserter"].count("retract") == 0
    assert mp_sequences(b)["inserter"].count("retract") == 2
    # the jam shows in the force only, and moves the hole estimate by a few mm
    assert a.features[:, FORCE].max() < world.force_threshold
    assert b.features[:, FORCE].max() >= world.force_threshold
    moves = np.diff(b.features[:, HOLE_X])
    moves = moves[moves != 0]
    assert len(moves) == 2
    assert np.all(np.abs(moves) > world.mouth_tolerance) and np.all(np.abs(moves) < 0.01)
    assert np.all(np.diff(a.features[:, HOLE_X]) == 0)


def test_strategy_decides_start_by_base_mass_only(world):
    for strategy in STRATEGIES:
        ctx = _context(world, strategy)
        light = world.start(ctx).features()[BASE_MASS] < 1.0
        assert world.strategy(ctx) == strategy
        assert world.initial_mps(ctx)["holder"] == ("hold" if light else "rest")
        assert light == strategy.startswith("light")


@pytest.mark.parametrize(
    "options",
    [
        {"dt": 0.0},
        {"dt": 0.2},
        {"tolerance": 0.003},
        {"shift_min": 0.001},
        {"force_threshold": 2.0},
        {"hold_force": 1.5},
        {"open_level": 0.1},
        {"home_tolerance": 0.001},
        {"start_jitter": -0.1},
        {"max_time": "long"},
        {"gain_holder": float("nan")},
    ],
)
def test_bad_options(options):
    with pytest.raises(ConfigError):
        PegWorld(**options)


def test_bad_contexts_and_mps(world):
    rng = np.random.default_rng(0)
    with pytest.raises(ConfigError):
        world.sample_context(rng, "medium", 0)
    with pytest.raises(ConfigError):
        world.sample_context(rng, "light_deep", 3)
    with pytest.raises(ConfigError):
        world.contexts(0, 0)
    run = world.start(_context(world, "light_deep"))
    with pytest.raises(UnknownMPError):
        run.advance({"holder": "hold", "inserter": "wiggle"}, 0.01)
    with pytest.raises(ConfigError):
        run.advance({"holder": "hold", "inserter": "align"}, 0.0)


def test_substeps(world):
    ctx = _context(world, "light_shallow", n_jams=1)
    one, three = world.start(ctx), world.start(ctx)
    active = {"holder": "hold", "inserter": "align"}
    for _ in range(40):
        one.advance(active, 0.03)
        for _ in range(3):
            three.advance(active, 0.01)
    np.testing.assert_allclose(one.features(), three.features(), atol=1e-9)
    assert one.state.t == pytest.approx(1.2) and three.state.t == pytest.approx(1.2)
    # a run still moves: the same time in one step of 0.05 gives the same too
    five = world.start(ctx)
    for _ in range(24):
        five.advance(active, 0.05)
    np.testing.assert_allclose(five.features(), three.features(), atol=1e-9)


def _run(world, ctx, schedule, h=0.01, limit=10.0):
    """Advance a run of ``ctx`` under ``schedule(t, x)`` until done or ``limit`` [s]."""
    run = world.start(ctx)
    t = 0.0
    active = schedule(t, run.features())
    while not run.done(active) and t < limit:
        run.advance(active, h)
        t = round(t + h, 10)
        active = schedule(t, run.features())
    return run, active


def test_inserting_before_the_hold_slides_a_light_base(world):
    tol, align_z = world.tolerance, MOUTH_Z + world.align_clearance
    inserting = []

    def early(t, x):  # align, then insert, without waiting for the holder's clamp
        aligned = abs(x[INSERTER_X] - x[HOLE_X]) < tol and abs(x[INSERTER_Z] - align_z) < tol
        if aligned and not inserting:
            inserting.append(x[CLAMP])
        return {"holder": "hold", "inserter": "insert" if inserting else "align"}

    run, active = _run(world, _context(world, "light_shallow"), early)
    assert run.done(active) and not run.complete(active)
    assert run.state.slid
    assert run.features()[CLAMP] < world.hold_force
    assert inserting[0] < world.hold_force  # the holder had not clamped yet
    # the run says what went wrong, and when
    slid_at = run.failed_at
    assert slid_at is not None and 0 < slid_at <= run.state.t
    assert run.failure() == (
        "the light base slid: the peg pressed on it while the holder's clamp force was below "
        f"{world.hold_force:g} at {slid_at:.2f} s"
    )
    # the same insertion into a heavy base does not slide: the holder rests
    inserting.clear()
    heavy = _context(world, "heavy_shallow")
    run, active = _run(world, heavy, lambda t, x: {**early(t, x), "holder": "rest"}, limit=3.0)
    assert not run.state.slid and not run.done(active)
    assert run.features()[PEG_DEPTH] > 0.1
    # not done, nothing failed: the goal conditions not met, each in words (the peg is home)
    assert run.failed_at is None and world.peg_home(run.state, heavy)
    assert run.failure() == "the gripper is not open; the inserter is not home"


def test_pressing_a_jam_breaks_the_peg(world):
    ctx = _context(world, "heavy_shallow", n_jams=1)
    policy = world.scripted_policy()

    def stubborn(t, x):  # the scripted policy, but it never retracts
        if t == 0.0:
            return policy.reset(t, x)
        active = policy.step(t, x)
        if active["inserter"] == "retract":
            active["inserter"] = policy.active["inserter"] = "insert"
        return active

    run, active = _run(world, ctx, stubborn)
    assert run.state.broken and run.done(active) and not run.complete(active)
    assert run.failure() == (
        f"the jammed peg broke (pressed for {world.break_time:g} s) at {run.failed_at:.2f} s"
    )


def test_an_incomplete_episodes_cause_carries_what_went_wrong(world):
    tol, align_z = world.tolerance, MOUTH_Z + world.align_clearance

    class Early:  # align, then insert without waiting for the holder: the base slides
        def reset(self, t, x):
            self.mp = "align"
            return {"holder": "hold", "inserter": self.mp}

        def step(self, t, x):
            aligned = abs(x[INSERTER_X] - x[HOLE_X]) < tol and abs(x[INSERTER_Z] - align_z) < tol
            self.mp = "insert" if aligned else self.mp
            return {"holder": "hold", "inserter": self.mp}

    episode = run_episode(world, Early(), _context(world, "light_shallow"))
    assert episode.outcome == "incomplete" and not episode.completed
    cause = episode.cause
    assert cause is not None and cause.reason == "unknown"  # a policy that does not explain
    assert cause.detail.startswith("the light base slid") and cause.detail.endswith(" s")
    assert cause.detail in cause.describe()


def test_misaligned_insert_jams_without_counting(world):
    ctx = _context(world, "heavy_shallow", n_jams=0)

    def hasty(t, x):  # inserts from the start, far from the align pose
        return {"holder": "rest", "inserter": "insert"}

    run, _ = _run(world, ctx, hasty, limit=0.8)
    assert run.state.jammed and run.state.attempts == 0
    assert run.features()[FORCE] >= world.force_threshold
    assert run.features()[HOLE_X] == ctx.hole_x


def test_a_peg_never_inserted_is_not_in_the_hole(world):
    run, active = _run(
        world,
        _context(world, "heavy_shallow"),
        lambda t, x: {"holder": "rest", "inserter": "align"},
        limit=1.0,
    )
    assert not run.done(active) and run.failed_at is None
    assert run.failure().split("; ")[0] == "the peg is not in the hole"
