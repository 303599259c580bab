"""The start decision a sequencer keeps (``start_decision``): the starts it weighed, each with
its score, and the one it took — what a recording shows of a wrong start."""

from __future__ import annotations

import numpy as np
import pytest

from cpmp.sequencer import PAPER_OPTIONS


def test_learned_rule_weighs_every_demonstrated_start_by_its_probability(fitted_klr, test_demos):
    assert fitted_klr.config.start_rule == "learned"
    start = fitted_klr.branches.start
    assert start is not None and len(start.combinations) >= 2
    assert sorted(map(str, start.combinations)) == sorted(map(str, fitted_klr.initial_combinations))
    for demo in test_demos:
        active = fitted_klr.reset(0.0, demo.features[0])
        decision = fitted_klr.start_decision
        assert decision.rule == "learned" and decision.chosen == active
        assert [o.combination for o in decision.options] == start.combinations
        scores = np.array([o.score for o in decision.options])
        assert np.all(np.isfinite(scores)) and scores.max() <= 0.0
        np.testing.assert_allclose(np.exp(scores).sum(), 1.0)
        assert decision.options[int(np.argmax(scores))].combination == active
        # each test demonstration starts as the demonstrator started it
        assert active == {v: str(demo.labels[v][0]) for v in fitted_klr.graphs}


def _entry_score(seq, x, combination) -> float:
    """``Σ log(1 - φ)`` of ``combination``'s nodes at the features ``x``, φ of their own
    progress predictors."""
    phi = seq.predict_progress(x)
    return sum(
        float(np.log(np.clip(1.0 - phi[v][mp], 1e-12, 1.0))) for v, mp in combination.items()
    )


def test_joint_rule_keeps_every_demonstrated_start_and_takes_the_best(fit_on_train, test_demos):
    seq = fit_on_train("klr", start_rule="joint")
    for demo in test_demos:
        active = seq.reset(0.0, demo.features[0])
        decision = seq.start_decision
        assert decision.rule == "joint" and decision.chosen == active
        assert [o.combination for o in decision.options] == seq.initial_combinations
        scores = [o.score for o in decision.options]
        assert all(np.isfinite(scores)) and max(scores) <= 0.0
        assert decision.options[int(np.argmax(scores))].combination == active
        # each start is scored on the nodes' own progress predictors
        x0 = demo.features[0]
        expected = [_entry_score(seq, x0, o.combination) for o in decision.options]
        np.testing.assert_allclose(scores, expected, rtol=1e-12)


def test_independent_rule_scores_each_variables_initial_mps(fit_on_train, test_demos):
    seq = fit_on_train("klr", **PAPER_OPTIONS)
    x0 = test_demos[0].features[0]
    active = seq.reset(0.0, x0)
    decision = seq.start_decision
    assert decision.rule == "independent" and decision.chosen == active
    for v, graph in seq.graphs.items():
        mine = [o for o in decision.options if list(o.combination) == [v]]
        assert sorted(o.combination[v] for o in mine) == sorted(graph.initial_nodes)
        assert max(mine, key=lambda o: o.score).combination[v] == active[v]
        for o in mine:
            assert o.score == pytest.approx(_entry_score(seq, x0, o.combination), rel=1e-12)
