"""The start decision a sequencer keeps (``start_decision``): the starts it weighed, each with
its score, and the one it took — what a recording shows of a wrong start."""

from __future__ import annotations

import numpy as np

from cpmp.sequencer import PAPER_OPTIONS


def test_joint_rule_keeps_every_demonstrated_start_and_takes_the_best(fitted_klr, test_demos):
    assert fitted_klr.config.start_rule == "joint"
    for demo in test_demos:
        active = fitted_klr.reset(0.0, demo.features[0])
        decision = fitted_klr.start_decision
        assert decision.rule == "joint" and decision.chosen == active
        assert [o.combination for o in decision.options] == fitted_klr.initial_combinations
        scores = [o.score for o in decision.options]
        assert all(np.isfinite(scores)) and max(scores) <= 0.0
        assert decision.options[int(np.argmax(scores))].combination == active


def test_independent_rule_scores_each_variables_initial_mps(fit_on_train, test_demos):
    seq = fit_on_train("klr", **{**PAPER_OPTIONS, "start_kernel": "isotropic"})
    active = seq.reset(0.0, test_demos[0].features[0])
    decision = seq.start_decision
    assert decision.rule == "independent" and decision.chosen == active
    for v, graph in seq.graphs.items():
        mine = [o for o in decision.options if list(o.combination) == [v]]
        assert sorted(o.combination[v] for o in mine) == sorted(graph.initial_nodes)
        assert max(mine, key=lambda o: o.score).combination[v] == active[v]
