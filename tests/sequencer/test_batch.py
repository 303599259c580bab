"""Batches of episodes (cpmp.sequencer.batch): the batched sequencer's N episodes in one predictor
call per tick decide exactly as N single sequencers (events, notes, tick information), with a live
mask and per-episode state."""

import math
from typing import ClassVar

import numpy as np
import pytest
import torch

from cpmp.config import SequencerConfig
from cpmp.data.demonstration import Demonstration
from cpmp.errors import ConfigError, DataError, NotFittedError
from cpmp.graph import build_graphs
from cpmp.predictors import PredictorConfig, ProgressPredictor
from cpmp.sequencer.batch import BatchedSequencer
from cpmp.sequencer.sequencer import ConcurrentSequencer
from cpmp.sequencer.switching import Coupling

DT = 0.01


class FeatureIsProgress(ProgressPredictor):
    """Test double: node k's progress is feature k; a feature above 1.5 gives a NaN φ. Records
    the rows of every call."""

    kind: ClassVar[str] = "feature_is_progress"

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.rows: list[int] = []

    def logits(self, z: torch.Tensor) -> torch.Tensor:
        self.rows.append(z.shape[0])
        out = torch.logit(z.clamp(1e-9, 1 - 1e-9))
        return torch.where(z > 1.5, torch.full_like(z, math.nan), out)


class StatefulDouble(FeatureIsProgress):
    """A stateful bank: remembers how many streams it was reset to."""

    kind: ClassVar[str] = "stateful_double"
    stateful: ClassVar[bool] = True

    def reset_state(self, n_streams: int) -> None:
        self.streams = n_streams


def _two_chains(model_class=FeatureIsProgress, **config) -> ConcurrentSequencer:
    """Variables u: U1 -> U2 and w: W1 -> W2 (features are φ_U1, φ_U2, φ_W1, φ_W2); w's switch
    was demonstrated only while u ran U2, so the coupling holds it back before."""
    labels = {"u": ["U1"] * 3 + ["U2"] * 4, "w": ["W1"] * 4 + ["W2"] * 3}
    demo = Demonstration(
        time=np.arange(7) * DT,
        features=np.zeros((7, 4)),
        labels={v: np.array(lab) for v, lab in labels.items()},
        feature_names=["a", "b", "c", "d"],
    )
    graphs = build_graphs([demo])
    keys = [("u", "U1"), ("u", "U2"), ("w", "W1"), ("w", "W2")]
    model = model_class(keys, 4, PredictorConfig(feature_scaling="none"))
    options = {"patience": 0.03, "stall_time": 0.3, "recovery_threshold": 0.3, **config}
    coupling = Coupling.learn([demo], ["u", "w"])
    return ConcurrentSequencer(
        graphs, model, demo.feature_names, SequencerConfig(**options), None, None, coupling
    )


def _streams(n: int, ticks: int, seed: int) -> np.ndarray:
    """Feature streams ``(ticks, n, 4)``: per episode and variable, the first node's φ rises
    from a random time to a random plateau (0.5: below the threshold, a stall; else a switch),
    the second node's φ a random while later: switches, holds and recoveries happen at
    different ticks in different episodes."""
    rng = np.random.default_rng(seed)
    t = np.arange(ticks) * DT
    out = np.empty((ticks, n, 4))
    for i in range(n):
        for first in (0, 2):
            start, rate = rng.uniform(0.0, 0.5), rng.uniform(2.0, 8.0)
            top = rng.choice([0.5, 0.8, 0.95])
            later = start + top / rate + rng.uniform(0.1, 0.6)
            out[:, i, first] = np.clip((t - start) * rate, 0.0, top)
            out[:, i, first + 1] = np.clip((t - later) * rate, 0.0, 0.9)
    return out


