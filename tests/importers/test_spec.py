"""Mapping records: YAML loading, validation on construction, and the train/test split."""

import pytest
from conftest import BAG_MAPPING, LEROBOT_MAPPING, MIMICGEN_MAPPING

from cpmp.errors import ConfigError, CpmpFileError
from cpmp.importers import (
    EffectorLabel,
    LeRobotSpec,
    MimicGenSpec,
    RosbagSpec,
    SplitSpec,
    Subtask,
    TopicFeature,
    TopicLabel,
    load_mapping,
    make_splits,
)

YAML = """\
source: rosbag
rate: 50
features:
  - {topic: /joint_states, field: position, slice: [0, 2], names: [q0, q1]}
  - {topic: /box_pose, field: pose.position, name: box}
labels:
  right_arm: {topic: /right_arm/mp, rename: {grip: grasp}}
  left_arm: {topic: /left_arm/switch, kind: events, sequence: [hold, push]}
"""


def test_a_yaml_mapping_loads_into_validated_records(tmp_path):
    path = tmp_path / "mapping.yaml"
    path.write_text(YAML)
    spec = load_mapping(path)
    assert isinstance(spec, RosbagSpec)
    assert spec.rate == 50.0 and spec.stamps == "header" and spec.min_activation == 0.0
    first, box = spec.features
    assert first == TopicFeature(
        topic="/joint_states", field="position", slice=(0, 2), names=("q0", "q1")
    )
    assert box.default_prefix == "box_pose.pose.position" and box.name == "box"
    right, left = spec.labels
    assert right.variable == "right_arm" and right.rename == {"grip": "grasp"}
    assert left.sequence == ("hold", "push") and left.kind == "events"


def test_every_example_mapping_parses():
    assert isinstance(load_mapping(BAG_MAPPING), RosbagSpec)
    assert isinstance(load_mapping(LEROBOT_MAPPING), LeRobotSpec)
    spec = load_mapping(MIMICGEN_MAPPING)
    assert isinstance(spec, MimicGenSpec)
    assert spec.labels[0].subtasks[-1] == Subtask("lift")


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("source: ros\n", "source must be one of rosbag, lerobot, mimicgen, got 'ros'"),
        ("- a\n- b\n", "must be a mapping with a source key"),
        (
            "source: rosbag\nrate: 50\nfeatures: []\nlabels: {a: {topic: /a}}\n",
            "features must be a non-empty list",
        ),
        (
            "source: rosbag\nrate: 50\nfeatures: [{topic: /a, fields: x}]\n"
            "labels: {a: {topic: /a}}\n",
            r"features\[0\]: unknown key\(s\) fields; known keys: index, slice, names, name, "
            "topic, field, joints",
        ),
        (
            "source: rosbag\nfeatures: [{topic: /a}]\nlabels: {a: {topic: /a}}\n",
            "missing 1 required keyword-only argument: 'rate'",
        ),
        ("source: rosbag\n  bad: [indent\n", "is not valid YAML"),
    ],
)
def test_bad_yaml_mappings_name_the_problem(tmp_path, text, match):
    path = tmp_path / "mapping.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=match):
        load_mapping(path)


def test_a_missing_mapping_file_is_a_file_error(tmp_path):
    with pytest.raises(CpmpFileError, match=r"mapping file .*nope.yaml does not exist"):
        load_mapping(tmp_path / "nope.yaml")


