"""The world protocol and registry: every registered world behaves as one interface says."""

from __future__ import annotations

import numpy as np
import pytest

from cpmp.data.demonstration import mp_sequences
from cpmp.errors import ConfigError
from cpmp.graph import build_graphs
from cpmp.sequencer import ConcurrentSequencer
from cpmp.worlds import relay, repetition, two_point
from cpmp.worlds.protocol import World, evaluate, run_episodes, substeps
from cpmp.worlds.registry import WORLDS, entry, make_world, members, world_names
from cpmp.worlds.relay import varied

SCRIPTED_EPISODES = 100
"""Episodes of each world's feature-only scripted policy (the fairness proof: >= 99 %)."""
FAMILY_MEMBERS = 5
"""Members of a family run here (the family's own tests run more)."""


def _every_world() -> list[tuple[str, int]]:
    """(name, member) of every registered world: single worlds once, a family's first few."""
    return [
        (name, i) for name in WORLDS for i in range(FAMILY_MEMBERS if WORLDS[name].family else 1)
    ]


def _world(name: str, member: int) -> World:
    return make_world(name, {"task": member} if entry(name).family else None)


@pytest.mark.parametrize(("name", "member"), _every_world())
def test_every_world_implements_the_protocol(name: str, member: int) -> None:
    world = _world(name, member)
    assert isinstance(world, World)
    assert world.name == name
    demos = world.demonstrations(3, 0)
    assert [d.name for d in demos] == ["demo_0", "demo_1", "demo_2"]
    assert all(list(d.feature_names) == list(world.feature_names) for d in demos)
    assert all(sorted(d.variables) == sorted(world.variables) for d in demos)
    contexts = world.contexts(4, 1000)
    assert all(world.strategy(c) in world.strategies for c in contexts)
    run = world.start(contexts[0])
    assert run.features().shape == (len(world.feature_names),)
    assert not run.done(world.initial_mps(contexts[0]))


@pytest.mark.parametrize(("name", "member"), _every_world())
def test_same_seed_same_demonstrations(name: str, member: int) -> None:
    a, b = _world(name, member).demonstrations(2, 3), _world(name, member).demonstrations(2, 3)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x.features, y.features)
        assert mp_sequences(x) == mp_sequences(y)
    other = _world(name, member).demonstrations(2, 4)
    assert not np.array_equal(a[0].features[0], other[0].features[0])


@pytest.mark.parametrize(("name", "member"), _every_world())
def test_scripted_policy_reading_only_features_completes(name: str, member: int) -> None:
    """The proof that a world is fair: its switches can be decided from its features."""
    world = _world(name, member)
    result = evaluate(world, world.scripted_policy(), SCRIPTED_EPISODES, seed=1000)
    assert result.complete >= 0.99 * SCRIPTED_EPISODES, result.counts


@pytest.mark.parametrize(("name", "member"), _every_world())
def test_demonstrator_runs_are_complete(name: str, member: int) -> None:
    """Replaying the demonstrator's own MPs on a context is scored complete.

    A demonstrator decides at sample ``i`` and the world moves under that decision, which is
    the label of sample ``i + 1``.
    """
    world = _world(name, member)
    for context in world.contexts(3, 1000):
        demo = world.demonstrate(context)
        want = mp_sequences(demo)
        labels = {v: demo.labels[v] for v in world.variables}
        run = world.start(context)
        for i in range(demo.n_samples - 1):
            run.advance({v: str(labels[v][i + 1]) for v in world.variables}, world.dt)
        last = {v: str(labels[v][-1]) for v in world.variables}
        assert run.complete(last)
        assert world.score(context, world.initial_mps(context), want, True) == "complete"


@pytest.mark.parametrize("name", world_names(family=False))
def test_a_longer_step_is_equal_sub_steps(name: str) -> None:
    world = make_world(name)
    context = world.contexts(1, 5)[0]
    active = world.initial_mps(context)
    one, three = world.start(context), world.start(context)
    one.advance(active, 3 * world.dt)
    for _ in range(3):
        three.advance(active, world.dt)
    np.testing.assert_allclose(one.features(), three.features(), rtol=0, atol=1e-12)


def test_substeps_split_a_step_into_equal_parts_no_longer_than_dt() -> None:
    assert substeps(0.01, 0.01) == (1, 0.01)
    n, h = substeps(0.025, 0.01)
    assert n == 3 and h == pytest.approx(0.025 / 3)
    for bad in (0.0, -0.01, float("nan")):
        with pytest.raises(ConfigError, match="positive time step"):
            substeps(bad, 0.01)


def test_the_registry_names_its_worlds_and_refuses_unknown_ones() -> None:
    assert {"two_point", "relay", "paced_relay", "repetition"} <= set(world_names())
    with pytest.raises(ConfigError, match="unknown world 'nope'; registered: two_point"):
        make_world("nope")
    with pytest.raises(ConfigError, match="bad task option for the relay world"):
        make_world("relay", {"no_such_option": 1})
    with pytest.raises(ConfigError, match="paced_relay world's demo"):
        make_world("paced_relay", {"demo": 3})
    with pytest.raises(ConfigError, match="bad task option for the procedural world"):
        make_world("procedural", {"bogus": 1})
    assert len(members("relay", 7)) == 1
    family = members("procedural", 3)
    assert [w.spec.seed for w in family] == [0, 1, 2]  # member i is the generator's task i


@pytest.mark.parametrize(
    ("name", "legacy"),
    [
        ("two_point", lambda s: two_point.evaluate(s, None, 12, 1000)),
        ("relay", lambda s: relay.evaluate(s, None, 12, 1000)),
        ("repetition", lambda s: repetition.evaluate(s, None, 12, 1000)),
    ],
)
def test_protocol_loop_gives_each_worlds_own_numbers(name: str, legacy) -> None:
    """The one closed loop reproduces every world's own evaluation, episode by episode."""
    world = make_world(name)
    seq = ConcurrentSequencer.fit(world.demonstrations(3, 0), "klr", seed=0, logger=None)
    ours, theirs = evaluate(world, seq, 12, 1000), legacy(seq)
    assert ours.counts == {k: theirs[k] for k in ours.counts}
    if "per_episode" in theirs:
        assert [e.sequences for e in ours.episodes] == [
            r["sequences"] for r in theirs["per_episode"]
        ]


def test_paced_relay_is_the_comparisons_paced_world() -> None:
    world = make_world("paced_relay")
    seq = ConcurrentSequencer.fit(world.demonstrations(3, 0), "klr", seed=0, logger=None)
    ours = [e.outcome for e in evaluate(world, seq, 8, 1000).episodes]
    assert ours == [s.outcome for s in varied.evaluate(seq, None, 8, 1000)]


def test_batched_episodes_equal_one_at_a_time(one_at_a_time) -> None:
    world = make_world("relay")
    seq = ConcurrentSequencer.fit(world.demonstrations(3, 0), "klr", seed=0, logger=None)
    contexts = world.contexts(6, 11)
    batched = run_episodes(world, seq, contexts)
    single = run_episodes(world, one_at_a_time(seq), contexts)
    assert [(e.outcome, e.sequences, e.time) for e in batched] == [
        (e.outcome, e.sequences, e.time) for e in single
    ]


@pytest.mark.parametrize(("name", "member"), _every_world())
def test_demonstrations_build_a_graph_per_variable(name: str, member: int) -> None:
    world = _world(name, member)
    graphs = build_graphs(world.demonstrations(len(world.strategies), 0))
    assert sorted(graphs) == sorted(world.variables)
    assert all(g.initial_nodes for g in graphs.values())
