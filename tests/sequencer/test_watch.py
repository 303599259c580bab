"""What an episode remembers of each pending switch (cpmp.sequencer.watch) and how
SequencerEpisode.explain names the switch that never came: every reason reachable, on the
fitted two-point sequencer driven with synthetic φ."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cpmp.records import PendingSwitch
from cpmp.sequencer import SequencerEpisode
from cpmp.sequencer.watch import ActivationWatch

DT = 0.01
EXPECTED = {"a": ["a_go", "a_back"], "b": ["b_go", "b_back"]}
"""The two-point demonstrator's parallel strategy (both go, then both back)."""


def watch(successors=("x", "y")) -> ActivationWatch:
    return ActivationWatch("v", "cur", list(successors), 0.0, 0.65, 0.05, 1e-3)


def test_watch_keeps_best_p_and_its_time_and_the_last_p():
    w = watch()
    for k, p in enumerate([[0.1, 0.2], [0.5, 0.1], [0.3, 0.4]]):
        w.see(k * DT, k * DT, p, stopped=False)
    assert w.best == [0.5, 0.4]
    assert w.best_t == pytest.approx([DT, 2 * DT])
    assert list(w.last) == [0.3, 0.4]
    cause = w.pending("x", gave_up=None)
    assert (cause.reason, cause.best_p, cause.final_p) == ("below_threshold", 0.5, 0.3)
    assert cause.best_t == pytest.approx(DT) and math.isnan(cause.at)


@pytest.mark.parametrize(("step", "status"), [(0.01, "rising"), (1e-5, "flat")])
def test_watch_tells_a_rising_p_from_a_plateau(step, status):
    w = watch(["x"])
    for k in range(20):  # 0.2 s above the threshold, patience 0.05 s
        assert w.see(k * DT, k * DT, [0.7 + step * k], stopped=False)
    assert w.status == [status]
    # a rule that did not fire on a flat p judged it improving: the cause says the p wobbles
    cause = w.pending("x", gave_up=None)
    assert cause.reason == "still_improving"
    assert ("wobbles" in cause.detail) == (status == "flat")
    assert ("wobbles" in cause.describe()) == (status == "flat")


def test_watch_gate_marks_held_and_outranked_successors():
    w = watch()
    assert w.see(0.0, 0.0, [0.8, 0.9], stopped=False)
    w.gate([True, True], None)
    assert w.status[0] == "outranked" and "y" in w.detail[0]
    assert w.pending("x", gave_up=None).reason == "held"
    w.see(DT, DT, [0.8, 0.9], stopped=False)
    w.gate([False, True], "y")
    assert w.status[0] == "held" and "branch choice picked y" in w.detail[0]
    w.see(2 * DT, 2 * DT, [0.8, 0.2], stopped=False)
    w.wait("x", "u: a -> b")
    cause = w.pending("x", gave_up=None)
    assert cause.reason == "held" and cause.detail == "waited for u: a -> b"
    # once the p drops below the threshold the last above-threshold tick still decides
    w.see(3 * DT, 3 * DT, [0.1, 0.1], stopped=False)
    assert w.pending("x", gave_up=None).reason == "held"


def test_watch_after_a_give_up_and_for_a_missing_edge():
    w = watch()
    w.see(0.0, 0.0, [0.3, 0.1], stopped=False)
    assert w.pending("x", gave_up=1.5).at == 1.5  # below the threshold, given up on later
    w.see(2.0, 2.0, [0.9, 0.1], stopped=True)
    cause = w.pending("x", gave_up=1.5)
    assert (cause.reason, cause.at, cause.best_p) == ("given_up", 1.5, 0.9)
    missing = w.pending("z", gave_up=None)
    assert missing.reason == "not_a_successor" and "x, y" in missing.detail
    assert math.isnan(missing.best_p)


# -- the episode, fitted two-point sequencer, synthetic φ ----------------------------------


def started(seq, **options) -> SequencerEpisode:
    """An episode of ``seq`` (with ``options``) started on a and b both ``go``."""
    model = seq.with_config(start_rule="joint", **options).transition_model
    nodes = model.nodes
    phi = np.full(len(nodes.keys), 0.99)
    for key in (("a", "a_go"), ("b", "b_go")):
        phi[nodes.index[key]] = 0.01
    episode = SequencerEpisode(model)
    assert episode.start(0.0, np.zeros(3), phi) == {"a": "a_go", "b": "b_go"}
    return episode


def phi_of(episode: SequencerEpisode, **values: float) -> list[float]:
    """Every node's φ: ``values`` by MP name, 0 for the rest."""
    return [values.get(mp, 0.0) for _, mp in episode.model.nodes.keys]


def run(episode: SequencerEpisode, phis, t0: float = 0.0, moving: bool = True) -> float:
    """Advance ``episode`` over ``phis``, one tick of DT each (stamped; the state moves)."""
    t = t0
    for phi in phis:
        t = round(t + DT, 10)
        state = np.array([t, t, 0.3]) if moving else np.zeros(3)
        episode.advance(t, state, phi, True, stamp=t)
    return t


SIMPLE = {"coupling": "none", "branch": "none", "recovery": False, "joint": False}