def _assert_same_episode(single, batched):
    """Equal decisions: active MPs every tick, events (state bit-exact), notes, held
    transitions; φ and p equal to rounding. A batch of rows may round differently in the
    predictor (vectorised transcendental functions, matrix products: ~1e-14 here)."""
    a_s, ev_s, no_s, ti_s = single
    a_b, ev_b, no_b, ti_b = batched
    assert a_b == a_s
    key = [(e.t, e.variable, e.source, e.target, e.kind) for e in ev_s]
    assert [(e.t, e.variable, e.source, e.target, e.kind) for e in ev_b] == key
    assert [e.probability for e in ev_b] == pytest.approx([e.probability for e in ev_s], rel=1e-9)
    for e_b, e_s in zip(ev_b, ev_s, strict=True):
        np.testing.assert_array_equal(e_b.state, e_s.state)
    assert [(n.t, n.kind, n.variable, n.text) for n in no_b] == [
        (n.t, n.kind, n.variable, n.text) for n in no_s
    ]
    assert len(ti_b) == len(ti_s)
    for t_b, t_s in zip(ti_b, ti_s, strict=True):
        assert (t_b.t, t_b.active, t_b.held) == (t_s.t, t_s.active, t_s.held)
        for v, phi in t_s.progress.items():
            assert t_b.progress[v] == pytest.approx(phi, rel=1e-9, abs=1e-12, nan_ok=True)
        assert t_b.transition_probs.keys() == t_s.transition_probs.keys()
        for v, probs in t_s.transition_probs.items():
            assert t_b.transition_probs[v] == pytest.approx(probs, rel=1e-9, abs=1e-12)


def _single_runs(seq, x, lengths):
    """Each episode alone: reset on tick 0, then step while the tick is below its length.

    Every tick is a new measurement (its stamp), also on the streams' exact plateaus."""
    out = []
    for i, n_ticks in enumerate(lengths):
        actives = [seq.reset(0.0, x[0, i])]
        ticks = [seq.last_tick]
        for k in range(1, n_ticks):
            actives.append(seq.step(k * DT, x[k, i], stamp=k * DT))
            ticks.append(seq.last_tick)
        out.append((actives, list(seq.events), list(seq.notes), ticks))
    return out


def _batched_run(batch, x, lengths):
    """All episodes together, each live while the tick is below its length."""
    n = len(lengths)
    lengths = np.asarray(lengths)
    actives = [[a] for a in batch.reset(0.0, x[0])]
    ticks = [[ep.last_tick] for ep in batch.episodes]
    for k in range(1, int(lengths.max())):
        live = k < lengths
        result = batch.step(k * DT, x[k], live=live, stamp=k * DT)
        for i in np.flatnonzero(live):
            actives[i].append(result[i])
            ticks[i].append(batch.episodes[i].last_tick)
    return [
        (actives[i], batch.episodes[i].events, batch.episodes[i].notes, ticks[i]) for i in range(n)
    ]


def test_batched_step_equals_single_steps_exactly():
    seq = _two_chains()
    n, ticks = 12, 160
    x = _streams(n, ticks, seed=22)
    x[40, 5, 1] = 2.0  # one non-finite φ in one episode at one tick
    x[30:33, 0] = np.nan  # three ticks of NaN features in another: the predictor never sees them
    lengths = np.random.default_rng(4).integers(60, ticks + 1, n)
    lengths[0] = ticks
    single = _single_runs(seq, x, lengths)
    batch = seq.batched(n)
    assert isinstance(batch, BatchedSequencer) and len(batch) == batch.n_episodes == n
    got = _batched_run(batch, x, lengths)
    for one, together in zip(single, got, strict=True):
        _assert_same_episode(one, together)
    # the streams exercise every path, at different ticks in different episodes
    kinds = {e.kind for _, events, _, _ in single for e in events}
    notes = {note.kind for _, _, episode_notes, _ in single for note in episode_notes}
    assert kinds == {"switch", "recovery"}
    assert notes == {"hold", "recovery", "give_up", "nonfinite"}
    assert [n.kind for n in single[0][2]].count("nonfinite") == 1  # one note for the burst
    first_switch = {events[0].t for _, events, _, _ in single if events}
    assert len(first_switch) >= 5


def test_one_predictor_call_per_tick_over_the_live_episodes():
    seq = _two_chains()
    x = _streams(5, 30, seed=0)
    batch = seq.batched(5)
    model = seq.predictor
    batch.reset(0.0, x[0])
    model.rows.clear()
    live = np.array([True, False, True, True, False])
    for k in range(1, 30):
        batch.step(k * DT, x[k], live=live)
    assert model.rows == [3] * 29
    # episodes left out are untouched: still at their reset state
    assert all(batch.episodes[i].last_tick.t == 0.0 for i in (1, 4))
    assert all(batch.episodes[i].last_tick.t == pytest.approx(0.29) for i in (0, 2, 3))


