"""The layout of an episode recording, shared by the writer and the reader.

The table is in :mod:`cpmp.recordings`: entity paths and the names of the machine-readable
records, the text of the log lines and of the ``status`` document, the feature panels
(:func:`group_features`), the viewer's default blueprint (:func:`blueprint`) and the 3D scene
(static geoms, per-tick body poses).
"""

from __future__ import annotations

import math
import re
import textwrap
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Literal, NamedTuple, Protocol, TypedDict

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from cpmp.errors import ConfigError, CpmpError, DataError, UnknownMPError
from cpmp.records import StartDecision

if TYPE_CHECKING:
    import numpy.typing as npt

GEOM_TYPES = ("box", "capsule", "sphere", "cylinder")
"""Geom types :class:`~cpmp.recordings.EpisodeRecorder` can draw."""

TOUCH_WORDS = ("contact", "contacts", "touch", "touching", "supported", "force", "collision")
"""A feature whose name has one of these words (between ``_``/``.``/``-``/``/``) goes into the
``touch`` panel (see :func:`group_features`)."""

MAX_SERIES_PER_PANEL = 8
"""Default largest number of features :func:`group_features` puts into one plot panel."""

TOUCH_GROUP = "touch"
OTHER_GROUP = "other"

PALETTE: tuple[tuple[int, int, int], ...] = (
    (31, 119, 180),
    (255, 127, 14),
    (44, 160, 44),
    (214, 39, 40),
    (148, 103, 189),
    (140, 86, 75),
    (227, 119, 194),
    (127, 127, 127),
    (188, 189, 34),
    (23, 190, 207),
)
"""Series colours (matplotlib's ``tab10``): series ``i`` of a panel gets ``PALETTE[i % 10]``, so
the series of one panel differ (rerun's own colours, from the entity path, repeat); an MP keeps
its colour in its variable's φ, entry and transition panels."""

LEGEND_CORNER = "LeftTop"
"""Where the legend of a plot with one sits (rerun's default, bottom right, covers the ends of
the φ curves)."""

LEGEND_SPACE_NARROW = 0.35
"""Share of a narrow plot's width (a variable's tab: three plots side by side) left empty
before t = 0 for its legend: rerun 0.41 places a legend only inside a plot, in a corner, so a
plot with a legend starts its time axis early and the legend (in :data:`LEGEND_CORNER`) sits
left of the curves (:func:`legend_time_axis`; y-axis headroom above 1 was tried first: the
legend of four MPs needs half a tab plot's height at 1920×1080)."""
LEGEND_SPACE_WIDE = 0.12
"""The same for a plot the column's width (a feature panel)."""

THRESHOLD_ENTITY = "threshold"
"""Scalar series of the switching rule's threshold, drawn as a grey line in every p plot."""
THRESHOLD_COLOR = (90, 90, 90)

MARKS_ENTITY = "marks"
"""Origin of the event marks: ``marks/<variable>/<kind>``, one point at the event's p."""
MARK_STYLES: dict[str, tuple[tuple[int, int, int], str]] = {
    "switch": ((0, 0, 0), "Diamond"),
    "recovery": ((204, 85, 0), "Cross"),
    "hold": ((110, 110, 110), "Down"),
}
"""Event kind -> (colour, marker shape) of its marks on the p(switch) plots."""
MARK_SIZE = 5.0
OVERVIEW_NAME = "p(switch), every variable"
"""Name of the grid of every variable's p(switch) plot (small multiples, no clicking)."""

LANE_SHARE = 1.0
"""Share of the middle column per state lane (one per control variable), three at least:
the lanes' view next to the overview (2 per row of three), the feature tabs (3) and the
probability tabs (4). Six variables (the simulator) then show every lane unscrolled in a
900 px tall viewer; with a fixed share of 3 they showed four at 1080 px."""

EVENT_WIDTH = 58
"""Characters per line of the events log, its time included (:func:`event_lines`). rerun 0.41
shows the first line of a multi-line text log entry only, so a long event is logged as
several rows; the log's monospace body column shows about 60 characters in the default layout
of a 1440 px wide viewer (a laptop's; a row of 62 lost its last 2) and about 82 at 1920 px, so
no row is cut at either."""

COLUMN_SHARES = (2.0, 4.0, 3.0)
"""Shares of the viewer's width: the scene above the ``status`` document | the lanes and plots
| the events log, with the ``start`` document and the start map in tabs beside it (a wrong
start's layout: the start document in the middle). Of a 1440 px wide viewer (a laptop's) the
left column gets 320 px, the right 480 px."""

START_TABLE_WIDTH = 360
"""Pixels the ``start`` document's tables need in rerun 0.41's web viewer, the panel's margins
and some room for longer MP names included: the simulator's training starts (box width and
depth [m], distance, start number) take about 320 px, its three demonstrated starts (a column
each) about 290 px. The column holding the start tabs is at least this wide at 1440 px: beside
the ``status`` document (the left column, 320 px) the training starts lost their last column;
in the right column (480 px) both tables show whole at 1440×900 and 1920×1080."""

EVENT_INDENT = 10
"""Continuation lines of an event start below its text, after the time (``"  3.25 s  "``)."""