@pytest.mark.parametrize(
    ("build", "match"),
    [
        (
            lambda: TopicFeature(topic="/a", index=[0], slice=[0, 2]),
            "give index or slice, not both",
        ),
        (lambda: TopicFeature(topic="/a", slice=[3, 1]), r"slice must be \[start, stop\]"),
        (lambda: TopicFeature(topic="/a", index=[0, 1], names=["x"]), "names has 1 entries but 2"),
        (lambda: TopicFeature(topic="/a", joints=["j"], index=[0]), "give joints, index or slice"),
        (lambda: TopicFeature(topic="/a", names=["x", "x"]), "repeats x"),
        (lambda: TopicLabel(variable="a/b", topic="/a"), "must not contain '/'"),
        (
            lambda: TopicLabel(variable="a", topic="/a", kind="toggle"),
            "kind must be one of state, events",
        ),
        (lambda: TopicLabel(variable="a", topic="/a", sequence=["x", "y"]), "are for kind: events"),
        (
            lambda: TopicLabel(variable="a", topic="/a", kind="events", sequence=["x"]),
            "sequence must list at least two MPs",
        ),
        (lambda: EffectorLabel(variable="a"), "give subtasks: .* or dataset: "),
        (
            lambda: EffectorLabel(
                variable="a",
                subtasks=[{"mp": "x", "signal": "s"}, {"mp": "y", "signal": "s"}, {"mp": "z"}],
            ),
            r"signal\(s\) s end two subtasks",
        ),
        (
            lambda: RosbagSpec(
                features=[
                    TopicFeature(topic="/a", names=["x"]),
                    TopicFeature(topic="/b", names=["x"]),
                ],
                labels=[TopicLabel(variable="v", topic="/c")],
                rate=10,
            ),
            r"feature name\(s\) x given twice",
        ),
        (
            lambda: RosbagSpec(
                features=[TopicFeature(topic="/a")],
                labels=[TopicLabel(variable="v", topic="/c")],
                rate=10,
                min_activation=-1,
            ),
            "min_activation must be >= 0",
        ),
        (lambda: MimicGenSpec(features=[], labels=[], rate=20), "the mapping has no features"),
        (lambda: SplitSpec(test_fraction=1.0), "test_fraction must be < 1"),
        (lambda: SplitSpec(test_fraction=0.2, test=["demo_0"]), "not both"),
        (lambda: SplitSpec(seed=1.5), "seed must be an integer"),
    ],
)
def test_records_validate_on_construction(build, match):
    with pytest.raises(ConfigError, match=match):
        build()


def test_splits_are_seeded_and_keep_one_demonstration_to_train():
    names = [f"demo_{k}" for k in range(10)]
    a = make_splits(names, SplitSpec(test_fraction=0.3, seed=4))
    assert a == make_splits(names, SplitSpec(test_fraction=0.3, seed=4))
    assert len(a["test"]) == 3 and sorted(a["train"] + a["test"]) == sorted(names)
    assert a["train"] == [n for n in names if n in a["train"]]  # the given order
    others = [make_splits(names, SplitSpec(test_fraction=0.3, seed=s))["test"] for s in range(5)]
    assert len({tuple(t) for t in others}) > 1  # the seed matters
    two = make_splits(names[:2], SplitSpec(test_fraction=0.9))  # 0.9 of 2 would hold out both
    assert (len(two["train"]), len(two["test"])) == (1, 1)
    assert make_splits(names, SplitSpec()) == {"train": names}
    assert make_splits(names, SplitSpec(test=("demo_4",)))["test"] == ["demo_4"]
    with pytest.raises(ConfigError, match="split: test names 'demo_x'"):
        make_splits(names, SplitSpec(test=("demo_x",)))
    with pytest.raises(ConfigError, match="needs at least 2 demonstrations"):
        make_splits(names[:1], SplitSpec(test_fraction=0.5))


def test_on_error_derive_and_the_lerobot_label_sources_are_validated():
    spec = load_mapping({**MIMICGEN_MAPPING, "on_error": "skip"})
    assert spec.on_error == "skip" and load_mapping(MIMICGEN_MAPPING).on_error == "raise"
    with pytest.raises(ConfigError, match="on_error must be one of raise, skip, got 'ignore'"):
        load_mapping({**LEROBOT_MAPPING, "on_error": "ignore"})
    with pytest.raises(ConfigError, match="derive must be one of velocity, got 'speed'"):
        load_mapping({**LEROBOT_MAPPING, "features": [{"column": "a", "derive": "speed"}]})
    labels = {"a": {"language": "motion"}, "b": {"sarm": "dense"}, "c": {"column": "x"}}
    spec = load_mapping({**LEROBOT_MAPPING, "labels": labels})
    assert [lab.source for lab in spec.labels] == [
        "language_persistent (style motion)",
        "SARM dense_subtask_* annotations",
        "column x",
    ]
    with pytest.raises(ConfigError, match="sarm must be one of sparse, dense, got 'fine'"):
        load_mapping({**LEROBOT_MAPPING, "labels": {"a": {"sarm": "fine"}}})
    with pytest.raises(ConfigError, match=r"give exactly one of column: .* got none"):
        load_mapping({**LEROBOT_MAPPING, "labels": {"a": {"rename": {"x": "y"}}}})
