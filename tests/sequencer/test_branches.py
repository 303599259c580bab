"""The learned choice at branching nodes and the stay choice (cpmp.sequencer.branches)."""

from __future__ import annotations

import numpy as np
import pytest

from cpmp.data import Demonstration
from cpmp.sequencer import ConcurrentSequencer
from cpmp.sequencer.branches import (
    SOFT_POWER,
    STAY,
    BranchChoices,
    StartChoice,
    added_separation,
    entry_scales,
    fit_softmax,
    learn_choice,
    separability,
    stay_examples,
)
from cpmp.sequencer.switching import Coupling, JointPartner, SwitchInstance
from cpmp.worlds import repetition


def _cycle_coupling(rng: np.random.Generator, n: int = 6) -> Coupling:
    """``pour`` exits to ``scoop`` while x[0] (soup left) > 0.2, to ``rest`` at x[0] = 0."""
    instances = []
    for _ in range(n):
        noise = rng.uniform(-1.0, 1.0)
        instances.append(SwitchInstance("scoop", np.array([rng.uniform(0.2, 2.0), noise]), {}))
        instances.append(SwitchInstance("rest", np.array([0.0, rng.uniform(-1.0, 1.0)]), {}))
    return Coupling(instances={("ladle", "pour"): instances})


def test_softmax_fit_separates_and_sums_to_one():
    rng = np.random.default_rng(0)
    z = np.concatenate([rng.normal(-1.0, 0.3, (20, 2)), rng.normal(1.0, 0.3, (20, 2))])
    y = np.repeat([0, 1], 20)
    w, b = fit_softmax(z, y, 2)
    logits = z @ w.T + b
    assert np.mean(np.argmax(logits, axis=1) == y) == 1.0
    w2, b2 = fit_softmax(z, y, 2)
    np.testing.assert_array_equal(w, w2)
    np.testing.assert_array_equal(b, b2)


def test_branch_choice_reads_the_deciding_feature_not_the_noise():
    rng = np.random.default_rng(1)
    choices = BranchChoices.learn(_cycle_coupling(rng), np.array([2.0, 2.0]))
    choice = choices.get("ladle", "pour")
    assert choice is not None and choice.targets == ["rest", "scoop"]
    assert choice.counts == [6, 6]
    for noise in (-1.0, 0.0, 1.0):
        assert choice.choose(np.array([1.5, noise]), ["rest", "scoop"]) == "scoop"
        assert choice.choose(np.array([0.0, noise]), ["rest", "scoop"]) == "rest"
    prob = choice.probabilities(np.array([[0.0, 0.3], [1.0, 0.3]]))
    np.testing.assert_allclose(prob.sum(axis=-1), 1.0)
    # A successor not demonstrated in the current context is not chosen.
    assert choice.choose(np.array([0.0, 0.0]), ["scoop"]) == "scoop"
    assert choice.choose(np.array([0.0, 0.0]), ["elsewhere"]) is None
    assert "weighs most: x[0]" in choice.describe()


def test_no_choice_without_a_branch_or_a_stay():
    one_way = Coupling(instances={("bowl", "hold"): [SwitchInstance("serve", np.zeros(2), {})] * 3})
    assert BranchChoices.learn(one_way, np.ones(2)).choices == {}
    stays = {("bowl", "hold"): [np.array([1.0, 0.0]), np.array([2.0, 0.0])]}
    choices = BranchChoices.learn(
        Coupling(
            instances={
                ("bowl", "hold"): [
                    SwitchInstance("serve", np.array([0.0, v]), {}) for v in (0.1, -0.1)
                ]
            }
        ),
        np.ones(2),
        stays,
    )
    choice = choices.get("bowl", "hold")
    assert choice is not None and choice.targets == [STAY, "serve"]
    assert choice.choose(np.array([1.5, 0.0]), ["serve"]) == STAY
    assert choice.choose(np.array([0.0, 0.0]), ["serve"]) == "serve"


