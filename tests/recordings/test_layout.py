"""The layout pieces of a recording on their own (no file written): the status document, MP
name checks, geoms and body poses as the writer logs them, and the per-tick series buffer."""

from __future__ import annotations

import numpy as np
import pytest
import rerun.blueprint as rrb

from cpmp.errors import ConfigError, DataError, UnknownMPError
from cpmp.recordings.columns import ColumnBuffer
from cpmp.recordings.layout import (
    COLUMN_SHARES,
    LANE_SHARE,
    START_TABLE_WIDTH,
    VariableSeries,
    blueprint,
    check_feature_groups,
    check_mp,
    entity,
    geom_archetypes,
    parse_geom,
    parse_geoms,
    pose_rows,
    status_markdown,
)

MP_NAMES = {"left_pos": ["approach", "grasp"], "right_fingers": ["open", "close"]}


def test_status_markdown() -> None:
    text = status_markdown(
        "demo 1", 1.234, {"left_pos": "grasp"}, list(MP_NAMES), "x -> y at 1.00 s", "outcome: ok"
    )
    assert text.split("\n") == [
        "**demo 1** · t = 1.23 s",
        "",
        "| variable | active MP |",
        "|---|---|",
        "| left_pos | grasp |",
        "| right_fingers | - |",
        "",
        "**outcome: ok**",
        "",
        "last transition: x -> y at 1.00 s",
    ]
    assert status_markdown("e", 0.0, {}, []).split("\n")[2:] == [
        "| variable | active MP |",
        "|---|---|",
    ]


def test_check_mp() -> None:
    check_mp(MP_NAMES, "left_pos")
    check_mp(MP_NAMES, "left_pos", "grasp")
    with pytest.raises(UnknownMPError, match=r"unknown control variable 'head'.*'left_pos'"):
        check_mp(MP_NAMES, "head")
    with pytest.raises(UnknownMPError, match=r"unknown MP 'open' for variable 'left_pos'"):
        check_mp(MP_NAMES, "left_pos", "open")


def test_check_feature_groups_appends_the_rest_as_other() -> None:
    groups = check_feature_groups({"ab": ("b", "a")}, ["a", "b", "c", "d"])
    assert groups == {"ab": ["b", "a"], "other": ["c", "d"]}
    with pytest.raises(ConfigError, match=r"features \['a'\] are in several groups"):
        check_feature_groups({"x": ["a"], "y": ["a", "b"]}, ["a", "b"])


def test_parse_geom_defaults_and_colour() -> None:
    geom = parse_geom(3, {"body": "arm", "type": "sphere", "size": [0.05, 0, 0]})
    assert (geom["body"], geom["name"], geom["type"], geom["size"]) == (
        "arm",
        "geom_3",
        "sphere",
        [0.05, 0.0, 0.0],
    )
    np.testing.assert_array_equal(geom["pos"], [0.0, 0.0, 0.0])
    np.testing.assert_array_equal(geom["quat"], [1.0, 0.0, 0.0, 0.0])
    np.testing.assert_array_equal(geom["rgba"], [153, 153, 153, 255])  # 0.6 * 255
    # Colours are clipped to [0, 1] before scaling; 0.5 * 255 = 127.5 rounds to even (128).
    rgba = parse_geom(0, {"body": "b", "type": "box", "size": [1, 1, 1], "rgba": [2, -1, 0.5, 1]})
    np.testing.assert_array_equal(rgba["rgba"], [255, 0, 128, 255])
    with pytest.raises(ConfigError, match=r"geoms\[2\] quat must have shape \(4,\)"):
        parse_geom(2, {"body": "b", "type": "box", "size": [1, 1, 1], "quat": [1, 0, 0]})
    with pytest.raises(ConfigError, match=r"geoms\[0\]: missing 'body'"):
        parse_geom(0, {"type": "box", "size": [1, 1, 1]})


def test_every_geom_gets_its_own_entity_path() -> None:
    """An empty name (MuJoCo's unnamed geoms) would log the geom at its body's own path, where
    its pose in the body and the body's pose in the world fight over one transform."""
    sphere = {"body": "arm", "type": "sphere", "size": [0.05]}
    geoms = parse_geoms([{**sphere, "name": ""}, {**sphere, "name": "elbow"}, sphere])
    assert [g["name"] for g in geoms] == ["geom_0", "elbow", "geom_2"]
    assert len({entity("world", g["body"], g["name"]) for g in geoms}) == 3
    with pytest.raises(ConfigError, match=r"geoms\[1\] and geoms\[0\] are both named 'elbow'"):
        parse_geoms([{**sphere, "name": "elbow"}, {**sphere, "name": "elbow"}])
    # the same name on two bodies is two paths
    assert len(parse_geoms([{**sphere, "name": "e"}, {**sphere, "body": "leg", "name": "e"}])) == 2


def test_geom_archetypes_centre_capsules_and_turn_quaternions() -> None:
    """MuJoCo capsules are centred on the geom frame, rerun's start at z = 0: the shape is
    shifted down by its half-length; the pose's wxyz quaternion is logged as xyzw."""
    geom = parse_geom(
        0,
        {"body": "b", "type": "capsule", "size": [0.04, 0.15], "quat": [0.5, 0.1, 0.2, 0.3]},
    )
    local, shape = geom_archetypes(geom)
    assert shape.lengths.as_arrow_array().to_pylist() == [pytest.approx(0.3)]
    translation = shape.translations.as_arrow_array().to_pylist()
    assert translation == [pytest.approx([0.0, 0.0, -0.15])]
    quaternion = local.quaternion.as_arrow_array().to_pylist()
    assert quaternion == [pytest.approx([0.1, 0.2, 0.3, 0.5])]


