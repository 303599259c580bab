"""Simulated two-arm pick-and-place world of the paper's evaluation (Sec. IV).

A torso with two 7-DOF arms and a 4-DOF / 7-DOF hand (25 actuated DOF) picks a box of random
width and depth from a plate and puts it into a container, using both hands, the right hand or
the left hand depending on the box size. Six control variables are driven by concurrent
first-order attractor MPs through damped-least-squares IK on pytorch-kinematics Jacobians.

Modules: ``scene`` (MJCF model, boxes, strategy regions), ``kinematics`` (arm FK/Jacobians),
``mps`` (the MP library), ``control`` (MPs to joint targets), ``features`` (the 33 features),
``simulation`` (one episode's world), ``demonstrator`` (the scripted demonstrator),
``collect`` (recording demonstrations, one box or many together), ``policies`` (replay and
batching of policies), ``runner`` (closed-loop episodes and their :data:`Outcome`), ``paced``
(the world with varied MP speeds and holds, :func:`~cpmp.sim.paced.paced_sim`). The options
are :class:`~cpmp.config.task.TaskConfig`; the simulator's speed benchmark is
:mod:`cpmp.benchmarks.sim`.
"""

# ruff: noqa: E402
# The extra is checked before the imports that need it.
from cpmp.errors import require as _require

_require("mujoco", "sim", "cpmp.sim (the MuJoCo world)")
_require("pytorch_kinematics", "sim", "cpmp.sim (the MuJoCo world)")

from cpmp.config.task import TaskConfig
from cpmp.data.demonstration import mp_sequences
from cpmp.records import BatchedPolicy, TickInfo
from cpmp.sim.collect import record_demonstration, record_demonstrations
from cpmp.sim.demonstrator import ScriptedDemonstrator
from cpmp.sim.mps import VARIABLES, mp_names
from cpmp.sim.policies import PolicyList
from cpmp.sim.runner import OUTCOMES, EpisodeResult, Outcome, run_episode, run_episodes
from cpmp.sim.scene import STRATEGIES, Box, correct_strategy, sample_box
from cpmp.sim.simulation import Simulation

__all__ = [
    "OUTCOMES",
    "STRATEGIES",
    "VARIABLES",
    "BatchedPolicy",
    "Box",
    "EpisodeResult",
    "Outcome",
    "PolicyList",
    "ScriptedDemonstrator",
    "Simulation",
    "TaskConfig",
    "TickInfo",
    "correct_strategy",
    "mp_names",
    "mp_sequences",
    "record_demonstration",
    "record_demonstrations",
    "run_episode",
    "run_episodes",
    "sample_box",
]
