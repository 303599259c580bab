"""The procedural world (cpmp.worlds.procedural): generator, dynamics, demonstrator, policy."""

from collections import Counter

import numpy as np
import pytest

from cpmp.errors import ConfigError, UnknownMPError
from cpmp.graph import build_graphs
from cpmp.worlds.procedural import ProceduralWorld, generate
from cpmp.worlds.procedural.generator import FAIL_LEVEL, STRATEGIES, TOLERANCE
from cpmp.worlds.protocol import World, WorldRun, evaluate

N_TASKS = 100


def _loop_task(hold: bool = True) -> ProceduralWorld:
    """The first member with a loop (and a variable holding through it when ``hold``)."""
    for i in range(N_TASKS):
        loop = generate(i).loop
        if loop is not None and (loop.hold_variable is not None) == hold:
            return ProceduralWorld(task=i)
    raise AssertionError("no such task")


def test_a_seed_gives_one_task_and_its_demonstrations():
    assert generate(7) == generate(7)
    assert len({generate(i) for i in range(N_TASKS)}) == N_TASKS
    one, two = ProceduralWorld(task=7), ProceduralWorld(task=7)
    for a, b in zip(one.demonstrations(3, 0), two.demonstrations(3, 0), strict=True):
        assert a.name == b.name and a.metadata == b.metadata
        np.testing.assert_array_equal(a.features, b.features)
        for v in one.variables:
            np.testing.assert_array_equal(a.labels[v], b.labels[v])
    other = ProceduralWorld(task=8).demonstrations(1, 0)[0]
    assert other.feature_names != one.feature_names or not np.array_equal(
        other.features[:5], one.demonstrations(1, 0)[0].features[:5]
    )


@pytest.mark.slow
def test_the_scripted_policy_completes_every_episode_of_100_tasks_of_every_kind():
    kinds: Counter[str] = Counter()
    for i in range(N_TASKS):
        world = ProceduralWorld(task=i)
        spec = world.spec
        assert isinstance(world, World)
        result = evaluate(world, world.scripted_policy(), 10, seed=1)
        assert result.counts["complete"] == 10, (i, result.counts, world.describe())
        for episode, context in zip(result.episodes, world.contexts(10, 1), strict=True):
            assert episode.sequences == spec.sequences(context.strategy, context.failures)
        kinds[f"{len(spec.variables)} variables"] += 1
        kinds[f"{spec.n_distractors} distractors"] += 1
        kinds[f"branch at the {spec.branch.kind}"] += 1
        kinds.update(f"{len(v.mps)} MPs" for v in spec.variables)
        kinds.update(f"{v.dim}-D" for v in spec.variables)
        kinds.update(f"{w.kind} wait" for w in spec.waits)
        kinds["loop"] += spec.loop is not None
        d = len(spec.feature_names)
        assert d == sum(v.dim for v in spec.variables) + (spec.loop is not None) + 1 + (
            spec.n_distractors
        )
    wanted = [
        "2 variables", "3 variables", "3 MPs", "4 MPs", "5 MPs", "1-D", "2-D",
        "1 distractors", "2 distractors", "3 distractors", "branch at the start",
        "branch at the end", "loop", "loop wait", "hold wait", "final wait",
    ]  # fmt: skip
    assert all(kinds[k] >= 10 for k in wanted), kinds
    assert 30 <= kinds["loop"] <= 80, kinds


def test_demonstrations_build_the_graphs_of_the_spec():
    for i in range(25):
        world = ProceduralWorld(task=i)
        spec = world.spec
        demos = world.demonstrations(6, 0)
        assert [d.name for d in demos] == [f"demo_{j}" for j in range(6)]
        assert [d.metadata["strategy"] for d in demos] == list("ababab")
        assert all(d.metadata["reached_goal"] for d in demos)
        for d in demos:
            assert d.features.min() >= 0.0 and d.features.max() <= 2.0
        graphs = build_graphs(demos, world.variables)
        starts = {s: spec.initial_mps(s) for s in STRATEGIES}
        for v in spec.variables:
            assert graphs[v.name].edges == v.edges, (i, v.name)
            assert graphs[v.name].initial_nodes == {starts[s][v.name] for s in STRATEGIES}
        if spec.loop is not None:  # three demos already run the loop
            assert [d.metadata["failures"] for d in demos[:3]] == [1, 2, 0]
            lp = spec.loop
            three = build_graphs(demos[:3], world.variables)[lp.variable].edges
            assert {(lp.try_mp, lp.undo_mp), (lp.undo_mp, lp.try_mp)} <= three