def test_a_stay_choice_reads_a_combination_and_weighs_features_softly():
    # peg's holder: it goes when the peg's depth (x[0]) reaches the hole's (x[1]); it stayed
    # with the peg half way in a deep hole and with the peg out; x[2] is jitter. Neither depth
    # separates staying from going on its own.
    rng = np.random.default_rng(0)
    go = [np.array([h, h, rng.uniform(-1, 1)]) for h in (0.13, 0.16, 0.19, 0.33, 0.38, 0.43)]
    stays = [np.array([h / 2, h, rng.uniform(-1, 1)]) for h in (0.31, 0.34, 0.37, 0.40, 0.43)]
    stays += [np.array([0.0, h, rng.uniform(-1, 1)]) for h in (0.14, 0.18, 0.32, 0.41)]
    coupling = Coupling(
        instances={("holder", "hold"): [SwitchInstance("retreat", x, {}) for x in go]}
    )
    feature_range = np.array([0.45, 0.32, 2.0])
    choices = BranchChoices.learn(coupling, feature_range, {("holder", "hold"): stays})
    choice = choices.get("holder", "hold")
    assert choice is not None and choice.targets == [STAY, "retreat"]
    assert choice.choose(np.array([0.18, 0.36, 0.0]), ["retreat"]) == STAY
    assert choice.choose(np.array([0.21, 0.42, 0.5]), ["retreat"]) == STAY
    assert choice.choose(np.array([0.36, 0.36, 0.0]), ["retreat"]) == "retreat"
    assert choice.choose(np.array([0.15, 0.15, -0.5]), ["retreat"]) == "retreat"
    # the stay choice weighs by the square root of separability or of the separation a feature
    # adds to those that separate better, whichever is larger; a branch choice by separability
    z = np.stack(go + stays) / feature_range
    y = np.array([1] * len(go) + [0] * len(stays))
    weight = np.maximum(separability(z, y, 2), added_separation(z, y, 2))
    np.testing.assert_allclose(choice.model.scale, weight**SOFT_POWER / feature_range)
    assert weight[1] > 2 * separability(z, y, 2)[1]  # the hole's depth, read with the peg's
    # an ambient feature (x[2] drifting alike under every MP) is left out of the stay choice
    drifting = Coupling(instances=coupling.instances, ambient=np.array([False, False, True]))
    without = BranchChoices.learn(drifting, feature_range, {("holder", "hold"): stays})
    scale = without.get("holder", "hold").model.scale
    assert scale[2] == 0.0 and scale[0] > 0.0 and scale[1] > 0.0
    assert without.get("holder", "hold").choose(np.array([0.18, 0.36, 0.9]), ["retreat"]) == STAY
    cycle_coupling = _cycle_coupling(np.random.default_rng(1))
    # ... and out of a branch choice among successors
    drifting_cycle = Coupling(instances=cycle_coupling.instances, ambient=np.array([False, True]))
    branch = BranchChoices.learn(cycle_coupling, np.array([2.0, 2.0]))
    assert branch.get("ladle", "pour").model.scale[1] > 0.0
    assert (
        BranchChoices.learn(drifting_cycle, np.array([2.0, 2.0]))
        .get("ladle", "pour")
        .model.scale[1]
        == 0.0
    )
    cycle = cycle_coupling.instances[("ladle", "pour")]
    zc = np.stack([inst.state for inst in cycle]) / 2.0
    yc = np.array([["rest", "scoop"].index(inst.target) for inst in cycle])
    np.testing.assert_allclose(
        branch.get("ladle", "pour").model.scale, separability(zc, yc, 2) / 2.0
    )