WARN_COLOR = (204, 85, 0)
"""Text colour of the events log's warnings (recoveries, give-ups, a failed outcome): the
level column is hidden to leave the text the width."""

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
EVENT_ORDER = ("events/start", "events/transitions", "events/notes", "events/outcome")
"""The entities of the events log (text lines and machine-readable records)."""
START_ARCHETYPE = "cpmp.Start"
"""Name of the machine-readable start-decision record (at ``events/start``)."""
START_ENTITY = "start"
"""Entity of the markdown document of the start decision."""
START_BOXES_ENTITY = "start/boxes"
"""Origin of the 2D plot of the episode's start state against the training starts."""

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
def series_color(index: int) -> tuple[int, int, int]:
    """The colour of series ``index`` of a panel (:data:`PALETTE`, cycled)."""
    return PALETTE[index % len(PALETTE)]


def transition_text(variable: str, source: str, target: str, probability: float, kind: str) -> str:
    """``"left_pos: approach -> grasp (p=0.71) [switch]"``, tagged with the switch's kind."""
    return f"{variable}: {source} -> {target} (p={probability:.2f}) [{kind}]"


def event_lines(t: float, text: str, width: int = EVENT_WIDTH) -> list[str]:
    """The rows of one event in the events log: ``"  3.25 s  <text>"``, wrapped at ``width``.

    The time is in the text itself (the log's own time column is hidden: the viewer cuts it to
    ``+3…``); continuation rows are indented by :data:`EVENT_INDENT` so that the text reads
    as one block below its time. No row is longer than ``width`` characters (a word longer than
    a line is broken).

    Args:
        t: the event's time [s].
        text: the event, any length.
        width: characters per row (at least :data:`EVENT_INDENT` + 10).

    Returns:
        The rows, the first starting with the time.

    Raises:
        ConfigError: ``width`` leaves too little room for the text.
    """
    if width < EVENT_INDENT + 10:
        raise ConfigError(f"event width must be >= {EVENT_INDENT + 10} characters, got {width}")
    head = f"{t:6.2f} s  "
    indent = " " * max(EVENT_INDENT, len(head))
    return textwrap.wrap(
        " ".join(text.split()),
        width,
        initial_indent=head,
        subsequent_indent=indent,
        break_on_hyphens=False,
    ) or [head.rstrip()]


def start_text(decision: StartDecision) -> str:
    """One line for the events log: the rule, the MPs chosen, their score and the runner-up.

    ``"start (joint rule, 3 demonstrated starts): left_pos=reach_edge, ... (log p -0.12; next
    best -2.31: left_pos=idle, ...)"``.
    """
    ranked = sorted(decision.options, key=lambda o: -o.score)
    chosen = _combination_text(decision.chosen)
    if decision.rule != "independent":
        differ = _differing([o.combination for o in decision.options]) or None
        chosen = _combination_text(decision.chosen, differ)
        count = len(decision.options)
        head = f"start ({decision.rule} rule, {count} demonstrated starts): {chosen}"
        best = ranked[0].score if ranked else math.nan
        others = [o for o in ranked if o.combination != decision.chosen]
        tail = f"log p {best:.2f}"
        if others:
            runner_up = _combination_text(others[0].combination, differ)
            tail += f"; next best {others[0].score:.2f}: {runner_up}"
        return f"{head} ({tail})"
    return f"start (independent rule, each variable's best initial MP): {chosen}"


def start_table(decision: StartDecision) -> list[str]:
    """Every option of a start decision with its score, best first, the chosen one marked.

    ``["   -0.12  left_pos=reach_edge, right_pos=idle  (chosen)", "   -2.31  ..."]``.
    """
    lines = []
    for option in sorted(decision.options, key=lambda o: -o.score):
        chosen = all(decision.chosen.get(v) == mp for v, mp in option.combination.items())
        mark = "  (chosen)" if chosen else ""
        lines.append(f"{option.score:8.2f}  {_combination_text(option.combination)}{mark}")
    return lines


def _combination_text(combination: Mapping[str, str], only: set[str] | None = None) -> str:
    """``"left_pos=reach_edge, right_pos=idle"`` (the variables in ``only``, if given)."""
    return ", ".join(
        f"{v}={mp}" for v, mp in sorted(combination.items()) if only is None or v in only
    )


def _differing(combinations: Sequence[Mapping[str, str]]) -> set[str]:
    """The variables whose MP is not the same in all of ``combinations``."""
    variables = {v for combo in combinations for v in combo}
    return {v for v in variables if len({combo.get(v) for combo in combinations}) > 1}


def series_label(group: str, name: str) -> str:
    """A feature's legend text in its panel: ``name`` less the panel's name as its prefix.

    ``dist.left_fingers.grasp`` in panel ``dist.left`` is ``fingers.grasp``, ``box_x`` in
    ``box`` is ``x`` (the panel's title says the rest), so the legend stays narrow.
    """
    head, _, tail = group.rpartition(" ")
    prefix = head if head and tail.isdigit() else group
    rest = name[len(prefix) :] if name.startswith(prefix) else ""
    return rest[1:] if len(rest) > 1 and rest[0] in "._-/ " else name


PALETTE_NAMES: tuple[str, ...] = (
    "blue",
    "orange",
    "green",
    "red",
    "purple",
    "brown",
    "pink",
    "grey",
    "olive",
    "cyan",
)
"""The colour of each :data:`PALETTE` entry in words (the start map's colour key)."""


