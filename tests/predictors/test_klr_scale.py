"""The default ``klr`` bank at scale (cpmp.predictors.klr): kernels in blocks of samples (the
same fit as a kernel held whole, memory bounded by ``chunk_size``), supports pooled over the
activations past ``support_cap`` (a count that saturates), and the fit on the trainer's
accelerator."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from cpmp.config import FitConfig
from cpmp.config.predictors import KLRConfig
from cpmp.config.trainer import SolverOptions, TrainerConfig
from cpmp.errors import ConfigError
from cpmp.graph import build_graphs
from cpmp.predictors import PREDICTORS
from cpmp.predictors.klr import (
    CHUNK_SIZE,
    MERGE_SIMILARITY,
    POOL_SIZE,
    SUPPORT_CAP,
    KLRPredictor,
    pool_supports,
)
from cpmp.predictors.training import fit_predictor
from cpmp.sequencer.fit_data import node_training_data


def _bank(demos, kind="klr", **attributes):
    """An untrained bank of ``kind`` over ``demos``' graphs and its node data.

    ``attributes`` are set on the bank before its data are made (``chunk_size``, ...).
    """
    config = FitConfig.from_options(kind)
    graphs = build_graphs(demos, config.variables)
    keys = [(v, mp) for v in sorted(graphs) for mp in graphs[v].ordered_nodes()]
    bank = PREDICTORS[kind](keys, len(demos[0].feature_names), config.predictor_config)
    for name, value in attributes.items():
        setattr(bank, name, value)
    bank.scaler.fit(np.concatenate([d.features for d in demos]), bank.config.feature_scaling)
    return bank, node_training_data(graphs, bank)


def _fitted(demos, trainer=None, **attributes):
    """A bank fitted on ``demos`` on the CPU (``trainer``: trainer options)."""
    bank, data = _bank(demos, **attributes)
    options = {"accelerator": "cpu", **(trainer or {})}
    summary = fit_predictor(bank, data, TrainerConfig(**options), seed=0)
    return bank, data, summary


@pytest.fixture(scope="module")
def whole_and_blocked(train_demos):
    """The default fit (every node's kernel in one block) and one in blocks of ~30 samples.

    Solved to a gradient of 1e-12: two minimisers reached from different points (a blocked
    node starts from its subsample's solution) differ by up to about |gradient| / l2 along
    the flattest directions (l2 = 1e-4); at the default 1e-10 the weights differed by 1.4e-8,
    at 1e-12 by 3e-11.
    """
    tight = {"newton_tol": 1e-12}
    whole = _fitted(train_demos, tight)
    blocked = _fitted(train_demos, tight, chunk_size=1000)
    return whole, blocked


def test_small_fits_hold_each_kernel_in_one_block(whole_and_blocked):
    (bank, data, _), _ = whole_and_blocked
    assert bank.chunk_size == CHUNK_SIZE
    assert all(bank.blocked(i, node.n_samples).rows is None for i, node in enumerate(data))


def test_blocks_give_the_fit_of_the_whole_kernel(whole_and_blocked):
    (whole, data, s_whole), (blocked, _, s_blocked) = whole_and_blocked
    assert all(blocked.blocked(i, n.n_samples).rows is not None for i, n in enumerate(data))
    assert torch.equal(whole.support, blocked.support)
    # the same convex problem, summed in another order and solved from another start
    assert torch.allclose(whole.weight, blocked.weight, atol=1e-10, rtol=0)
    assert torch.allclose(whole.bias, blocked.bias, atol=1e-10, rtol=0)
    assert s_blocked.loss == pytest.approx(s_whole.loss, abs=1e-12)
    assert s_blocked.newton.converged and s_whole.newton.converged
    with torch.no_grad():
        for i, node in enumerate(data):
            # node_logits in blocks and whole, the same bank: rounding only
            torch.testing.assert_close(
                blocked.node_logits(node.x, i), whole.node_logits(node.x, i), atol=1e-9, rtol=0
            )
        x = torch.cat([node.x for node in data])
        torch.testing.assert_close(blocked.logits(x), whole.logits(x), atol=1e-9, rtol=0)
        torch.testing.assert_close(
            blocked.streamed_loss(data), whole.streamed_loss(data), atol=1e-12, rtol=0
        )


def test_a_blocked_fit_never_holds_more_than_a_block(train_demos, monkeypatch):
    bank, data = _bank(train_demos, chunk_size=1000)
    bank.initialize(data, torch.Generator().manual_seed(0))
    largest = []
    original = KLRPredictor.blocked

    def recording(self, i, n):
        made = original(self, i, n)

        def kernel(x):
            out = made.kernel(x)
            largest.append(out.numel())
            return out

        return type(made)(kernel, made.rows, made.mask)

    def whole_kernels(self, data):
        raise AssertionError("the Newton fit asked for every node's whole kernel")

    monkeypatch.setattr(KLRPredictor, "blocked", recording)
    monkeypatch.setattr(KLRPredictor, "node_kernels", whole_kernels)
    infos = bank.solve_convex(data, SolverOptions())
    with torch.no_grad():
        bank.training_loss(data)
    assert all(info.converged for info in infos)
    assert largest and max(largest) <= 1000


def test_the_default_caches_the_kernel_only_where_gradients_need_it(whole_and_blocked):
    (bank, data, _), _ = whole_and_blocked
    bank.clear_cache()
    with torch.no_grad():
        bank.training_loss(data)
    assert bank._cache is None  # the Newton fit's loss streams
    loss = bank.training_loss(data)  # with gradients (LBFGS, Adam): the cached kernels
    assert loss.requires_grad and bank._cache is not None


def test_pooling_keeps_one_of_each_repeated_point():
    path = np.linspace([0.0, 0.0], [1.0, 0.5], 9)
    rng = np.random.default_rng(0)
    repeats = [path + 1e-4 * rng.standard_normal(path.shape) for _ in range(20)]
    weights = np.array([4.0, 4.0])
    kept = pool_supports(repeats, weights, 0.995, 256)
    # one of the 20 copies of each point of the path, the first activation's start first
    nearest = np.abs(kept[:, None, :] - path[None]).max(2)
    assert len(kept) == 9 and sorted(nearest.argmin(1)) == list(range(9))
    assert nearest.min(1).max() < 1e-3
    np.testing.assert_array_equal(kept[0], repeats[0][0])
    shifted = [path, path + np.array([0.0, 0.3])]  # a new region: kept
    assert len(pool_supports(shifted, weights, 0.995, 256)) == 18
    # a lower similarity merges more; the weights are the kernel's metric; size caps
    assert len(pool_supports(shifted, weights, 0.5, 256)) == 3  # radius 0.42: 3 cover both
    assert len(pool_supports(shifted, np.array([4.0, 0.0]), 0.995, 256)) == 9
    few = pool_supports(shifted, weights, 0.995, 5)
    assert len(few) == 5
    assert {tuple(p) for p in [path[0], path[-1] + [0.0, 0.3]]} <= {tuple(p) for p in few}


def test_a_node_within_the_cap_keeps_the_rules_supports(train_demos):
    bank, data = _bank(train_demos)
    bank.initialize(data, torch.Generator().manual_seed(0))
    assert bank.support_cap == SUPPORT_CAP and bank.merge_similarity == MERGE_SIMILARITY
    assert bank.pool_size == POOL_SIZE
    for i, node in enumerate(data):
        rule = bank._supports_for(node)
        assert int(bank.support_mask[i].sum()) == len(rule) <= SUPPORT_CAP
        np.testing.assert_array_equal(bank.support[i, : len(rule)].numpy(), rule)


def test_pooled_supports_saturate_with_the_demonstrations(train_demos):
    from cpmp.worlds.two_point import make_demonstrations

    counts, rule, default = [], [], []
    for n in (6, 24, 48):
        demos = make_demonstrations(n, seed=0)
        # merging alone (no size cap) at a coarse similarity saturates
        bank, data = _bank(demos, support_cap=40, pool_size=1000, merge_similarity=0.995)
        bank.initialize(data, torch.Generator().manual_seed(0))
        counts.append(int(bank.support_mask.sum()))
        rule.append(sum(len(bank._supports_for(node)) for node in data))
        for i, node in enumerate(data):  # a pooled node's points are among the rule's
            pts = bank.support[i, bank.support_mask[i]].numpy()
            ref = bank._supports_for(node)
            assert all(np.isclose(ref, p).all(1).any() for p in pts)
        bank, data = _bank(demos, support_cap=40, pool_size=1000)  # the default similarity
        bank.initialize(data, torch.Generator().manual_seed(0))
        default.append(int(bank.support_mask.sum()))
    assert rule[2] == pytest.approx(8 * rule[0], rel=0.2)  # the rule: linear in the demos
    # pooled: doubling the demonstrations adds few (measured 332 -> 357, the rule's count
    # doubling to 1,272)
    assert counts[2] < 1.25 * counts[1] and counts[2] < rule[2] / 3
    # the default's finer similarity keeps more, a falling share of the rule's points (measured
    # 450 -> 634 of 636 -> 1,272); pool_size then caps each node
    assert counts[1] < default[1] < rule[1] and counts[2] < default[2] < rule[2]
    assert default[2] / rule[2] < 0.8 * default[1] / rule[1]


@pytest.mark.parametrize("kind", ["klr_full", "klr_sparse"])
def test_full_and_sparse_banks_never_pool(kind):
    assert not PREDICTORS[kind].pools_supports
    assert PREDICTORS["klr"].pools_supports


@pytest.mark.parametrize(
    ("name", "value"),
    [
        ("chunk_size", 0),
        ("chunk_size", 2.5),
        ("support_cap", -1),
        ("pool_size", 0),
        ("merge_similarity", 1.0),
    ],
)
def test_bad_scale_options_are_config_errors(name, value):
    config = KLRConfig()
    setattr(config, name, value)  # as a config with the option would carry it
    with pytest.raises(ConfigError, match=name):
        KLRPredictor([("a", "m")], 2, config)


def test_the_fit_runs_on_the_trainers_accelerator(whole_and_blocked):
    (bank, _, summary), _ = whole_and_blocked
    assert summary.device == "cpu"
    assert {t.device.type for t in [*bank.parameters(), *bank.buffers()]} == {"cpu"}


def test_a_pooled_blocked_fit_converges_on_the_pooled_supports(train_demos):
    bank, data, summary = _fitted(train_demos, support_cap=20, pool_size=12, chunk_size=500)
    counts = bank.support_mask.sum(1).tolist()
    rule = [len(bank._supports_for(node)) for node in data]
    assert all(c == r if r <= 20 else c <= 12 for c, r in zip(counts, rule, strict=True))
    assert any(r > 20 for r in rule)  # some nodes were pooled
    assert summary.newton.converged and summary.n_support_total == sum(counts)


def test_too_many_rule_points_to_pool_is_a_config_error(train_demos):
    bank, data = _bank(train_demos, support_cap=20)
    bank.config.max_total_support = 10  # 20 x 10 candidates at most
    with pytest.raises(ConfigError, match="max_total_support"):
        bank.initialize(data, torch.Generator().manual_seed(0))