def test_pose_rows() -> None:
    bodies, positions, quats = pose_rows(
        {"box": ([1, 2, 3], [1, 0, 0, 0]), "arm": ([4, 5, 6], [0.5, 0.1, 0.2, 0.3])}
    )
    assert bodies == ("box", "arm")
    np.testing.assert_array_equal(positions, [[1, 2, 3], [4, 5, 6]])
    np.testing.assert_array_equal(quats, [[0, 0, 0, 1], [0.1, 0.2, 0.3, 0.5]])
    with pytest.raises(DataError, match=r"position of body 'arm' must have shape \(3,\)"):
        pose_rows({"box": ([1, 2, 3], [1, 0, 0, 0]), "arm": ([4, 5], [1, 0, 0, 0])})


class _Stream:
    """Stands in for ``rr.RecordingStream``: keeps what is logged and sent."""

    def __init__(self) -> None:
        self.logged: list[str] = []
        self.sent: list[tuple[str, int]] = []

    def log(self, path: str, *archetypes: object, static: bool = False) -> None:
        assert static
        self.logged.append(path)

    def send_columns(self, path: str, indexes: list, columns: object) -> None:
        self.sent.append((path, len(indexes[0].times)))


def test_column_buffer_makes_each_layout_once_and_sends_each_entity() -> None:
    stream = _Stream()
    columns = ColumnBuffer(stream, MP_NAMES)
    paths = columns.progress_paths("left_pos", ("approach", "grasp"))
    assert paths == tuple(
        entity("progress", "left_pos", mp, part)
        for mp in ("approach", "grasp")
        for part in ("phi", "entry", "exit")
    )
    assert columns.progress_paths("left_pos", ("approach", "grasp")) is paths
    assert stream.logged == list(paths)  # each series named once
    index = columns.index_paths(("left_pos", "right_fingers"))
    assert index == ("active/left_pos/index", "active/right_fingers/index")
    assert stream.logged == list(paths)  # the index series are not named
    with pytest.raises(UnknownMPError, match="'lift'"):
        columns.transition_paths("left_pos", ("grasp", "lift"))
    assert stream.logged == list(paths)  # nothing named for a layout that fails its check

    for tick in range(3):
        columns.add_row(paths, tick, 0.1 * tick, np.arange(6.0))
    columns.add_poses(("box",), 2, 0.2, np.zeros((1, 3)), np.array([[0, 0, 0, 1.0]]))
    columns.send()
    assert stream.sent == [(path, 3) for path in paths] + [("world/box", 1)]
    columns.send()  # the buffers were emptied
    assert len(stream.sent) == len(paths) + 1


def _middle_shares(n_variables: int) -> list[float]:
    """The middle column's row shares of a blueprint for ``n_variables`` variables."""
    series = {f"v{i}": VariableSeries(["a", "b"], ["b"]) for i in range(n_variables)}
    bp = blueprint({"x": ["x0"]}, series, scene=True)
    columns = bp.root_container.contents
    return list(columns[1].row_shares)


@pytest.mark.parametrize("n", [1, 2, 6, 10])
def test_the_state_lanes_grow_with_the_variables(n: int) -> None:
    """Every lane a share of the middle column (at least the three a lane or two always had),
    so the simulator's six variables show without scrolling; the other rows keep theirs."""
    shares = _middle_shares(n)
    assert shares[0] == pytest.approx(max(3.0, LANE_SHARE * n))
    rows = -(-n // 3)  # the overview grid: three plots a row
    assert shares[1:] == pytest.approx([2.0 * rows, 3.0, 4.0])


def _widths(bp: object, viewer: float) -> list[float]:
    """The columns' widths [px] of a blueprint's root in a ``viewer`` px wide viewer."""
    shares = list(bp.root_container.column_shares)  # type: ignore[attr-defined]
    return [viewer * share / sum(shares) for share in shares]


def _names(container: object) -> list[str]:
    """The names of the views in ``container`` (a view: its own), depth first."""
    if not isinstance(container, rrb.Container):
        return [container.name]  # type: ignore[attr-defined]
    return [name for child in container.contents for name in _names(child)]


@pytest.mark.parametrize("scene", [True, False])
def test_the_start_tables_fit_their_column_at_1440_px(scene: bool) -> None:
    """A laptop's 1440 px wide viewer: the start document (its tables START_TABLE_WIDTH px) and
    the start map are tabs beside the events log, the right column, wide enough for them; the
    left column (the status document), where they cut the training starts' last column, is
    not. A wrong start's start document has the middle column, wider still."""
    series = {f"v{i}": VariableSeries(["a", "b"], ["b"]) for i in range(6)}
    bp = blueprint({"x": ["x0"]}, series, start=True, scene=scene)
    left, _, right = bp.root_container.contents
    assert list(bp.root_container.column_shares) == list(COLUMN_SHARES)
    assert _names(right) == ["events", "active MP log", "start", "start map"]
    assert right.active_tab == 0  # the events log shows as the recording opens
    assert _names(left) == (["scene", "status"] if scene else ["status"])
    widths = _widths(bp, 1440)
    assert widths[2] >= START_TABLE_WIDTH > widths[0]
    wrong = blueprint({"x": ["x0"]}, series, start=True, start_focus=True, scene=scene)
    middle = wrong.root_container.contents[1]
    assert _names(middle) == ["start"]
    assert _widths(wrong, 1440)[1] >= START_TABLE_WIDTH
    # without a start decision: the events log and its neighbour tab alone
    plain = blueprint({"x": ["x0"]}, series, scene=scene)
    assert _names(plain.root_container.contents[2]) == ["events", "active MP log"]