def test_live_mask_on_reset_and_per_episode_times():
    seq = _two_chains()
    x = _streams(3, 50, seed=1)
    batch = seq.batched(3)
    out = batch.reset(0.0, x[0], live=[True, False, True])
    assert out[1] == {} and out[0] == out[2] == {"u": "U1", "w": "W1"}
    with pytest.raises(NotFittedError, match="episode 1: call reset"):
        batch.step(DT, x[1])
    batch.reset(np.array([0.0, 0.2, 0.0]), x[0], live=np.array([False, True, False]))
    with pytest.raises(DataError, match="episode 1: time went backwards"):
        batch.step(0.1, x[1])
    # each episode keeps its own clock: episode 1 started later
    batch.step(np.array([0.1, 0.3, 0.1]), x[1])
    assert [ep.last_tick.t for ep in batch.episodes] == [0.1, 0.3, 0.1]


def test_fitted_klr_batch_equals_single_replays(fitted_klr, test_demos):
    """The klr bank over the held-out synthetic demos, each live for its own length."""
    seq = fitted_klr
    lengths = [d.n_samples for d in test_demos]
    n_ticks = max(lengths)
    x = np.zeros((n_ticks, len(test_demos), len(seq.feature_names)))
    for i, demo in enumerate(test_demos):
        x[: demo.n_samples, i] = demo.features
        x[demo.n_samples :, i] = demo.features[-1]
    single = _single_runs(seq, x, lengths)
    got = _batched_run(seq.batched(len(test_demos)), x, lengths)
    for one, together in zip(single, got, strict=True):
        _assert_same_episode(one, together)
    switch_ticks = {tuple(e.t for e in events) for _, events, _, _ in single}
    assert len(switch_ticks) >= 4  # the episodes switch at different ticks


def test_stateful_predictor_runs_one_stream_per_episode():
    seq = _two_chains(StatefulDouble)
    x = _streams(4, 10, seed=2)
    batch = seq.batched(4)
    batch.reset(0.0, x[0], live=[True, True, False, True])
    assert seq.predictor.streams == 4
    seq.predictor.rows.clear()
    batch.step(DT, x[1], live=[True, False, False, True])
    assert seq.predictor.rows == [4]  # every stream advances one tick per call
    assert batch.episodes[1].last_tick.t == 0.0 and batch.episodes[0].last_tick.t == DT


def test_torch_input_and_bad_inputs():
    seq = _two_chains()
    x = _streams(2, 3, seed=0)
    batch = seq.batched(2)
    assert batch.reset(0.0, torch.from_numpy(x[0])) == batch.reset(0.0, x[0])
    with pytest.raises(DataError, match=r"shape \(2, 4\)"):
        batch.step(DT, x[1, :1])
    with pytest.raises(DataError, match="boolean mask"):
        batch.step(DT, x[1], live=[1, 0])
    with pytest.raises(DataError, match="finite"):
        batch.step(math.nan, x[1])
    with pytest.raises(DataError, match="one time or 2 times"):
        batch.step(np.array([DT, DT, DT]), x[1])
    with pytest.raises(DataError, match="one time or 2 times"):
        batch.step(DT, x[1], stamp=[0.0, 0.0, 0.0])
    with pytest.raises(DataError, match="stamp"):
        batch.step(DT, x[1], stamp=[0.0, 2 * DT])  # measured after it is given
    bad = x[1].copy()
    bad[0, 0] = np.inf
    with pytest.raises(DataError, match="NaN or inf"):
        batch.reset(0.0, bad)  # no MP to keep at the start
    strict = _two_chains(nonfinite="raise").batched(2)
    strict.reset(0.0, x[0])
    with pytest.raises(DataError, match=r"episode 0: .*non-finite features \(columns 0\)"):
        strict.step(DT, bad)
    batch.reset(0.0, x[0])
    assert batch.step(DT, bad) == batch.active  # held (nonfinite="hold")
    assert [n.kind for n in batch.notes[0]] == ["nonfinite"] and not batch.notes[1]
    for n in (0, -1, 2.5, True):
        with pytest.raises(ConfigError, match="n >= 1"):
            seq.batched(n)
