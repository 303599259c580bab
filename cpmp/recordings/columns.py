"""The per-tick series of a recording, buffered and sent column-wise.

:class:`ColumnBuffer` makes, checks and names the entity paths of a row layout once, keeps one
row per tick for each tuple of entity paths (scalars) and of bodies (poses), and sends each
entity's column with one ``send_columns`` call (why: :mod:`cpmp.recordings`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import rerun as rr

from cpmp.recordings.layout import check_mp, entity, series_color

_RowBuffer = tuple[list[int], list[float], list[np.ndarray]]
"""Ticks, times [s] and one row (K,) of scalar values per tick for a tuple of K entity paths."""
_PoseBuffer = tuple[list[int], list[float], list[np.ndarray], list[np.ndarray]]
"""Ticks, times [s], positions (B, 3) and xyzw quaternions (B, 4) per tick for B bodies."""
_LayoutKey = tuple[str | tuple[str, ...], ...]
"""A row layout: its kind, then its variable and MP names, or its variables."""


class ColumnBuffer:
    """The per-tick series of one recording stream, buffered in the order they were added.

    Args:
        rec: the ``rr.RecordingStream`` the series names are logged to and the columns sent to.
        mp_names: control variable -> its MP names, to check the variables and MPs of a layout.
    """

    def __init__(self, rec: rr.RecordingStream, mp_names: Mapping[str, Sequence[str]]) -> None:
        self._rec = rec
        self._mp_names = mp_names
        self._rows: dict[tuple[str, ...], _RowBuffer] = {}
        self._poses: dict[tuple[str, ...], _PoseBuffer] = {}
        # The paths of a (kind, variable, MP names) layout are made, checked and named once.
        self._layouts: dict[_LayoutKey, tuple[str, ...]] = {}
        self._named_series: set[str] = set()

    def name_series(self, path: str, name: str, color: tuple[int, int, int] | None = None) -> None:
        """Give the series at ``path`` its legend ``name`` and ``color`` (static ``SeriesLines``).

        Once per path; ``color`` ``None``: rerun's colour.
        """
        if path not in self._named_series:
            self._named_series.add(path)
            lines = rr.SeriesLines(names=[name], colors=None if color is None else [color])
            self._rec.log(path, lines, static=True)

    def mp_color(self, variable: str, mp: str) -> tuple[int, int, int]:
        """The colour of ``mp``'s series in every panel of ``variable`` (by its place)."""
        return series_color(list(self._mp_names[variable]).index(mp))

    def progress_paths(self, variable: str, mps: tuple[str, ...]) -> tuple[str, ...]:
        """``phi``, ``entry``, ``exit`` paths of each MP in ``mps`` (MP-major), checked, named.

        Every series of an MP is named by the MP (its panel says which quantity it is).
        """
        key = ("progress", variable, mps)
        if key not in self._layouts:
            series = [(mp, part) for mp in mps for part in ("phi", "entry", "exit")]
            self._add_layout(
                key,
                [(variable, mp) for mp in mps],
                [(("progress", variable, mp, part), mp) for mp, part in series],
            )
        return self._layouts[key]

    def transition_paths(self, variable: str, targets: tuple[str, ...]) -> tuple[str, ...]:
        """``transition/<variable>/<target>`` of each of ``targets``, checked, named."""
        key = ("transition", variable, targets)
        if key not in self._layouts:
            self._add_layout(
                key,
                [(variable, target) for target in targets],
                [(("transition", variable, target), target) for target in targets],
            )
        return self._layouts[key]

    def index_paths(self, variables: tuple[str, ...]) -> tuple[str, ...]:
        """``active/<variable>/index`` of each of ``variables``, checked."""
        key = ("active", variables)
        if key not in self._layouts:
            self._add_layout(
                key,
                [(variable, None) for variable in variables],
                [(("active", variable, "index"), None) for variable in variables],
            )
        return self._layouts[key]

    def _add_layout(
        self,
        key: _LayoutKey,
        checks: Sequence[tuple[str, str | None]],
        series: Sequence[tuple[tuple[str, ...], str | None]],
    ) -> None:
        """The entity paths of layout ``key``: checked, made and named once.

        Checks the (variable, MP or ``None``) pairs ``checks``, then makes the entity path of
        each of ``series`` (path parts, series name or ``None``), names its series and keeps
        the paths as layout ``key``.
        """
        for variable, mp in checks:
            check_mp(self._mp_names, variable, mp)
        paths = tuple(entity(*parts) for parts, _ in series)
        for path, (parts, name) in zip(paths, series, strict=True):
            if name is not None:
                self.name_series(path, name, self.mp_color(parts[1], name))
        self._layouts[key] = paths

    def add_row(self, paths: tuple[str, ...], tick: int, t: float, row: np.ndarray) -> None:
        """One tick's values ``row`` (K,) of the K scalar entities ``paths`` at ``t`` [s]."""
        ticks, times, rows = self._rows.setdefault(paths, ([], [], []))
        ticks.append(tick)
        times.append(t)
        rows.append(row)

    def add_poses(
        self,
        bodies: tuple[str, ...],
        tick: int,
        t: float,
        positions: np.ndarray,
        quats: np.ndarray,
    ) -> None:
        """One tick's poses of ``bodies``: positions (B, 3) [m], xyzw quaternions (B, 4)."""
        ticks, times, position_rows, quat_rows = self._poses.setdefault(bodies, ([], [], [], []))
        ticks.append(tick)
        times.append(t)
        position_rows.append(positions)
        quat_rows.append(quats)

    def send(self) -> None:
        """Send every buffered column to the recording stream and empty the buffers.

        Scalars go to their entity, poses as ``Transform3D`` to ``world/<body>``, on the
        ``time`` and ``tick`` timelines.
        """

        def indexes(ticks: list[int], times: list[float]) -> list[rr.TimeColumn]:
            return [
                rr.TimeColumn("time", duration=np.asarray(times)),
                rr.TimeColumn("tick", sequence=np.asarray(ticks)),
            ]

        for paths, (ticks, times, rows) in self._rows.items():
            if ticks:
                table = np.asarray(rows, dtype=float)  # (T, K)
                for j, path in enumerate(paths):
                    self._rec.send_columns(
                        path,
                        indexes=indexes(ticks, times),
                        columns=rr.Scalars.columns(scalars=table[:, j]),
                    )
                for column in (ticks, times, rows):
                    column.clear()
        for bodies, (ticks, times, positions, quats) in self._poses.items():
            if ticks:
                translation, rotation = np.stack(positions), np.stack(quats)  # (T, B, 3|4)
                for j, body in enumerate(bodies):
                    self._rec.send_columns(
                        entity("world", body),
                        indexes=indexes(ticks, times),
                        columns=rr.Transform3D.columns(
                            translation=translation[:, j], quaternion=rotation[:, j]
                        ),
                    )
                for column in (ticks, times, positions, quats):
                    column.clear()