def _matches(combination: Mapping[str, str], partial: Mapping[str, str]) -> bool:
    """Whether ``combination`` agrees with every variable ``partial`` names."""
    return all(combination.get(v) == mp for v, mp in partial.items())


def start_labels(
    decision: StartDecision, references: Sequence[StartReference] = ()
) -> list[dict[str, str]]:
    """The demonstrated starts by number: start ``k`` (from 1) is ``result[k - 1]``.

    The joint rule's options ranked by score come first, then any training start that is none
    of them; the start map colours a training start by this number (:data:`PALETTE`).
    """
    combos: list[dict[str, str]] = []
    if decision.rule != "independent":
        combos = [dict(o.combination) for o in sorted(decision.options, key=lambda o: -o.score)]
    for ref in references:
        if ref.combination not in combos:
            combos.append(dict(ref.combination))
    return combos


def _start_number(combos: Sequence[Mapping[str, str]], combination: Mapping[str, str]) -> str:
    """``"2"`` for the start ``combination`` is, ``"–"`` for none."""
    for k, combo in enumerate(combos, start=1):
        if _matches(combo, combination) and _matches(combination, combo):
            return str(k)
    return "–"


def start_markdown(
    decision: StartDecision,
    features: Mapping[str, float],
    references: Sequence[StartReference],
    axes: Sequence[str],
    *,
    correct: Mapping[str, str] | None = None,
    values: Mapping[str, float] | None = None,
    colours: bool = False,
) -> str:
    """The start-decision document: the starts weighed with their scores, the state decided on.

    Args:
        decision: the sequencer's start decision.
        features: feature name -> value at the start (empty if unknown).
        references: the training demonstrations' starts (may be empty).
        axes: what the training starts are compared on (columns of their table): features, or
            keys of ``values`` and of every reference's ``values``; a unit belongs in the name
            (``box_width_m``).
        correct: the initial MPs the demonstrator uses for this episode (some or all
            variables), or ``None`` if unknown: the start it names is marked ``correct``.
        values: the episode's value of each axis that is not a feature.
        colours: whether the start map colours the starts (a ``map colour`` row names them).

    Returns:
        Markdown: the rule and the starts, one column each (score, chosen, correct, map colour,
        each differing variable's MP), the episode's ``axes`` against each training start
        (nearest first) and every feature at the start, grouped as the feature panels are.
    """
    lines = [f"**start decision** at t = {decision.t:.2f} s, rule `{decision.rule}`", ""]
    combos = start_labels(decision, references)
    differ = _differing(combos) if decision.rule != "independent" else None
    if decision.rule != "independent":
        scores = {_start_number(combos, o.combination): o.score for o in decision.options}
        numbers = [str(k) for k in range(1, len(combos) + 1)]
        chosen = _start_number(combos, decision.chosen)
        right = [k for k in numbers if correct and _matches(combos[int(k) - 1], correct)]
        if correct and chosen not in right:
            wanted = ", ".join(right) if right else "none of these"
            lines += [
                f"**Wrong start**: the demonstrator starts this box with "
                f"{_combination_text(correct, differ or None)} (start {wanted}); start "
                f"{chosen} was chosen.",
                "",
            ]
        score = (
            "log-probability of the learned start choice"
            if decision.rule == "learned"
            else "Σ log(1 − φ) of the MPs' nodes (0: every MP surely at its beginning)"
        )
        lines += [
            f"Demonstrated starts; score: {score}.",
            "",
            "| start | " + " | ".join(numbers) + " |",
            "|---|" + "---|" * len(numbers),
            "| score | "
            + " | ".join(f"{scores[k]:.2f}" if k in scores else "–" for k in numbers)
            + " |",
            "| chosen | " + " | ".join("**chosen**" if k == chosen else "" for k in numbers) + " |",
        ]
        if correct:
            lines.append(
                "| correct | "
                + " | ".join("**correct**" if k in right else "" for k in numbers)
                + " |"
            )
        if colours:
            lines.append(
                "| map colour | "
                + " | ".join(PALETTE_NAMES[(int(k) - 1) % len(PALETTE)] for k in numbers)
                + " |"
            )
        for variable in sorted(differ or ()):
            lines.append(
                f"| {variable} | " + " | ".join(c.get(variable, "–") for c in combos) + " |"
            )
        same = {v: mp for v, mp in decision.chosen.items() if v not in (differ or ())}
        if same:
            lines += ["", f"The same in every start: {_combination_text(same)}."]
    else:
        lines += [
            "Each variable's initial MPs, scored by log(1 − φ) of their nodes:",
            "",
            "| | score | initial MP |",
            "|---|---|---|",
        ]
        for option in sorted(decision.options, key=lambda o: -o.score):
            mark = "**chosen**" if _matches(decision.chosen, option.combination) else ""
            lines.append(
                f"| {mark} | {option.score:.2f} | {_combination_text(option.combination)} |"
            )
        if correct:
            lines += ["", f"The demonstrator starts this box with {_combination_text(correct)}."]
    here = {**features, **(values or {})}
    shown = [a for a in axes if a in here]
    nearest = reference_distances(here, references, axes)
    if nearest:
        lines += [
            "",
            "This episode against the training starts (dist.: distance in training ranges):",
            "",
            "| | " + " | ".join(shown) + " | dist. | start |",
            "|---|" + "---|" * (len(shown) + 2),
            "| **episode** | "
            + " | ".join(f"{here[a]:.3f}" for a in shown)
            + f" | 0 | {_start_number(combos, decision.chosen)} |",
        ]
        for ref, dist in nearest:
            row = " | ".join(f"{ref.values[a]:.3f}" for a in shown)
            lines.append(
                f"| {ref.name} | {row} | {dist:.2f} | {_start_number(combos, ref.combination)} |"
            )
    if features:
        lines += ["", "Features at the start (as the sequencer sees them):", ""]
        groups = group_features(list(features))
        lines += [
            f"- **{group}**: " + ", ".join(f"{n} {features[n]:.3f}" for n in members)
            for group, members in groups.items()
        ]
    return "\n".join(lines)


