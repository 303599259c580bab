"""The simulator as a paced world (cpmp.sim.paced, and the pacing of cpmp.sim's demonstrator,
recordings and closed loop): holds stand a hand still, speed factors shorten the motions, the
same seed gives the same demonstrations, the defaults change nothing."""

from __future__ import annotations

import numpy as np
import pytest

from cpmp.config.task import Pacing
from cpmp.sim import Box, Simulation, TaskConfig, record_demonstrations, run_episodes
from cpmp.sim.collect import make_pacer
from cpmp.sim.demonstrator import ScriptedDemonstrator
from cpmp.sim.paced import paced_sim
from cpmp.worlds.pacing import Pacer

RIGHT_BOX = Box(0.15, 0.12, 0.10)
RIGHT_EE = slice(9, 12)
"""Columns of ``right_ee_x, right_ee_y, right_ee_z`` in the features."""
LAG_TICKS = 10
"""Ticks the position actuators take to stop the hand once its reference stands (measured: the
hand slows from 5 mm to 0.1 mm per tick within 6 ticks)."""


class InitialMPs:
    """A policy that keeps the right-hand strategy's initial MPs (the reach runs, nothing else)."""

    def __init__(self, mps: dict[str, str]) -> None:
        self.mps = mps

    def reset(self, t: float, x: np.ndarray) -> dict[str, str]:
        return dict(self.mps)

    def step(self, t: float, x: np.ndarray) -> dict[str, str]:
        return dict(self.mps)


def demonstrate(cfg: TaskConfig, pacer: Pacer | None) -> np.ndarray:
    """The scripted demonstrator's loop on :data:`RIGHT_BOX`: the features ``(n, 33)``."""
    sim = Simulation(cfg, RIGHT_BOX)
    policy = ScriptedDemonstrator(sim, pacer)
    x = sim.features()
    active = policy.reset(0.0, x)
    features = [x]
    for k in range(round(cfg.max_time / cfg.control_dt)):
        sim.set_active(active)
        assert sim.step()
        x = sim.features()
        features.append(x)
        active = policy.step((k + 1) * cfg.control_dt, x)
        if policy.done:
            break
    return np.asarray(features)


def test_a_hold_stands_the_hand_still_for_the_drawn_ticks():
    cfg = TaskConfig(demo_pause=(0.4, 0.4))
    pacer = make_pacer(cfg.demo_pacing, cfg, (0, 0, 0))
    features = demonstrate(cfg, pacer)
    hold = next(h for h in pacer.holds if h.variable == "right_pos")
    assert hold.mp == "reach_top" and hold.ticks == 40
    ee = features[:, RIGHT_EE]
    # samples hold.start + 1 ... hold.start + ticks follow the held steps
    held = ee[hold.start + LAG_TICKS : hold.start + hold.ticks + 1]
    before = ee[hold.start - (hold.ticks - LAG_TICKS) : hold.start + 1]
    assert np.linalg.norm(held[-1] - held[0]) < 1e-3  # < 1 mm in 0.3 s
    assert np.linalg.norm(before[-1] - before[0]) > 2e-2  # > 2 cm in as long before it
    after = ee[hold.start + hold.ticks + LAG_TICKS]
    assert np.linalg.norm(after - held[-1]) > 5e-3  # and it goes on


def test_a_speed_factor_shortens_the_free_motions_by_it():
    fast, plain = (
        record_demonstrations([RIGHT_BOX], TaskConfig(demo_speed=speed))[0]
        for speed in ((2.0, 2.0), None)
    )
    settle = TaskConfig().settle_time
    for mp in ("lift", "carry"):  # free-space motions that end on a position guard
        (f,) = [s for s in fast.segments("right_pos") if s.mp == mp]
        (p,) = [s for s in plain.segments("right_pos") if s.mp == mp]
        moving = [(s.stop - s.start) * 0.01 - settle for s in (f, p)]
        # x2 speed: half the time, up to the actuators' lag and a tick at each end
        assert moving[1] / moving[0] == pytest.approx(2.0, rel=0.06)
    assert fast.time[-1] < 0.7 * plain.time[-1]
    assert "holds" not in plain.metadata and fast.metadata["holds"] == 0


@pytest.mark.slow
def test_same_seed_same_demonstrations_and_unit_speeds_change_nothing(cfg):
    paced = TaskConfig(demo_speed=(0.5, 2.0), demo_pause=(0.3, 1.0), demo_pause_probability=0.5)
    a0, a1 = record_demonstrations([RIGHT_BOX, RIGHT_BOX], paced, pacing_seed=0)
    (b0,) = record_demonstrations([RIGHT_BOX], paced, pacing_seed=0)
    assert np.array_equal(a0.features, b0.features) and a0.metadata == b0.metadata
    assert not np.array_equal(a0.features[:400], a1.features[:400])  # box 1: its own pace
    assert a0.metadata["success"] and a1.metadata["success"]
    # a pace of 1 is the nominal run, to the last bit
    sims = [Simulation(cfg, RIGHT_BOX) for _ in range(2)]
    active = ScriptedDemonstrator(sims[0]).reset(0.0, sims[0].features())
    sims[1].set_speeds(dict.fromkeys(sims[1].variables, 1.0))
    for sim in sims:
        sim.set_active(active)
        for _ in range(30):
            sim.step()
    np.testing.assert_array_equal(sims[0].features(), sims[1].features())


def test_robot_pacing_moves_the_closed_loop_robot_slower():
    cfg = TaskConfig(max_time=0.6)
    reach = {"right_pos": "reach_top", "right_rot": "down", "right_fingers": "relax"}
    mps = {"left_pos": "idle", "left_rot": "idle", "left_fingers": "relax", **reach}
    moved = []
    for task in (cfg, TaskConfig(max_time=0.6, robot_speed=(0.5, 0.5))):
        ticks = []
        run_episodes([RIGHT_BOX], [InitialMPs(mps)], task, on_tick=[ticks.append])
        moved.append(np.linalg.norm(ticks[20].features[RIGHT_EE] - ticks[0].features[RIGHT_EE]))
    assert moved[1] < 0.6 * moved[0]  # x0.5: half the way in 0.2 s, up to the actuators' lag


@pytest.mark.slow
def test_paced_sim_face():
    cfg = TaskConfig(max_time=40.0, demo_speed=(0.5, 2.0), robot_speed=(0.5, 2.0))
    world = paced_sim(0, 3, cfg)
    assert [d.metadata["strategy"] for d in world.demonstrations] == ["both", "right", "left"]
    assert all(d.metadata["success"] for d in world.demonstrations)
    wrong = {v: "idle" for v in ("left_pos", "left_rot", "right_pos", "right_rot")}
    wrong |= {"left_fingers": "relax", "right_fingers": "relax"}
    scores = world.evaluate([InitialMPs(wrong)], 1, 5)
    assert [(s.outcome, s.strategy) for s in scores] == [("wrong_start", "both")]
    assert Pacing(speed=(0.5, 2.0)) == cfg.robot_pacing
