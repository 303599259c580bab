"""The learned choice at branching nodes and the stay choice (cpmp.sequencer.branches)."""

from __future__ import annotations

import numpy as np
import pytest

from cpmp.data import Demonstration
from cpmp.sequencer import ConcurrentSequencer
from cpmp.sequencer.branches import STAY, BranchChoices, fit_softmax, stay_examples
from cpmp.sequencer.switching import Coupling, SwitchInstance
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


def test_stay_examples_are_the_other_variables_switches_before_the_end():
    demo = _demo({"u": ["a"] * 3 + ["b"] * 5, "v": ["w"] * 6 + ["x"] * 2})
    early = {"u": np.zeros(8), "v": np.linspace(0.0, 1.0, 8)}
    out = stay_examples([demo], ["u", "v"], [early], margin=0.2)
    # u switched at sample 3 while v (progress 0.43) kept w; v's own switch at 6 is no stay of
    # v, and u kept b there while near 0 progress: a stay of u.
    assert sorted(out) == [("u", "b"), ("v", "w")]
    np.testing.assert_array_equal(out[("v", "w")][0], demo.features[3])
    late = {"u": np.zeros(8), "v": np.full(8, 0.9)}
    assert ("v", "w") not in stay_examples([demo], ["u", "v"], [late], margin=0.2)


def test_joint_switches_are_learned_only_when_always_together():
    together = _demo({"u": ["a"] * 4 + ["b"] * 4, "v": ["w"] * 4 + ["x"] * 4})
    apart = _demo({"u": ["a"] * 3 + ["b"] * 5, "v": ["w"] * 5 + ["x"] * 3})
    coupling = Coupling.learn([together, together], ["u", "v"])
    assert coupling.joint[("v", "w", "x")] == {"u": ("a", "b")}
    assert coupling.joint[("u", "a", "b")] == {"v": ("w", "x")}
    assert "together with u: a -> b" in "\n".join(coupling.describe("v"))
    assert Coupling.from_dict(coupling.to_dict()).joint == coupling.joint
    mixed = Coupling.learn([together, apart], ["u", "v"])
    assert ("v", "w", "x") not in mixed.joint


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
