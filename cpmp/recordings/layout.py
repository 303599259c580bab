"""The layout of an episode recording, shared by the writer and the reader.

The table is in :mod:`cpmp.recordings`: entity paths and the names of the machine-readable
records, the text of the log lines and of the ``status`` document, the feature panels
(:func:`group_features`), the viewer's default blueprint (:func:`blueprint`) and the 3D scene
(static geoms, per-tick body poses).
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from cpmp.errors import ConfigError, CpmpError, DataError, UnknownMPError

GEOM_TYPES = ("box", "capsule", "sphere", "cylinder")
"""Geom types :class:`~cpmp.recordings.EpisodeRecorder` can draw."""

TOUCH_WORDS = ("contact", "contacts", "touch", "touching", "supported", "force", "collision")
"""A feature whose name has one of these words (between ``_``/``.``/``-``/``/``) goes into the
``touch`` panel (see :func:`group_features`)."""

MAX_SERIES_PER_PANEL = 8
"""Default largest number of features :func:`group_features` puts into one plot panel."""

TOUCH_GROUP = "touch"
OTHER_GROUP = "other"

TRANSITION_ARCHETYPE = "cpmp.Transition"
"""Name of the machine-readable transition record (columns ``cpmp.Transition:<field>``)."""
OUTCOME_ARCHETYPE = "cpmp.Outcome"
"""Name of the machine-readable outcome record."""
NOTE_ARCHETYPE = "cpmp.Note"
"""Name of the machine-readable sequencer-note record."""
PROPERTY_NAME = "cpmp"
"""Name of the recording property holding the episode, features, MP names and metadata."""
STATUS_ENTITY = "status"
"""Entity of the markdown ``status`` document."""

_GEOM_MIN_SIZE = {"box": 3, "capsule": 2, "sphere": 1, "cylinder": 2}
_DEFAULT_RGBA = (0.6, 0.6, 0.6, 1.0)
_TOKEN = re.compile(r"[^._\-/\s]+")


def entity(*parts: str) -> str:
    """The entity path of ``parts``, each escaped (a part may hold ``/``, spaces, ...)."""
    return "/".join(rr.escape_entity_path_part(part) for part in parts)


def check_mp(mp_names: Mapping[str, Sequence[str]], variable: str, mp: str | None = None) -> None:
    """Check that ``variable`` is a control variable of ``mp_names`` and ``mp`` one of its MPs.

    Raises:
        UnknownMPError: ``variable`` or ``mp`` (when given) is unknown.
    """
    if variable not in mp_names:
        raise UnknownMPError(f"unknown control variable {variable!r}; known: {sorted(mp_names)}")
    if mp is not None and mp not in mp_names[variable]:
        raise UnknownMPError(
            f"unknown MP {mp!r} for variable {variable!r}; known: {mp_names[variable]}"
        )


# ------------------------------------------------------------------------- text of the logs
def transition_text(variable: str, source: str, target: str, probability: float, kind: str) -> str:
    """``"left_pos: approach -> grasp (p=0.71)"``, with ``" [recovery]"`` for a recovery."""
    text = f"{variable}: {source} -> {target} (p={probability:.2f})"
    return text if kind == "switch" else f"{text} [{kind}]"


def outcome_text(outcome: str, reason: str) -> str:
    """``"outcome: incomplete (deadlock)"``."""
    return f"outcome: {outcome}" + (f" ({reason})" if reason else "")


def status_markdown(
    episode: str,
    t: float,
    active: Mapping[str, str],
    variables: Sequence[str],
    last_transition: str = "",
    outcome: str = "",
) -> str:
    """The ``status`` document at ``t`` [s], as markdown.

    It shows the active MP of each of ``variables`` (``-`` when none yet), the last
    transition and the outcome text.
    """
    lines = [f"**{episode}** · t = {t:.2f} s", "", "| variable | active MP |", "|---|---|"]
    lines += [f"| {var} | {active.get(var, '-')} |" for var in variables]
    if last_transition:
        lines += ["", f"last transition: {last_transition}"]
    if outcome:
        lines += ["", f"**{outcome}**"]
    return "\n".join(lines)


# --------------------------------------------------------------------------- feature panels
def group_features(
    names: Sequence[str],
    *,
    max_series: int = MAX_SERIES_PER_PANEL,
    touch_words: Sequence[str] = TOUCH_WORDS,
) -> dict[str, list[str]]:
    """Group feature names into plot panels, from the names alone.

    A name is split into words at ``_ . - /`` and white space. Names with a word in
    ``touch_words`` (case-insensitive) form the ``touch`` group; the others are grouped by
    their first word (``box_x``, ``box_z`` -> ``box``). A group of more than ``max_series``
    names is split by the next word, and named by the common prefix (``dist.left_rot.home``,
    ``dist.right_rot.home`` -> ``dist.left``, ``dist.right``); names that cannot be split
    further, or only into more than ``max_series`` parts, are cut into numbered parts
    (``arm_q 1``, ``arm_q 2``). Single-name groups are merged into
    ``other`` when there are several. Groups and their members keep the order of ``names``.
    """
    if max_series < 1:
        raise ConfigError(f"max_series must be >= 1, got {max_series}")
    if len(set(names)) != len(names):
        raise ConfigError(f"feature names must be unique, got {list(names)}")
    touch = {word.lower() for word in touch_words}
    tokens = {name: [m.span() for m in _TOKEN.finditer(name)] for name in names}
    touching = [n for n in names if any(n[a:b].lower() in touch for a, b in tokens[n])]
    rest = [n for n in names if n not in set(touching)]

    def words(name: str, depth: int) -> tuple[str, ...]:
        return tuple(name[a:b] for a, b in tokens[name][:depth])

    def prefix(name: str, depth: int) -> str:
        spans = tokens[name][:depth]
        return name[: spans[-1][1]] if spans else name

    def chunks(key: str, members: list[str]) -> dict[str, list[str]]:
        if len(members) <= max_series:
            return {key: members}
        starts = range(0, len(members), max_series)
        return {f"{key} {i + 1}": members[s : s + max_series] for i, s in enumerate(starts)}

    def split(key: str, members: list[str], depth: int) -> dict[str, list[str]]:
        if len(members) <= max_series:
            return {key: members}
        stay = [n for n in members if len(tokens[n]) <= depth]
        deeper: dict[tuple[str, ...], list[str]] = {}
        for name in members:
            if len(tokens[name]) > depth:
                deeper.setdefault(words(name, depth + 1), []).append(name)
        if not deeper or len(deeper) + bool(stay) > max_series:
            return chunks(key, members)
        if len(deeper) == 1 and not stay:
            (only,) = deeper.values()
            return split(prefix(only[0], depth + 1), only, depth + 1)
        out: dict[str, list[str]] = {}
        if stay:
            _merge(out, split(key, stay, depth))
        for sub in deeper.values():
            _merge(out, split(prefix(sub[0], depth + 1), sub, depth + 1))
        return out

    groups: dict[str, list[str]] = {}
    first: dict[str, list[str]] = {}
    for name in rest:
        first.setdefault(prefix(name, 1), []).append(name)
    for key, members in first.items():
        _merge(groups, split(key, members, 1))
    singles = [key for key, members in groups.items() if len(members) == 1]
    if len(singles) > 1:
        _merge(groups, chunks(OTHER_GROUP, [groups.pop(key)[0] for key in singles]))
    if touching:
        _merge(groups, chunks(TOUCH_GROUP, touching))
    order = {name: i for i, name in enumerate(names)}
    for members in groups.values():
        members.sort(key=order.__getitem__)
    return dict(sorted(groups.items(), key=lambda item: order[item[1][0]]))


def _merge(groups: dict[str, list[str]], more: Mapping[str, list[str]]) -> None:
    """Add ``more`` to ``groups`` in place; a name already used gets the members appended."""
    for key, members in more.items():
        groups.setdefault(key, []).extend(members)


def check_feature_groups(
    groups: Mapping[str, Sequence[str]], names: Sequence[str]
) -> dict[str, list[str]]:
    """User-given groups, validated; features in no group are appended as ``other``."""
    out = {str(key): [str(n) for n in members] for key, members in groups.items()}
    seen: set[str] = set()
    for key, members in out.items():
        if not key or not members:
            raise ConfigError(f"feature_groups: group {key!r} needs a name and some features")
        unknown = [n for n in members if n not in names]
        if unknown:
            raise ConfigError(
                f"feature_groups[{key!r}] names unknown features {unknown}; known: {list(names)}"
            )
        twice = seen.intersection(members)
        if twice or len(set(members)) != len(members):
            raise ConfigError(f"feature_groups: features {sorted(twice)} are in several groups")
        seen.update(members)
    missing = [n for n in names if n not in seen]
    if missing:
        out.setdefault(OTHER_GROUP, []).extend(missing)
    return out


# -------------------------------------------------------------------------------- blueprint
def blueprint(feature_groups: Mapping[str, Sequence[str]], variables: Sequence[str]) -> Any:
    """The viewer's default layout (an ``rrb.Blueprint``).

    Scene and status | feature panels (one per group of ``feature_groups``) and per-variable
    probabilities (a tab per control variable of ``variables``) | active MPs and events. Every
    plot has few series (rerun's legend sits in its bottom-right corner).
    """
    unit = rrb.ScalarAxis(range=(0.0, 1.0))
    feature_views = [
        rrb.TimeSeriesView(
            origin="features",
            contents=[f"+ {entity('features', name)}" for name in members],
            name=group,
        )
        for group, members in feature_groups.items()
    ] or [rrb.TimeSeriesView(origin="features", name="features")]
    variable_tabs = [
        rrb.Grid(
            rrb.TimeSeriesView(
                origin=entity("progress", var),
                contents="+ $origin/*/phi",
                name=f"{var}: progress φ (= exit)",
                axis_y=unit,
            ),
            rrb.TimeSeriesView(
                origin=entity("progress", var),
                contents="+ $origin/*/entry",
                name=f"{var}: entry 1 - φ",
                axis_y=unit,
            ),
            rrb.TimeSeriesView(
                origin=entity("transition", var),
                name=f"{var}: transition probabilities",
                axis_y=unit,
            ),
            name=var,
        )
        for var in variables
    ]
    body_first = rrb.TextLogColumns(
        timeline_columns=[rrb.encodings.TimelineColumn("time")],
        text_log_columns=[
            rrb.encodings.TextLogColumn("body"),
            rrb.encodings.TextLogColumn("loglevel"),
            rrb.encodings.TextLogColumn("entitypath", visible=False),
        ],
    )
    middle = [rrb.Grid(*feature_views, name="features")]
    if variable_tabs:
        middle.append(rrb.Tabs(*variable_tabs, name="probabilities"))
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial3DView(origin="world", name="scene"),
                rrb.TextDocumentView(origin=STATUS_ENTITY, name="status"),
                row_shares=[3, 2],
            ),
            rrb.Vertical(*middle, row_shares=[3, 2][: len(middle)]),
            rrb.Vertical(
                rrb.StateTimelineView(origin="active", name="active MPs"),
                rrb.Tabs(
                    rrb.TextLogView(
                        origin="events",
                        contents=[
                            "+ events/transitions",
                            "+ events/notes",
                            "+ events/outcome",
                        ],
                        name="events",
                        columns=body_first,
                    ),
                    rrb.TextLogView(origin="active", name="active MP log", columns=body_first),
                ),
                row_shares=[2, 3],
            ),
            column_shares=[2, 3, 2],
        ),
        # Room for the views; the full time panel stays: its rows mark every event.
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(state="expanded"),
    )


# ----------------------------------------------------------------------------- the 3D scene
def _as_vector(value: Any, size: int, what: str, error: type[CpmpError]) -> np.ndarray:
    array = np.asarray(value, dtype=float)
    if array.shape != (size,):
        raise error(f"{what} must have shape ({size},), got {array.shape}")
    return array


def _wxyz_to_xyzw(quat_wxyz: np.ndarray) -> np.ndarray:
    return quat_wxyz[[1, 2, 3, 0]]


def parse_geom(index: int, geom: Mapping[str, Any]) -> dict[str, Any]:
    """Geom ``index`` of the recorder's ``geoms``, validated and completed with its defaults.

    The result has ``body``, ``name``, ``type``, ``size`` (list), ``pos`` (3,) [m], ``quat``
    (4,) wxyz and ``rgba`` (4,) uint8.
    """
    where = f"geoms[{index}]"
    kind = geom.get("type")
    if kind not in GEOM_TYPES:
        raise ConfigError(f"{where}: type must be one of {GEOM_TYPES}, got {kind!r}")
    if "body" not in geom:
        raise ConfigError(f"{where}: missing 'body'")
    size = np.asarray(geom.get("size", ()), dtype=float).ravel()
    if size.size < _GEOM_MIN_SIZE[kind] or not np.all(np.isfinite(size)):
        raise ConfigError(
            f"{where}: a {kind} needs at least {_GEOM_MIN_SIZE[kind]} finite size values, "
            f"got {size.tolist()}"
        )
    pos = _as_vector(geom.get("pos", (0.0, 0.0, 0.0)), 3, f"{where} pos", ConfigError)
    quat = _as_vector(geom.get("quat", (1.0, 0.0, 0.0, 0.0)), 4, f"{where} quat", ConfigError)
    rgba = _as_vector(geom.get("rgba", _DEFAULT_RGBA), 4, f"{where} rgba", ConfigError)
    return {
        "body": str(geom["body"]),
        "name": str(geom.get("name", f"geom_{index}")),
        "type": kind,
        "size": size.tolist(),
        "pos": pos,
        "quat": quat,
        "rgba": np.round(np.clip(rgba, 0.0, 1.0) * 255).astype(np.uint8),
    }


def geom_archetypes(geom: Mapping[str, Any]) -> tuple[Any, Any]:
    """The static ``Transform3D`` (pose in the body frame) and shape of a parsed geom.

    Both are logged at ``world/<body>/<name>`` for a geom of :func:`parse_geom`.
    """
    size, color = geom["size"], geom["rgba"]
    kind = geom["type"]
    if kind == "box":
        shape = rr.Boxes3D(half_sizes=[size[:3]], colors=[color], fill_mode="solid")
    elif kind == "sphere":
        shape = rr.Ellipsoids3D(half_sizes=[[size[0]] * 3], colors=[color], fill_mode="solid")
    elif kind == "cylinder":
        shape = rr.Cylinders3D(
            lengths=[2 * size[1]], radii=[size[0]], colors=[color], fill_mode="solid"
        )
    else:
        # rerun capsules run from z = 0 to z = length; MuJoCo's are centred on the geom frame.
        shape = rr.Capsules3D(
            lengths=[2 * size[1]],
            radii=[size[0]],
            translations=[[0.0, 0.0, -size[1]]],
            colors=[color],
            fill_mode="solid",
        )
    local = rr.Transform3D(translation=geom["pos"], quaternion=_wxyz_to_xyzw(geom["quat"]))
    return local, shape


def pose_rows(
    body_poses: Mapping[str, tuple[Any, Any]],
) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
    """Body names, positions (B, 3) [m] and xyzw quaternions (B, 4) of wxyz ``body_poses``.

    Raises:
        DataError: a malformed pose, naming its body.
    """
    bodies = tuple(str(body) for body in body_poses)
    try:
        positions = np.array([pos for pos, _ in body_poses.values()], dtype=float)
        quats = np.array([quat for _, quat in body_poses.values()], dtype=float)
    except (TypeError, ValueError):
        positions = quats = np.empty(0)
    if positions.shape != (len(bodies), 3) or quats.shape != (len(bodies), 4):
        for body, (pos, quat) in body_poses.items():
            _as_vector(pos, 3, f"position of body {body!r}", DataError)
            _as_vector(quat, 4, f"quaternion (wxyz) of body {body!r}", DataError)
        raise DataError("body_poses must map each body to (position (3,), quaternion (4,))")
    return bodies, positions, quats[:, [1, 2, 3, 0]]


__all__ = [
    "GEOM_TYPES",
    "MAX_SERIES_PER_PANEL",
    "TOUCH_WORDS",
    "group_features",
    "outcome_text",
    "transition_text",
]