def reference_distances(
    here: Mapping[str, float], references: Sequence[StartReference], axes: Sequence[str]
) -> list[tuple[StartReference, float]]:
    """The training starts with their distance to this episode's, nearest first.

    Args:
        here: the episode's value of each axis (features and given values).
        references: the training demonstrations' starts.
        axes: what they are compared on; axes ``here`` lacks are left out.

    Returns:
        ``(reference, distance)`` pairs, nearest first; the distance is Euclidean over the
        axes, each in units of its range over the references (1 where they all agree). Empty
        without references or a shared axis.
    """
    shown = [a for a in axes if a in here]
    if not references or not shown:
        return []
    point = np.array([here[a] for a in shown])
    scale = np.ptp([[r.values[a] for a in shown] for r in references], axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    pairs = [
        (ref, float(np.linalg.norm((np.array([ref.values[a] for a in shown]) - point) / scale)))
        for ref in references
    ]
    return sorted(pairs, key=lambda pair: pair[1])


def _ticks(lo: float, hi: float) -> np.ndarray:
    """Round tick values (1, 2 or 5 times a power of ten apart) inside ``[lo, hi]``: 3 to 6."""
    span = max(hi - lo, 1e-9)
    for step in sorted(m * 10.0**e for e in range(-6, 7) for m in (1, 2, 5)):
        ticks = np.arange(math.ceil(lo / step), math.floor(hi / step) + 1) * step
        if len(ticks) <= 6:
            return np.round(ticks, 10)
    return np.array([lo, lo + span])  # pragma: no cover (a span over 1e7)


class StartMap(NamedTuple):
    """What the start map draws and the part of the plane to show.

    Attributes:
        entities: ``(entity path, archetype)`` pairs, paths under :data:`START_BOXES_ENTITY`.
        x_range: the view's x range (``axes[0]``, with the tick values, the key and margins).
        y_range: the view's y range (downwards: ``-axes[1]``, with the titles and margins).
    """

    entities: list[tuple[str, rr.Points2D | rr.LineStrips2D]]
    x_range: tuple[float, float]
    y_range: tuple[float, float]


def start_map(
    references: Sequence[StartReference],
    axes: Sequence[str],
    here: Sequence[float] | None,
    combos: Sequence[Mapping[str, str]],
) -> StartMap:
    """What :data:`START_BOXES_ENTITY` draws: the starts as dots in two axes, with a frame.

    ``x`` is ``axes[0]`` to the right, ``y`` is ``axes[1]`` upwards (the view's y runs down, so
    the points are logged at ``-y``). A training start is coloured by its start number in
    ``combos`` (:func:`start_labels`; :data:`PALETTE`), this episode is the larger black dot.
    The names sit below their dots, on transparent anchors of their own, so that no label
    covers a dot; the frame has tick values, axis titles (the axis names, whose units they
    carry) and a colour key right of its top corner.

    Args:
        references: the training starts (each with both ``axes`` in its values).
        axes: the two axis names.
        here: this episode's values in ``axes``, or ``None``.
        combos: the numbered starts.

    Returns:
        The entities to log and the view's bounds (so that the map fills its view).
    """
    train = np.array([[ref.values[a] for a in axes[:2]] for ref in references], dtype=float)
    points = train if here is None else np.vstack([train, [list(here)[:2]]])
    lo, hi = points.min(axis=0), points.max(axis=0)
    span = float(np.max(hi - lo)) or max(float(np.max(np.abs(points))), 1.0) * 0.1
    # room below and left of the starts for their names above the axes
    lo, hi = lo - 0.25 * span, hi + 0.15 * span
    radius = 0.03 * span
    # from a dot's centre to its label's anchor: the viewer centres a label on its anchor,
    # about 20 px tall, so the anchor sits a dot's radius and half a label below the dot
    gap = radius + 0.07 * span
    ink = (70, 70, 70)

    def flip(xy: np.ndarray) -> np.ndarray:
        return np.column_stack([xy[:, 0], -xy[:, 1]])

    def labels(
        xy: np.ndarray,
        texts: Sequence[str],
        colors: tuple[int, int, int] | Sequence[tuple[int, int, int]] = ink,
    ) -> rr.Points2D:
        # a label takes its point's colour: the anchor is a dot too small to see
        anchors = flip(xy) + np.array([0.0, gap])
        return rr.Points2D(anchors, radii=1e-4 * span, colors=colors, labels=list(texts))

    def number(combination: Mapping[str, str]) -> int:
        return next(k for k, c in enumerate(combos) if dict(c) == dict(combination))

    base = START_BOXES_ENTITY.split("/")
    out: list[tuple[str, rr.Points2D | rr.LineStrips2D]] = [
        (
            entity(*base, "training"),
            rr.Points2D(
                flip(train),
                radii=radius,
                colors=[series_color(number(ref.combination)) for ref in references],
            ),
        ),
        (
            entity(*base, "training_names"),
            labels(
                train,
                [ref.name for ref in references],
                [series_color(number(ref.combination)) for ref in references],
            ),
        ),
    ]
    if here is not None:
        mine = np.array([list(here)[:2]], dtype=float)
        out += [
            (
                entity(*base, "episode"),
                rr.Points2D(flip(mine), radii=1.6 * radius, colors=[(0, 0, 0)]),
            ),
            (
                entity(*base, "episode_name"),
                labels(mine - np.array([0.0, 0.6 * radius]), ["this episode"], (0, 0, 0)),
            ),
        ]
    x_ticks, y_ticks = _ticks(lo[0], hi[0]), _ticks(lo[1], hi[1])
    tick = 0.6 * radius
    frame = [[[lo[0], -lo[1]], [hi[0], -lo[1]]], [[lo[0], -lo[1]], [lo[0], -hi[1]]]]
    frame += [[[x, -lo[1]], [x, -lo[1] + tick]] for x in x_ticks]
    frame += [[[lo[0], -y], [lo[0] - tick, -y]] for y in y_ticks]
    out.append((entity(*base, "axes"), rr.LineStrips2D(frame, colors=[(90, 90, 90)])))
    tick_xy = [[x, lo[1] - tick] for x in x_ticks] + [
        [lo[0] - 0.1 * span, y + gap] for y in y_ticks
    ]
    tick_text = [f"{x:g}" for x in x_ticks] + [f"{y:g}" for y in y_ticks]
    out.append((entity(*base, "tick_values"), labels(np.array(tick_xy), tick_text)))
    titles = np.array([[hi[0], lo[1] - 0.12 * span], [lo[0] + 0.15 * span, hi[1] + 0.25 * span]])
    out.append((entity(*base, "axis_titles"), labels(titles, [f"{axes[0]} →", f"↑ {axes[1]}"])))
    # the key stands right of the frame, where no start is
    keys = np.array([[hi[0] + 0.35 * span, hi[1] - k * 0.4 * span] for k in range(len(combos))])
    out += [
        (
            entity(*base, "key"),
            rr.Points2D(
                flip(keys), radii=radius, colors=[series_color(k) for k in range(len(combos))]
            ),
        ),
        (
            entity(*base, "key_names"),
            labels(
                keys,
                [f"start {k + 1}" for k in range(len(combos))],
                [series_color(k) for k in range(len(combos))],
            ),
        ),
    ]
    x_range = (float(lo[0] - 0.3 * span), float(hi[0] + 0.65 * span))
    y_range = (float(-hi[1] - 0.4 * span), float(-lo[1] + 0.45 * span))
    return StartMap(out, x_range, y_range)


def outcome_text(outcome: str, reason: str) -> str:
    """``"outcome: incomplete (deadlock)"``."""
    return f"outcome: {outcome}" + (f" ({reason})" if reason else "")


HoldEnd = Literal["switch", "hold", "end"]
"""What ended a hold: its variable switched, the coupling held it to another MP, the episode
ended."""


def hold_text(
    text: str,
    start: float,
    end: float,
    ended_by: HoldEnd,
    count: int,
    variable: str,
    then: str = "",
) -> str:
    """A hold note with how long it lasted: ``text`` and ``"; held 0.63 s, until ..."``.

    Args:
        text: the sequencer's note (its reason first).
        start: when the hold was first noted [s].
        end: when it ended [s].
        ended_by: what ended it.
        count: how many times the sequencer noted it (its p dips below the threshold and
            crosses it again while the switch is held).
        variable: the held control variable.
        then: the MP ``variable`` switched to (``switch``) or was held to instead (``hold``).

    Returns:
        ``"<text>; held 0.63 s, until left_fingers switched to relax at 9.91 s (noted 3
        times)"``.
    """
    if ended_by == "switch":
        until = f"until {variable} switched to {then} at {end:.2f} s"
    elif ended_by == "hold":
        until = f"until {end:.2f} s, then held to {then}"
    else:
        until = f"until the episode ended at {end:.2f} s"
    noted = f" (noted {count} times)" if count > 1 else ""
    return f"{text}; held {max(end - start, 0.0):.2f} s, {until}{noted}"


def status_markdown(
    episode: str,
    t: float,
    active: Mapping[str, str],
    variables: Sequence[str],
    last_transition: str = "",
    outcome: str = "",
    last_note: str = "",
    start: str = "",
) -> str:
    """The ``status`` document at ``t`` [s], as markdown.

    It shows the active MP of each of ``variables`` (``-`` when none yet), the outcome, the
    start decision, the last transition and the last sequencer note, the longest, last (the
    events log has every note in full).
    """
    lines = [f"**{episode}** · t = {t:.2f} s", "", "| variable | active MP |", "|---|---|"]
    lines += [f"| {var} | {active.get(var, '-')} |" for var in variables]
    if outcome:
        lines += ["", f"**{outcome}**"]
    if start:
        lines += ["", start]
    if last_transition:
        lines += ["", f"last transition: {last_transition}"]
    if last_note:
        lines += ["", f"last note: {last_note}"]
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
class VariableSeries(NamedTuple):
    """What a recording logged of one control variable's probabilities.

    Attributes:
        progress: the MPs whose φ (and entry 1 - φ) were logged, in ``mp_names`` order.
        targets: the MPs a transition probability was logged to, in ``mp_names`` order.
    """

    progress: list[str]
    targets: list[str]


def blueprint(
    feature_groups: Mapping[str, Sequence[str]],
    series: Mapping[str, VariableSeries],
    *,
    start: bool = False,
    start_focus: bool = False,
    events: Sequence[str] = EVENT_ORDER,
    threshold: bool = False,
    marks: Mapping[str, Sequence[str]] | None = None,
    duration: float | None = None,
    start_bounds: tuple[tuple[float, float], tuple[float, float]] | None = None,
    focus: str | None = None,
    focus_time: tuple[float, float] | None = None,
    scene: bool = True,
) -> rrb.Blueprint:
    """The viewer's default layout (an ``rrb.Blueprint``) for what a recording logged.

    Scene above the ``status`` document | the active MPs as state lanes (:data:`LANE_SHARE` of the
    column's height per variable, so that every lane shows unscrolled) above a tab per feature
    panel (one
    per group of ``feature_groups``: a plot the column's width, whose legend covers little of
    it; six small plots side by side had their legends over a third of their curves) above a
    tab per control variable of ``series`` with its φ (= exit), entry (1 - φ) and transition
    probabilities (one legend, φ's: an MP has its colour in all three) | the events log the
    column's height (monospace, its rows :data:`EVENT_WIDTH` characters at most) and, with
    ``start``, the start decision and its 2D map in tabs beside it (the widest side column,
    :data:`START_TABLE_WIDTH`); the columns' widths are :data:`COLUMN_SHARES`. Every view's
    contents are the logged entity paths themselves (rerun 0.41 matches no wildcard in the
    middle of a path). Between the lanes and the feature tabs, :data:`OVERVIEW_NAME`: a grid
    with a small p(switch) plot per variable (no legend; the variable's tab has it), so the
    variable whose switch never came shows without a click. Every p plot draws the rule's
    threshold (:data:`THRESHOLD_ENTITY`) and the variable's event marks
    (:data:`MARKS_ENTITY`). With the episode's ``duration``, a plot with a legend starts its
    time axis before t = 0 (:func:`legend_time_axis`), so the legend sits left of the curves.
    ``start_focus`` (an episode that
    ended at its first tick, e.g. a wrong start, where the plots would hold one point): the
    start decision takes the middle column instead, its map goes between the lanes and the
    events log on the right. The time panel starts collapsed (one row), the blueprint and
    selection panels too. A failure opens on the variable that failed: ``focus`` picks its tab
    among the per-variable probability tabs, and ``focus_time`` selects the span of its
    pending switch on the time panel (rerun 0.41 has no way to place the time cursor itself).

    Args:
        feature_groups: panel name -> feature names.
        series: variable -> the MPs its φ and transition probabilities were logged for.
        start: whether a start decision was logged (:data:`START_ENTITY`).
        start_focus: lay out the start decision instead of the time series.
        events: the event entities logged (of :data:`EVENT_ORDER`), listed by the events log.
        threshold: whether the threshold series was logged.
        marks: variable -> the event kinds (of :data:`MARK_STYLES`) marked for it.
        duration: the episode's last time [s] (``None``: the viewer's default time axes).
        start_bounds: the start map's (x range, y range) (:class:`StartMap`; ``None``: the
            viewer's default, which leaves most of the view empty).
        focus: the variable whose tab the probability tabs open on (``None``: the first).
        focus_time: (start, end) [s] selected on the time panel (``None``: no selection).
        scene: whether there is a 3D scene (geoms or body poses logged); without one the
            status document takes the left column (a synthetic world).

    Returns:
        The blueprint.
    """
    feature_views = [
        rrb.TimeSeriesView(
            origin="features",
            contents=[f"+ {entity('features', name)}" for name in members],
            name=group,
            plot_legend=rrb.PlotLegend(LEGEND_CORNER),
            axis_x=legend_time_axis(duration, LEGEND_SPACE_WIDE),
        )
        for group, members in feature_groups.items()
    ] or [rrb.TimeSeriesView(origin="features", name="features")]
    extra = {
        var: ([THRESHOLD_ENTITY] if threshold else [])
        + [entity(MARKS_ENTITY, var, kind) for kind in (marks or {}).get(var, ())]
        for var in series
    }
    tab_variables = [var for var, logged in series.items() if logged.progress or logged.targets]
    variable_tabs = [
        _variable_views(var, series[var], extra[var], duration) for var in tab_variables
    ]
    focus_tab = tab_variables.index(focus) if focus in tab_variables else 0
    overview = [
        rrb.TimeSeriesView(
            origin=entity("transition", var),
            contents=[f"+ {entity('transition', var, mp)}" for mp in logged.targets]
            + [f"+ {path}" for path in extra[var]],
            name=var,
            axis_y=rrb.ScalarAxis(range=(0.0, 1.0)),
            plot_legend=rrb.PlotLegend(LEGEND_CORNER, visible=False),
        )
        for var, logged in series.items()
        if logged.targets
    ]
    start_doc = rrb.TextDocumentView(origin=START_ENTITY, name="start")
    start_plot = rrb.Spatial2DView(
        origin=START_BOXES_ENTITY,
        name="start map",
        visual_bounds=None
        if start_bounds is None
        else rrb.VisualBounds2D(x_range=start_bounds[0], y_range=start_bounds[1]),
    )
    status = rrb.TextDocumentView(origin=STATUS_ENTITY, name="status")
    lanes = rrb.StateTimelineView(origin="active", name="active MPs")
    logs = [
        rrb.TextLogView(
            origin="events",
            contents=[f"+ {path}" for path in events] or ["+ events/outcome"],
            name="events",
            columns=_TEXT_FIRST,
            format_options=_MONOSPACE,
        ),
        rrb.TextLogView(
            origin="active", name="active MP log", columns=_TEXT_FIRST, format_options=_MONOSPACE
        ),
    ]
    view3d = rrb.Spatial3DView(origin="world", name="scene")
    if start_focus and start:
        left = rrb.Vertical(view3d, status, row_shares=[1, 1]) if scene else status
        middle = start_doc  # the whole column: every feature at the start without scrolling
        right = rrb.Vertical(lanes, start_plot, rrb.Tabs(*logs), row_shares=[3, 3, 2])
    else:
        # the status document (with the start line) unscrolled below the scene at 900 px
        left = (
            rrb.Vertical(view3d, status, row_shares=[2, 3] if start else [1, 1])
            if scene
            else status
        )
        parts: list[rrb.ContainerLike] = [lanes]
        shares = [max(3.0, LANE_SHARE * len(series))]
        if overview:
            columns = min(len(overview), 3)
            parts.append(rrb.Grid(*overview, grid_columns=columns, name=OVERVIEW_NAME))
            shares.append(2.0 * math.ceil(len(overview) / columns))
        parts.append(rrb.Tabs(*feature_views, name="features", active_tab=0))
        shares.append(3.0)
        if variable_tabs:
            parts.append(rrb.Tabs(*variable_tabs, name="probabilities", active_tab=focus_tab))
            shares.append(4.0)
        middle = rrb.Vertical(*parts, row_shares=shares)
        # the start tabs the column's width and height: its tables uncut (START_TABLE_WIDTH)
        right = rrb.Tabs(*logs, *([start_doc, start_plot] if start else []), active_tab=0)
    return rrb.Blueprint(
        rrb.Horizontal(left, middle, right, column_shares=list(COLUMN_SHARES)),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(
            state="collapsed",
            timeline="time",
            time_selection=None
            if focus_time is None
            else rr.encodings.AbsoluteTimeRange(
                round(focus_time[0] * 1e9), round(focus_time[1] * 1e9)
            ),
        ),
    )


_TEXT_FIRST = rrb.TextLogColumns(
    timeline_columns=[rrb.encodings.TimelineColumn("time", visible=False)],
    text_log_columns=[
        rrb.encodings.TextLogColumn("body"),
        rrb.encodings.TextLogColumn("loglevel", visible=False),
        rrb.encodings.TextLogColumn("entitypath", visible=False),
    ],
)
"""Text logs: the message alone (it carries its time, :func:`event_lines`; warnings in
:data:`WARN_COLOR`), no level or path column: the text gets the width."""

_MONOSPACE = rrb.TextLogFormat(monospace_body=True)
"""Text logs in a monospace font: :data:`EVENT_WIDTH` characters take a known width and an
event's continuation rows line up below its text."""


def legend_time_axis(duration: float | None, space: float) -> rrb.TimeAxis | None:
    """A plot's time axis from before t = 0 to ``duration`` [s], room for its legend.

    The first ``space`` of the plot's width is empty (before t = 0); ``None`` without a
    positive ``duration`` (the viewer's default axis). The viewer can still zoom and pan.
    """
    if duration is None or not duration > 0:
        return None
    before = duration * space / (1.0 - space)
    return rrb.TimeAxis(
        view_range=rrb.TimeRange(
            start=rrb.TimeRangeBoundary.absolute(seconds=-before),
            end=rrb.TimeRangeBoundary.absolute(seconds=duration),
        )
    )


def _variable_views(
    variable: str,
    logged: VariableSeries,
    extra: Sequence[str] = (),
    duration: float | None = None,
) -> rrb.Horizontal:
    """One variable's tab: φ (= exit), entry (1 - φ) and the transition probabilities.

    Only φ shows a legend (entry and the transitions use its colours; its time axis starts
    early to leave it room, :func:`legend_time_axis`); without φ logged, the transitions show
    theirs. ``extra``: entity paths drawn in the transition plot besides (the threshold, the
    event marks).
    """
    unit = rrb.ScalarAxis(range=(0.0, 1.0))
    room = legend_time_axis(duration, LEGEND_SPACE_NARROW)
    views = []
    if logged.progress:
        views += [
            rrb.TimeSeriesView(
                origin=entity("progress", variable),
                contents=[f"+ {entity('progress', variable, mp, 'phi')}" for mp in logged.progress],
                name="φ (exit)",
                axis_y=unit,
                axis_x=room,
                plot_legend=rrb.PlotLegend(LEGEND_CORNER),
            ),
            rrb.TimeSeriesView(
                origin=entity("progress", variable),
                contents=[
                    f"+ {entity('progress', variable, mp, 'entry')}" for mp in logged.progress
                ],
                name="entry 1 − φ",
                axis_y=unit,
                plot_legend=rrb.PlotLegend(LEGEND_CORNER, visible=False),
            ),
        ]
    if logged.targets:
        legend = not logged.progress
        views.append(
            rrb.TimeSeriesView(
                origin=entity("transition", variable),
                contents=[f"+ {entity('transition', variable, mp)}" for mp in logged.targets]
                + [f"+ {path}" for path in extra],
                name="p(switch to)",
                axis_y=unit,
                axis_x=room if legend else None,
                # φ's legend names the colours (an MP keeps its colour in the three panels)
                plot_legend=rrb.PlotLegend(LEGEND_CORNER, visible=legend),
            )
        )
    return rrb.Horizontal(*views, name=variable)


class _ViewContents(Protocol):
    """A view with its contents lines (a :class:`~cpmp.recordings.ViewInfo`)."""

    @property
    def contents(self) -> Sequence[str]: ...


def blueprint_paths(views: Sequence[_ViewContents]) -> list[str]:
    """The entity paths the ``+ path`` lines of ``views``' contents name (no wildcards).

    Args:
        views: :class:`~cpmp.recordings.ViewInfo` of a recording (``read_views``).

    Returns:
        Each path once, in order.
    """
    out: dict[str, None] = {}
    for view in views:
        for line in view.contents:
            if line.startswith("+ ") and "*" not in line and "$origin" not in line:
                out[line[2:].strip()] = None
    return list(out)


class StartReference(NamedTuple):
    """A training demonstration's start, to compare an episode's start against.

    Attributes:
        name: the demonstration's name.
        combination: variable -> its initial MP.
        values: feature name -> value at its first sample.
    """

    name: str
    combination: dict[str, str]
    values: dict[str, float]


# ----------------------------------------------------------------------------- the 3D scene
class ParsedGeom(TypedDict):
    """A geom of :func:`parse_geom`: validated, with its defaults."""

    body: str
    name: str
    type: str
    size: list[float]
    pos: np.ndarray
    quat: np.ndarray
    rgba: np.ndarray


GeomShape = rr.Boxes3D | rr.Ellipsoids3D | rr.Cylinders3D | rr.Capsules3D
"""The shape archetype of a geom (:func:`geom_archetypes`)."""


def _as_vector(value: npt.ArrayLike, size: int, what: str, error: type[CpmpError]) -> np.ndarray:
    array = np.asarray(value, dtype=float)
    if array.shape != (size,):
        raise error(f"{what} must have shape ({size},), got {array.shape}")
    return array


def _wxyz_to_xyzw(quat_wxyz: np.ndarray) -> np.ndarray:
    return quat_wxyz[[1, 2, 3, 0]]


def parse_geom(index: int, geom: Mapping[str, str | npt.ArrayLike]) -> ParsedGeom:
    """Geom ``index`` of the recorder's ``geoms``, validated and completed with its defaults.

    The result has ``body``, ``name``, ``type``, ``size`` (list), ``pos`` (3,) [m], ``quat``
    (4,) wxyz and ``rgba`` (4,) uint8. A missing or empty name becomes ``geom_<index>``: an
    empty one would log the geom at ``world/<body>`` itself, where its pose in the body frame
    and the body's pose in the world then fight over one transform (the robot was drawn in
    pieces, each link shifted along itself, before this).
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
        "name": str(geom.get("name") or f"geom_{index}"),
        "type": kind,
        "size": size.tolist(),
        "pos": pos,
        "quat": quat,
        "rgba": np.round(np.clip(rgba, 0.0, 1.0) * 255).astype(np.uint8),
    }


def parse_geoms(geoms: Sequence[Mapping[str, str | npt.ArrayLike]]) -> list[ParsedGeom]:
    """Every geom of the recorder's ``geoms`` through :func:`parse_geom`, each at its own path.

    Args:
        geoms: geom descriptions (``body``, ``type``, ``size``, optional ``name``, ``pos``,
            ``quat``, ``rgba``).

    Returns:
        The parsed geoms, in order.

    Raises:
        ConfigError: a malformed geom, or two geoms of one body with the same name (they would
            be logged at one entity path, one hiding the other).
    """
    parsed = [parse_geom(i, geom) for i, geom in enumerate(geoms)]
    seen: dict[tuple[str, str], int] = {}
    for i, geom in enumerate(parsed):
        key = (geom["body"], geom["name"])
        if key in seen:
            raise ConfigError(
                f"geoms[{i}] and geoms[{seen[key]}] are both named {geom['name']!r} on body "
                f"{geom['body']!r}: give each geom of a body its own name"
            )
        seen[key] = i
    return parsed


def geom_archetypes(geom: ParsedGeom) -> tuple[rr.Transform3D, GeomShape]:
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
    body_poses: Mapping[str, tuple[npt.ArrayLike, npt.ArrayLike]],
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
    "EVENT_WIDTH",
    "GEOM_TYPES",
    "MAX_SERIES_PER_PANEL",
    "TOUCH_WORDS",
    "StartReference",
    "event_lines",
    "group_features",
    "outcome_text",
    "transition_text",
]