def test_explain_below_threshold_and_nothing_pending(fitted_klr):
    episode = started(fitted_klr, **SIMPLE)
    ramp = [0.1 * k for k in range(6)] + [0.4] * 5  # best 0.5 at the 6th tick
    run(episode, [phi_of(episode, a_go=f, a_wait=1.0, b_go=0.0) for f in ramp])
    assert episode.active == {"a": "a_go", "b": "b_go"}
    cause = episode.explain(EXPECTED)
    assert isinstance(cause, PendingSwitch)
    assert (cause.variable, cause.current, cause.expected) == ("a", "a_go", "a_back")
    assert cause.reason == "below_threshold"
    assert cause.best_p == pytest.approx(0.5) and cause.best_t == pytest.approx(6 * DT)
    assert cause.final_p == pytest.approx(0.4)
    assert cause.threshold == fitted_klr.config.threshold
    assert "a a_go -> a_back never fired: p reached 0.500" in cause.describe()
    # the same episode against sequences it ran: nothing pending; a wrong start: no cause
    assert episode.explain({"a": ["a_go"], "b": ["b_go"]}) is None
    assert episode.explain({"a": ["a_wait", "a_back"], "b": ["b_go"]}) is None


def test_explain_still_improving(fitted_klr):
    episode = started(fitted_klr, **SIMPLE)
    rising = [0.7 + 0.01 * k for k in range(25)]  # +0.05 per patience, far above 1e-3
    end = run(episode, [phi_of(episode, a_go=f, a_wait=1.0) for f in rising])
    assert episode.active["a"] == "a_go"  # the rule waits for the plateau
    cause = episode.explain(EXPECTED)
    assert cause.reason == "still_improving"
    assert cause.best_p == pytest.approx(rising[-1]) and cause.best_t == pytest.approx(end)
    assert "above 0.65 but still rising" in cause.describe()


def test_explain_wrong_transition_names_the_switch_that_fired(fitted_klr):
    episode = started(fitted_klr, **SIMPLE)
    run(episode, [phi_of(episode, a_go=0.6 + 0.005 * k, a_back=0.5) for k in range(10)])
    assert episode.active["a"] == "a_go"
    run(episode, [phi_of(episode, a_go=0.9, a_back=1.0)] * 20, t0=10 * DT)
    assert episode.active["a"] == "a_wait"
    fired = episode.events[0]
    cause = episode.explain(EXPECTED)
    assert (cause.reason, cause.current, cause.expected, cause.fired) == (
        "wrong_transition",
        "a_go",
        "a_back",
        "a_wait",
    )
    assert cause.at == fired.t
    # the p the demonstrated edge reached before: 0.645 * (1 - 0.5), at the 10th tick
    assert cause.best_p == pytest.approx(0.645 * 0.5) and cause.best_t == pytest.approx(10 * DT)
    assert "a a_go -> a_wait fired at" in cause.describe()


def test_explain_not_a_successor(fitted_klr):
    episode = started(fitted_klr, **SIMPLE)
    run(episode, [phi_of(episode)] * 3)
    cause = episode.explain({"a": ["a_go"], "b": ["b_go", "b_wait"]})
    assert (cause.variable, cause.expected, cause.reason) == ("b", "b_wait", "not_a_successor")
    assert "b_back" in cause.detail


def test_explain_held_by_the_coupling_or_a_joint_switch(fitted_klr):
    episode = started(fitted_klr)  # the default: context coupling, joint switches, branches
    # a is ready to go back (flat p 0.9); b never is: a's switch waits or is held
    run(episode, [phi_of(episode, a_go=0.9, a_wait=1.0)] * 30)
    assert episode.active == {"a": "a_go", "b": "b_go"}
    cause = episode.explain({"a": ["a_go", "a_back"], "b": ["b_go"]})
    assert cause.reason == "held" and cause.detail
    assert cause.best_p == pytest.approx(0.9)
    assert "held back" in cause.describe()


def test_explain_given_up(fitted_klr):
    episode = started(fitted_klr, stall_time=0.2, recovery_threshold=0.2)
    # no motion and p below the recovery threshold: a stall nothing resolves, it gives up ...
    end = run(episode, [phi_of(episode, a_back=1.0, a_wait=1.0, b_back=1.0)] * 40, moving=False)
    assert episode.gave_up is not None
    assert any(n.kind == "give_up" for n in episode.notes)
    cause = episode.explain(EXPECTED)
    assert cause.reason == "below_threshold" and cause.at == episode.gave_up
    # ... and a p that passes the threshold afterwards fires no more
    run(episode, [phi_of(episode, a_go=0.95, a_wait=1.0)] * 10, t0=end)
    assert episode.active == {"a": "a_go", "b": "b_go"}
    cause = episode.explain(EXPECTED)
    assert (cause.reason, cause.at) == ("given_up", episode.gave_up)
    assert cause.best_p == pytest.approx(0.95)


def test_explain_is_exposed_on_the_sequencer_and_per_episode_of_a_batch(fitted_klr, test_demos):
    from cpmp.data.demonstration import mp_sequences

    demo = test_demos[0]
    expected = mp_sequences(demo)
    fitted_klr.reset(0.0, demo.features[0])
    batch = fitted_klr.batched(2)
    batch.reset(0.0, np.stack([demo.features[0]] * 2))
    for k in range(1, 4):
        fitted_klr.step(demo.time[k], demo.features[k])
        batch.step(demo.time[k], np.stack([demo.features[k]] * 2))
    one = fitted_klr.explain(expected)
    assert one is not None and one.reason in ("below_threshold", "still_improving", "held")
    for other in (batch.explain(1, expected), batch.episodes[0].explain(expected)):
        # the same decision; φ of a batch may differ from one row's in the last bits
        assert (other.variable, other.current, other.expected, other.reason) == (
            one.variable,
            one.current,
            one.expected,
            one.reason,
        )
        assert other.best_p == pytest.approx(one.best_p, abs=1e-9)
