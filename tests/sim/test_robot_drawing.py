"""The robot as a recording draws it: every geom logged to rerun, composed with its body's
logged pose the way the viewer composes entity transforms, lies where MuJoCo puts it, and each
hand's palm meets its forearm, at the home posture and at a bent one."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path
from typing import NamedTuple

import mujoco
import numpy as np
import pytest
from rerun.chunk import RrdReader

from cpmp.recordings import EpisodeRecorder
from cpmp.sim import Box, TaskConfig
from cpmp.sim.simulation import HANDS, Simulation

BENT = np.array([0.4, 0.3, -0.5, -0.4, 0.6, 0.5, -0.3])
"""A second posture: home plus these joint offsets [rad] (left arm; the right arm mirrored)."""
POSITION_TOL = 1e-4
"""[m]: poses are stored as float32."""
HAND_GAP = 0.04
"""[m]: the palm's wrist-side face lies this close to its forearm's end (here about 1 cm)."""


class Pose(NamedTuple):
    """A rigid transform: ``rotation`` (3, 3) and ``translation`` (3,) [m]."""

    rotation: np.ndarray
    translation: np.ndarray

    def apply(self, point: np.ndarray) -> np.ndarray:
        """``point`` (3,) of this frame in the parent frame."""
        return self.rotation @ point + self.translation

    def then(self, child: Pose) -> Pose:
        """The pose of ``child`` (given in this frame) in the parent frame."""
        return Pose(self.rotation @ child.rotation, self.apply(child.translation))


class Logged(NamedTuple):
    """What a recording holds about the 3D scene.

    Attributes:
        static: entity path -> its static ``Transform3D``.
        timed: entity path -> time [s] -> its ``Transform3D`` at that time.
        shapes: entity path -> component column -> its static value (capsule lengths, ...).
    """

    static: dict[str, Pose]
    timed: dict[str, dict[float, Pose]]
    shapes: dict[str, dict[str, list]]


def _pose(translation: list[float] | None, quat_xyzw: list[float] | None) -> Pose:
    rotation = np.eye(3)
    if quat_xyzw is not None:
        x, y, z, w = quat_xyzw
        mat = np.zeros(9)
        mujoco.mju_quat2Mat(mat, np.array([w, x, y, z], dtype=float))
        rotation = mat.reshape(3, 3)
    return Pose(rotation, np.zeros(3) if translation is None else np.asarray(translation, float))


def _read_scene(path: Path) -> Logged:
    """The ``world/...`` transforms and shapes of a recording, read back offline."""
    static: dict[str, Pose] = {}
    timed: dict[str, dict[float, Pose]] = defaultdict(dict)
    shapes: dict[str, dict[str, list]] = defaultdict(dict)
    for chunk in RrdReader(path).stream():
        if not chunk.entity_path.startswith("/world"):
            continue
        entity = chunk.entity_path.lstrip("/")
        batch = chunk.to_record_batch()
        columns = {name: batch.column(name).to_pylist() for name in batch.schema.names}
        for name, values in columns.items():
            if chunk.is_static and name.split(":")[0] in ("Capsules3D", "Boxes3D"):
                shapes[entity][name] = values[-1]
        if "Transform3D:translation" not in columns:
            continue
        translations = columns["Transform3D:translation"]
        quats = columns.get("Transform3D:quaternion", [None] * len(translations))
        poses = [
            _pose(t[0] if t else None, q[0] if q else None)
            for t, q in zip(translations, quats, strict=True)
        ]
        if chunk.is_static:
            static[entity] = poses[-1]
        else:
            times = [round(t * 1e-9, 6) for t in batch.column("time").cast("int64").to_pylist()]
            timed[entity].update(zip(times, poses, strict=True))
    return Logged(static, dict(timed), dict(shapes))


def _world_pose(logged: Logged, entity: str, t: float) -> Pose:
    """``entity``'s pose in the world at ``t``: its ancestors' transforms composed, root first."""
    parts = entity.split("/")
    pose = Pose(np.eye(3), np.zeros(3))
    for depth in range(1, len(parts) + 1):
        path = "/".join(parts[:depth])
        if path in logged.timed:
            pose = pose.then(logged.timed[path][t])
        elif path in logged.static:
            pose = pose.then(logged.static[path])
    return pose


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[dict]]:
    """A two-tick recording of the robot (t = 0: home, t = 1: bent) and MuJoCo's geom poses
    (per tick: entity path -> (position (3,), rotation (3, 3)))."""
    sim = Simulation(TaskConfig(), Box(0.2, 0.15, 0.1))
    m, d = sim.model, sim.data
    drawn = [i for i in range(m.ngeom) if int(m.geom_type[i]) != int(mujoco.mjtGeom.mjGEOM_PLANE)]
    geoms = sim.geoms()
    assert len(geoms) == len(drawn)
    paths = [f"world/{g['body']}/{g['name']}" for g in geoms]
    bent = sim.q_home + np.stack([BENT, BENT * [-1, -1, -1, 1, -1, 1, -1]])
    path = tmp_path_factory.mktemp("robot") / "robot.rrd"
    expected = []
    with EpisodeRecorder(path, feature_names=["x"], mp_names={"v": ["a"]}, geoms=geoms) as rec:
        for t, posture in ((0.0, None), (1.0, bent)):
            sim.reset(arm_posture=posture)
            rec.log_tick(t, [0.0], {}, {"v": "a"}, None, sim.body_poses())
            expected.append(
                {
                    p: (d.geom_xpos[i].copy(), d.geom_xmat[i].reshape(3, 3).copy())
                    for p, i in zip(paths, drawn, strict=True)
                }
            )
    return path, expected


def test_no_entity_mixes_a_static_and_a_timed_transform(recorded) -> None:
    """A geom logged at its body's own path: its pose in the body frame and the body's world
    pose would fight over one transform (the bug that drew the robot in pieces)."""
    logged = _read_scene(recorded[0])
    assert "world/left_forearm" in logged.timed
    assert set(logged.static) & set(logged.timed) == set()


@pytest.mark.parametrize("tick", [0, 1], ids=["home", "bent"])
def test_every_geom_is_drawn_where_mujoco_has_it(recorded, tick: int) -> None:
    path, expected = recorded
    logged = _read_scene(path)
    for entity, (position, rotation) in expected[tick].items():
        pose = _world_pose(logged, entity, float(tick))
        np.testing.assert_allclose(pose.translation, position, atol=POSITION_TOL, err_msg=entity)
        np.testing.assert_allclose(pose.rotation, rotation, atol=1e-4, err_msg=entity)


@pytest.mark.parametrize("tick", [0, 1], ids=["home", "bent"])
def test_each_palm_meets_its_forearm(recorded, tick: int) -> None:
    """The drawn forearm capsule ends within a few cm of the drawn palm's wrist-side face (the
    hands floated about 15 cm off the forearms before)."""
    path, _ = recorded
    logged = _read_scene(path)
    t = float(tick)
    for hand in HANDS:
        (forearm,) = [e for e in logged.shapes if e.startswith(f"world/{hand}_forearm/")]
        capsule = logged.shapes[forearm]
        start = np.asarray(capsule["Capsules3D:translations"][0], float)
        length = capsule["Capsules3D:lengths"][0]
        frame = _world_pose(logged, forearm, t)
        ends = [frame.apply(start), frame.apply(start + np.array([0.0, 0.0, length]))]
        palm = f"world/{hand}_hand/{hand}_palm"
        half = logged.shapes[palm]["Boxes3D:half_sizes"][0]
        face = _world_pose(logged, palm, t).apply(np.array([0.0, 0.0, half[2]]))
        gap = min(np.linalg.norm(end - face) for end in ends)
        assert gap < HAND_GAP, f"{hand} palm is {gap:.3f} m from its forearm at t = {t}"
        # and its other end is at the elbow (the forearm body's origin)
        elbow = _world_pose(logged, f"world/{hand}_forearm", t).translation
        assert min(np.linalg.norm(end - elbow) for end in ends) < POSITION_TOL