def test_added_separation_keeps_a_partner_and_not_jitter_or_a_copy():
    # go where x[0] (the peg's depth) reaches x[1] (the hole's), stay short of it; x[2] is
    # jitter, x[3] a copy of x[0], x[4] constant.
    rng = np.random.default_rng(3)
    hole = rng.uniform(0.1, 0.45, 40)
    going = np.arange(40) % 2 == 0
    peg = np.where(going, hole, hole * rng.uniform(0.0, 0.6, 40))
    z = np.stack([peg, hole, rng.uniform(-1, 1, 40), peg, np.full(40, 0.3)], axis=1)
    y = going.astype(int)
    alone = separability(z, y, 2)
    added = added_separation(z, y, 2)
    assert added[0] == 1.0 and alone[0] == 1.0  # the best alone
    assert alone[1] < 0.3 and added[1] == 1.0  # the hole's depth: only with the peg's
    assert max(added[2], added[3]) < 0.3 and added[4] == 0.0  # small beside the partner's 1
    # a stay choice among several successors adds to telling staying from going only
    target = np.where(going, np.arange(40) % 4 // 2 + 1, 0)  # stay 0, two successors 1 and 2
    model = learn_choice(z, target, 3, np.ones(5), stay=0)
    expected = np.maximum(separability(z, target, 3), added)
    np.testing.assert_allclose(model.scale, expected)
    # every feature constant: nothing separates
    assert not added_separation(np.ones((4, 2)), np.array([0, 1, 0, 1]), 2).any()


def test_choices_survive_to_dict():
    choices = BranchChoices.learn(_cycle_coupling(np.random.default_rng(2)), np.array([2.0, 2.0]))
    back = BranchChoices.from_dict(choices.to_dict())
    x = np.array([[0.1, 0.5], [1.2, -0.5]])
    np.testing.assert_allclose(
        back.get("ladle", "pour").probabilities(x), choices.get("ladle", "pour").probabilities(x)
    )


def _demo(labels: dict[str, list[str]]) -> Demonstration:
    n = len(next(iter(labels.values())))
    x = np.stack([np.arange(n, dtype=float), np.zeros(n)], axis=1)
    return Demonstration(np.arange(n) * 0.1, x, labels, ["a", "b"])


def test_stay_examples_are_the_other_variables_switches_a_variable_stays_through():
    # u switches at 2 and 4, v at 6: v stayed in w through u's switch at 2 (u switched again
    # before v did), but at u's switch at 4 v was waiting (its own switch came next). u kept b
    # through v's switch at 6 (the end of the data comes first: no stay).
    demo = _demo({"u": ["a"] * 2 + ["b"] * 2 + ["c"] * 4, "v": ["w"] * 6 + ["x"] * 2})
    out = stay_examples([demo], ["u", "v"])
    assert sorted(out) == [("v", "w")]
    assert len(out[("v", "w")]) == 1
    np.testing.assert_array_equal(out[("v", "w")][0], demo.features[2])


def test_a_stay_through_the_last_part_of_a_node_counts_and_a_shared_moment_too():
    # v's own switch in the same sample as u's next one (the holder's hold -> retreat as the
    # push ends) still makes u's earlier switch a stay of v, however far v is through w.
    demo = _demo({"u": ["a"] * 5 + ["b"] * 2 + ["c"], "v": ["w"] * 7 + ["x"]})
    out = stay_examples([demo], ["u", "v"])
    assert list(out) == [("v", "w")]
    np.testing.assert_array_equal(out[("v", "w")][0], demo.features[5])
    # a switch of v in the same sample as u's is no stay of v
    together = _demo({"u": ["a"] * 4 + ["b"] * 4, "v": ["w"] * 4 + ["x"] * 4})
    assert stay_examples([together], ["u", "v"]) == {}
    # one variable: no other variable's switch, no stay
    assert stay_examples([together], ["u"]) == {}


def test_joint_switches_are_learned_only_when_always_together():
    together = _demo({"u": ["a"] * 4 + ["b"] * 4, "v": ["w"] * 4 + ["x"] * 4})
    apart = _demo({"u": ["a"] * 3 + ["b"] * 5, "v": ["w"] * 5 + ["x"] * 3})
    coupling = Coupling.learn([together, together], ["u", "v"])
    assert coupling.joint[("v", "w", "x")] == {"u": JointPartner(("a",), "b")}
    assert coupling.joint[("u", "a", "b")] == {"v": JointPartner(("w",), "x")}
    assert "together with u: a -> b" in "\n".join(coupling.describe("v"))
    assert Coupling.from_dict(coupling.to_dict()).joint == coupling.joint
    mixed = Coupling.learn([together, apart], ["u", "v"])
    assert ("v", "w", "x") not in mixed.joint


def test_a_joint_switch_is_keyed_by_the_mp_the_other_variable_switches_into():
    # v: w -> x always came with u switching into b, once from a and once from c
    from_a = _demo({"u": ["a"] * 4 + ["b"] * 4, "v": ["w"] * 4 + ["x"] * 4})
    from_c = _demo({"u": ["c"] * 4 + ["b"] * 4, "v": ["w"] * 4 + ["x"] * 4})
    coupling = Coupling.learn([from_a, from_c], ["u", "v"])
    assert coupling.joint[("v", "w", "x")] == {"u": JointPartner(("a", "c"), "b")}
    assert "together with u: a or c -> b" in "\n".join(coupling.describe("v"))
    assert Coupling.from_dict(coupling.to_dict()).joint == coupling.joint
    # into different MPs: not joint
    into_d = _demo({"u": ["c"] * 4 + ["d"] * 4, "v": ["w"] * 4 + ["x"] * 4})
    assert ("v", "w", "x") not in Coupling.learn([from_a, into_d], ["u", "v"]).joint


def _constant_progress(values: dict[tuple[str, str], float]):
    """φ of the nodes ``values`` (in that order), the same for every state."""
    index = {key: k for k, key in enumerate(values)}
    row = np.array(list(values.values()))
    return (lambda x: np.tile(row, (len(x), 1))), index


@pytest.mark.parametrize(
    ("phi_u", "carried"),
    [
        ((0.5, 0.2), True),  # u's p 0.4: below v's 0.9 and below the threshold
        ((0.95, 0.05), False),  # u's p 0.9025: as high as v's, its own p times the pair
        ((0.8, 0.1), False),  # u's p 0.72: below v's, but above the threshold: it can fire
    ],
)
def test_a_joint_partner_is_carried_only_when_its_p_lags_at_every_instance(phi_u, carried):
    together = _demo({"u": ["a"] * 4 + ["b"] * 4, "v": ["w"] * 4 + ["x"] * 4})
    coupling = Coupling.learn([together, together], ["u", "v"])
    phi, index = _constant_progress(
        {("u", "a"): phi_u[0], ("u", "b"): phi_u[1], ("v", "w"): 0.9, ("v", "x"): 0.0}
    )
    out = coupling.with_carried(phi, index, threshold=0.65)
    assert out.joint[("v", "w", "x")]["u"].carried is carried
    assert out.joint[("u", "a", "b")]["v"].carried is False  # v's p is never the lower one
    assert (
        out.contexts == coupling.contexts and coupling.joint[("v", "w", "x")]["u"].carried is False
    )
    back = Coupling.from_dict(out.to_dict())
    assert back.joint == out.joint
    assert ("(taken along)" in "\n".join(out.describe("v"))) is carried


def test_an_entry_scale_counts_in_the_carried_test():
    together = _demo({"u": ["a"] * 4 + ["b"] * 4, "v": ["w"] * 4 + ["x"] * 4})
    coupling = Coupling.learn([together], ["u", "v"])
    phi, index = _constant_progress(
        {("u", "a"): 0.9, ("u", "b"): 0.6, ("v", "w"): 0.9, ("v", "x"): 0.0}
    )
    # u's p 0.36 lags v's 0.9; with u's entry scaled x2 (a factor the fit found) it is 0.72,
    # above the threshold
    assert coupling.with_carried(phi, index, 0.65).joint[("v", "w", "x")]["u"].carried
    scaled = coupling.with_carried(phi, index, 0.65, {("u", "a", "b"): 2.0})
    assert not scaled.joint[("v", "w", "x")]["u"].carried


@pytest.fixture(scope="module")
def repetition_fit():
    """A sequencer fitted on 6 repetition-world demonstrations (2 per strategy)."""
    return ConcurrentSequencer.fit(repetition.make_demonstrations(6, seed=0), seed=0, logger=None)


@pytest.mark.slow
def test_repetition_is_read_from_the_state(repetition_fit):
    seq = repetition_fit
    text = seq.describe()
    assert "pour -> rest | scoop chosen from the state" in text
    assert "hold -> (stay) | serve" in text
    assert "together with ladle: pour -> rest" in text
    learned = repetition.evaluate(seq, n_episodes=12, seed=100)
    paper = repetition.evaluate(seq.with_config(branch="none"), n_episodes=12, seed=100)
    repeating = ("twice", "thrice")
    done = sum(learned["by_strategy"][s]["complete"] for s in repeating)
    assert done >= 7  # of 8 repeating episodes
    assert done > sum(paper["by_strategy"][s]["complete"] for s in repeating)


def test_checkpoint_keeps_the_choices(repetition_fit, tmp_path):
    seq = repetition_fit
    back = ConcurrentSequencer.load(seq.save(tmp_path / "rep.pt"))

    def learned(text: str) -> list[str]:
        return [line for line in text.splitlines() if "chosen" in line or "together" in line]

    assert learned(back.describe()) == learned(seq.describe()) != []
    assert back.config.branch == "learned"
    x = np.array([1.0, 0.5, 0.0, 1.0, 0.5, 1.0, 0.4])
    for key, choice in seq.branches.choices.items():
        np.testing.assert_allclose(
            back.branches.choices[key].probabilities(x), choice.probabilities(x)
        )
    assert seq.with_config(branch="none").branches.choices == {}


def _start_demo(name: str, first: np.ndarray, starts: tuple[str, str]) -> Demonstration:
    """Two samples; ``arm`` and ``gripper`` start with ``starts``, then move on."""
    x = np.stack([first, first + 0.5])
    labels = {"arm": np.array([starts[0], "b"]), "gripper": np.array([starts[1], "c"])}
    return Demonstration(
        np.array([0.0, 0.01]), x, labels, ["switch", "home", "light"], f"demo_{name}"
    )


def test_start_choice_reads_the_feature_that_separates_the_starts_not_the_jitter():
    rng = np.random.default_rng(3)
    demos = []
    for i in range(6):
        shut = i % 2 == 0  # x[0]: 0 (shut) or 1 (open) decides; x[1], x[2] jitter widely
        first = np.array([0.0 if shut else 1.0, rng.uniform(-2, 2), rng.uniform(-2, 2)])
        demos.append(_start_demo(f"d{i}", first, ("pull", "wait") if shut else ("hold", "wait")))
    choice = StartChoice.learn(demos, ["arm", "gripper"], np.array([1.0, 4.0, 4.0]))
    assert choice.combinations == [
        {"arm": "hold", "gripper": "wait"},
        {"arm": "pull", "gripper": "wait"},
    ]
    assert choice.counts == [3, 3]
    # the jitter of every demonstration with the other start does not move the choice
    for demo in demos:
        for shut in (True, False):
            x = demo.features[0].copy()
            x[0] = 0.0 if shut else 1.0
            best = choice.combinations[int(np.argmax(choice.probabilities(x)))]
            assert best["arm"] == ("pull" if shut else "hold")
    assert "weighs most: switch" in choice.describe(["switch", "home", "light"])
    back = StartChoice.from_dict(choice.to_dict())
    x = np.array([[0.2, 1.0, -1.0], [0.9, -1.5, 0.3]])
    np.testing.assert_allclose(back.probabilities(x), choice.probabilities(x))


def test_the_start_leaves_out_an_ambient_feature_that_separates_the_starts_by_chance():
    # x[0] decides (0 / 0.4 shut, 1 open); the light x[2] drifts and, by chance, was low in
    # both shut demonstrations: alone it would say "shut" at every low light.
    demos = [
        _start_demo("a", np.array([0.0, 0.1, 0.2]), ("pull", "wait")),
        _start_demo("b", np.array([0.4, -0.1, 0.22]), ("pull", "wait")),
        _start_demo("c", np.array([1.0, 0.0, 1.2]), ("hold", "wait")),
    ]
    feature_range = np.array([1.0, 1.0, 1.5])
    open_in_low_light, shut_in_bright_light = np.array([1.0, 0.0, 0.21]), np.array([0.0, 0.0, 1.2])
    misled = StartChoice.learn(demos, ["arm", "gripper"], feature_range)
    assert misled.combinations[int(np.argmax(misled.probabilities(open_in_low_light)))] == {
        "arm": "pull",
        "gripper": "wait",
    }
    choice = StartChoice.learn(
        demos, ["arm", "gripper"], feature_range, np.array([False, False, True])
    )
    assert choice.model is not None and choice.model.scale[2] == 0.0
    for x, arm in ((open_in_low_light, "hold"), (shut_in_bright_light, "pull")):
        assert choice.combinations[int(np.argmax(choice.probabilities(x)))]["arm"] == arm


def test_one_demonstrated_start_needs_no_choice():
    demos = [_start_demo(f"d{i}", np.array([i, 0.0, 1.0]), ("pull", "wait")) for i in range(3)]
    choice = StartChoice.learn(demos, ["arm", "gripper"], np.ones(3))
    assert choice.model is None and choice.counts == [3]
    np.testing.assert_array_equal(choice.probabilities(np.zeros((2, 3))), np.ones((2, 1)))
    assert "the one demonstrated start" in choice.describe()
    assert StartChoice.from_dict(choice.to_dict()).combinations == choice.combinations


def test_entry_scales_only_where_the_demonstrated_entry_reads_done():
    key_loop, key_fine, key_exit = ("arm", "retract", "align"), ("arm", "a", "b"), ("arm", "c", "d")
    exit_phi = {
        key_loop: np.array([0.95, 0.96, 0.94]),
        key_fine: np.array([0.95, 0.9, 0.92]),
        key_exit: np.array([0.3, 0.4, 0.35]),  # low exit, fine entry: not the entry's doing
    }
    entry = {
        key_loop: np.array([0.2, 0.15, 0.4]),  # re-entered: the target reads "done"
        key_fine: np.array([0.9, 0.95, 0.93]),
        key_exit: np.array([0.9, 0.95, 0.93]),
    }
    scales = entry_scales(exit_phi, entry, 0.65)
    assert set(scales) == {key_loop}
    assert scales[key_loop] == pytest.approx(1.0 / 0.2)
    # an entry of about nothing is scaled by at most 20
    tiny = entry_scales({key_loop: np.ones(3)}, {key_loop: np.full(3, 1e-4)}, 0.65)
    assert tiny[key_loop] == pytest.approx(20.0)
    back = BranchChoices.from_dict([], None, BranchChoices({}, None, scales).entry_rows())
    assert back.entry_scale == scales


@pytest.mark.slow
def test_a_re_entered_node_fires_with_its_entry_scaled():
    """The peg world's re-align starts where the first align ended (align's φ near 1 there):
    the fit scales the entry of ``retract -> align``, and in closed loop a jam re-aligns by
    itself (stall recovery off: it may also fire a re-align, a second later)."""
    from cpmp.worlds.protocol import run_episodes
    from cpmp.worlds.registry import make_world

    world = make_world("peg", {})
    seq = ConcurrentSequencer.fit(world.demonstrations(9, 0), seed=0, logger=None)
    scales = seq.branches.entry_scale
    assert scales.get(("inserter", "retract", "align"), 1.0) > 1.0
    assert all(target != "retract" for _, _, target in scales)  # the first tries are untouched
    plain = seq._with_branches(BranchChoices(seq.branches.choices, seq.branches.start))
    jammed = [c for c in world.contexts(12, 1000) if c.n_jams > 0][:4]
    assert jammed

    def realigned(policy) -> list[bool]:
        """Per episode that retracted after a jam, whether the arm aligned again."""
        runs = run_episodes(world, policy, jammed)
        tails = [r.sequences["inserter"] for r in runs if "retract" in r.sequences["inserter"]]
        return [mps[mps.index("retract") :][1:2] == ["align"] for mps in tails]

    with_scale = realigned(seq.with_config(recovery=False))
    without = realigned(plain.with_config(recovery=False))
    assert len(with_scale) >= 2 and all(with_scale)
    assert len(without) >= 2 and not any(without)