def test_every_demonstrated_switch_is_decided_by_the_features():
    """The feature-only policy, fed a demonstration's features, gives its labels."""
    for i in range(20):
        world = ProceduralWorld(task=i)
        for demo in world.demonstrations(3, 2):
            policy = world.scripted_policy()
            labels = [
                dict(zip(demo.labels, row, strict=True))
                for row in zip(*demo.labels.values(), strict=True)
            ]
            assert policy.reset(0.0, demo.features[0]) == labels[0]
            for j in range(1, len(demo.time) - 1):
                assert policy.step(demo.time[j], demo.features[j]) == labels[j + 1], (i, j)


def test_a_failed_try_jams_raises_the_force_and_the_holder_waits():
    world = _loop_task(hold=True)
    lp = world.spec.loop
    force = world.feature_names.index(f"{lp.variable}_force")
    demos = world.demonstrations(3, 0)
    for demo in demos:
        seq = demo.labels[lp.variable]
        tries = np.flatnonzero((seq[1:] == lp.try_mp) & (seq[:-1] != lp.try_mp)) + 1
        undos = np.flatnonzero((seq[1:] == lp.undo_mp) & (seq[:-1] != lp.undo_mp)) + 1
        assert len(undos) == demo.metadata["failures"] == len(tries) - 1
        for u in undos:  # the switch to undo comes when the force crossed the level
            assert demo.features[u - 1, force] > FAIL_LEVEL
        if not len(undos):
            assert demo.features[:, force].max() == 0.0
        holder = demo.labels[lp.hold_variable]
        last_try = np.flatnonzero(seq == lp.try_mp)[-1]
        assert (holder[tries[0] : last_try + 1] == f"{lp.hold_variable}_hold").all()


def test_advancing_by_three_ticks_equals_three_single_ticks():
    world = _loop_task()
    context = world.contexts(2, 0)[1]  # two failures
    coarse, fine = world.start(context), world.start(context)
    assert isinstance(coarse, WorldRun)
    policy = world.scripted_policy()
    active = policy.reset(0.0, coarse.features())
    for k in range(300):
        coarse.advance(active, 0.03)
        for _ in range(3):
            fine.advance(active, 0.01)
        np.testing.assert_allclose(coarse.features(), fine.features(), rtol=0, atol=1e-12)
        active = policy.step(0.03 * (k + 1), coarse.features())
    assert coarse.failed == fine.failed == 2


def test_the_run_checks_its_mps_and_the_goal():
    world = ProceduralWorld(task=3)
    context = world.contexts(1, 0)[0]
    run = world.start(context)
    active = world.initial_mps(context)
    assert not run.done(active) and not run.complete(active)
    v = world.variables[0]
    with pytest.raises(UnknownMPError, match="no MP"):
        run.advance({**active, v: "dance"}, 0.01)
    with pytest.raises(UnknownMPError):
        run.advance({k: m for k, m in active.items() if k != v}, 0.01)
    with pytest.raises(ConfigError, match="positive"):
        run.advance(active, 0.0)
    with pytest.raises(UnknownMPError):
        world.spec.variable(v).mp("dance")
    demo = world.demonstrate(context)
    last = {u: demo.labels[u][-1] for u in world.variables}
    assert last == world.spec.final_mps(context.strategy)
    x = demo.features[-1]
    for var in world.spec.variables:
        i = world.feature_names.index(f"{var.name}_x")
        goal = np.asarray(var.mp(last[var.name]).goal)
        assert np.linalg.norm(x[i : i + var.dim] - goal) < TOLERANCE


@pytest.mark.parametrize(
    "options",
    [
        {"task": -1},
        {"task": 1.5},
        {"task": True},
        {"goal_jitter": 0.1},
        {"start_jitter": -0.01},
        {"max_time": 1.0},
        {"max_time": float("nan")},
    ],
)
def test_bad_options_are_refused(options):
    with pytest.raises(ConfigError):
        ProceduralWorld(**options)


def test_bad_counts_seeds_and_strategies_are_refused():
    world = ProceduralWorld(task=1)
    with pytest.raises(ConfigError):
        world.contexts(0, 0)
    with pytest.raises(ConfigError, match="seed"):
        world.contexts(2, -1)
    with pytest.raises(ConfigError, match="strategy"):
        world.spec.sequences("c", 0)


def test_describe_names_the_structure():
    world = _loop_task()
    text = "\n".join(world.describe())
    assert "loop" in text and "wait (hold)" in text and world.spec.loop.try_mp in text
    assert all(v in text for v in world.variables) and "distractor" in text
