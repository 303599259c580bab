"""Aggregate a Hydra multirun of the main job into one table.

A sweep such as ``python scripts/experiment.py -m predictor=klr,klr_sparse`` leaves one job
directory per combination (``<sweep_dir>/<job.num>/``), each with ``report.json`` and the job's
command-line overrides in ``.hydra/overrides.yaml``. :func:`collect_sweep` reads them into a
:class:`SweepTable` with one row per job and training size D: the overrides as columns, then
the Table I counts W/I/C (mean and std over seeds), the switch-state distance, the progress MAE
and the strategy-map accuracy. :func:`write_aggregate` writes ``aggregate.json``,
``aggregate.md``, ``aggregate.csv`` and ``aggregate.png`` into the sweep directory itself, so
the summary lives beside the runs it summarises (the aggregate job's own Hydra run directory
only holds its log).
"""

from __future__ import annotations

import csv
import io
import json
import logging
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np
import yaml
from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.errors import HydraException
from omegaconf import DictConfig

from cpmp.errors import ConfigError, CpmpFileError
from cpmp.experiment.output import jsonable, write_json
from cpmp.experiment.plots import Cell, plot_sweep
from cpmp.io import atomic_write_text
from cpmp.records import JsonValue

log = logging.getLogger(__name__)

METRIC_COLUMNS: tuple[str, ...] = (
    "D",
    "n_seeds",
    "n_boxes",
    "W",
    "W_std",
    "I",
    "I_std",
    "C",
    "C_std",
    "distance_mean",
    "distance_std",
    "progress_mae",
    "progress_mae_std",
    "strategy_accuracy",
    "strategy_accuracy_std",
)
"""Columns after ``job`` and the overrides. W/I/C: mean [boxes] over seeds; distance: pooled
feature-space switch-state distance; progress_mae in [0, 1]; strategy_accuracy: fraction of the
strategy-map grid (only at the largest D of a job, else ``None``)."""

OUTPUT_FILES: tuple[str, ...] = (
    "aggregate.json",
    "aggregate.md",
    "aggregate.csv",
    "aggregate.png",
)
"""Files :func:`write_aggregate` writes into the sweep directory."""


@dataclass
class SweepTable:
    """The aggregated sweep.

    ``rows``: one dict per (job, D), keys ``columns``; ``override_keys``: every override seen
    (column order); ``swept``: the overrides whose value differs between jobs (a subset, in
    the same order); ``sweep_dir``: where the jobs were found.
    """

    sweep_dir: Path
    rows: list[dict[str, Cell]]
    columns: list[str]
    override_keys: list[str]
    swept: list[str]

    def to_dict(self) -> dict[str, JsonValue]:
        """The table as JSON-ready data (``aggregate.json``)."""
        return jsonable(
            {
                "sweep_dir": str(self.sweep_dir),
                "columns": self.columns,
                "override_keys": self.override_keys,
                "swept": self.swept,
                "rows": self.rows,
            }
        )


def _natural_key(path: Path) -> list[tuple[int, int | str]]:
    return [(0, int(tok)) if tok.isdigit() else (1, tok) for tok in re.split(r"(\d+)", str(path))]


def find_job_dirs(sweep_dir: str | Path) -> list[Path]:
    """Every directory under ``sweep_dir`` (itself included) holding a ``report.json``.

    In natural order (job ``2`` before ``10``); hidden directories (``.submitit``) are skipped.

    Raises:
        CpmpFileError: ``sweep_dir`` is not a directory or holds no report.
    """
    root = Path(sweep_dir)
    if not root.is_dir():
        raise CpmpFileError(f"sweep directory {root} does not exist or is not a directory")
    jobs = [
        report.parent
        for report in root.rglob("report.json")
        if not any(part.startswith(".") for part in report.relative_to(root).parts[:-1])
    ]
    if not jobs:
        raise CpmpFileError(
            f"no report.json under {root}: not a finished multirun of scripts/experiment.py "
            "(expected <sweep_dir>/<job.num>/report.json; did every job fail?)"
        )
    return sorted(jobs, key=lambda p: _natural_key(p.relative_to(root)))


def read_overrides(job_dir: str | Path) -> dict[str, Cell]:
    """The job's command-line overrides (``.hydra/overrides.yaml``) as key -> value.

    Values are parsed as Hydra does (``0.5`` -> float, ``klr`` -> str, ``null`` -> None);
    lists and dicts are kept as their override text (``[0,1]``) so they can be table cells.
    The ``+``/``++``/``~`` prefixes are dropped from keys. No file -> ``{}``.
    """
    path = Path(job_dir) / ".hydra" / "overrides.yaml"
    if not path.is_file():
        log.warning("%s has no .hydra/overrides.yaml; no override columns for it", job_dir)
        return {}
    try:
        lines = yaml.safe_load(path.read_text(encoding="utf-8")) or []
        parsed = OverridesParser.create().parse_overrides([str(line) for line in lines])
    except (yaml.YAMLError, HydraException, TypeError) as err:
        raise CpmpFileError(f"cannot parse overrides in {path}: {err}") from err
    out: dict[str, Cell] = {}
    for override in parsed:
        key = override.get_key_element().lstrip("+~")
        value = override.value()
        if not (value is None or isinstance(value, str | int | float | bool)):
            value = override.get_value_element_as_str()
        out[key] = value
    return out


def _read_report(job_dir: Path) -> dict[str, JsonValue]:
    path = job_dir / "report.json"
    try:
        report = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as err:
        raise CpmpFileError(f"cannot read {path} as JSON: {err}") from err
    missing = [k for k in ("reproduction", "progress") if k not in report]
    if missing:
        raise CpmpFileError(
            f"{path} is not a cpmp experiment report (missing {', '.join(missing)})"
        )
    return report


def report_rows(report: Mapping[str, JsonValue]) -> list[dict[str, Cell]]:
    """The metric columns (:data:`METRIC_COLUMNS`) of one report, one row per D (ascending)."""
    smap = report.get("strategy_map") or {}
    map_d = smap.get("train_size")
    n_seeds = len((report.get("experiment") or {}).get("seeds") or []) or None
    rows = []
    by_d_progress = report["progress"].get("by_train_size", {})
    for d in sorted(report["reproduction"], key=int):
        rep = report["reproduction"][d]
        prog = by_d_progress.get(d, {})
        at_map = map_d is not None and int(d) == int(map_d)
        rows.append(
            {
                "D": int(d),
                "n_seeds": n_seeds,
                "n_boxes": rep.get("n_boxes"),
                **{key: rep.get(key) for key in ("W", "W_std", "I", "I_std", "C", "C_std")},
                "distance_mean": rep.get("distance_mean"),
                "distance_std": rep.get("distance_std"),
                "progress_mae": prog.get("mae"),
                "progress_mae_std": prog.get("mae_std"),
                "strategy_accuracy": smap.get("accuracy") if at_map else None,
                "strategy_accuracy_std": smap.get("accuracy_std") if at_map else None,
            }
        )
    return rows


def collect_sweep(sweep_dir: str | Path) -> SweepTable:
    """Read every finished job of a sweep into a :class:`SweepTable` (see the module doc)."""
    root = Path(sweep_dir)
    jobs = find_job_dirs(root)
    overrides = {job: read_overrides(job) for job in jobs}
    keys = list(dict.fromkeys(k for job in jobs for k in overrides[job]))
    clash = sorted(set(keys) & {"job", *METRIC_COLUMNS})
    if clash:
        raise ConfigError(f"override key(s) {clash} clash with the aggregate's own column names")
    swept = [k for k in keys if len({repr(overrides[job].get(k)) for job in jobs}) > 1]
    rows = []
    for job in jobs:
        name = job.relative_to(root).as_posix() if job != root else "."
        for metrics in report_rows(_read_report(job)):
            rows.append({"job": name, **{k: overrides[job].get(k) for k in keys}, **metrics})
    log.info("aggregated %d jobs (%d rows) from %s; swept: %s", len(jobs), len(rows), root, swept)
    return SweepTable(root, jsonable(rows), ["job", *keys, *METRIC_COLUMNS], keys, swept)


class PlotAxes(NamedTuple):
    """What the sweep plot shows (:func:`plot_axes`)."""

    x: str
    """The x axis: the first swept override (else D)."""
    hue: str | None
    """One line per value of: a second swept override, else D when several were run, else none."""
    only_d: int | None
    """When D is neither x nor hue but several D were run: the largest, whose rows are plotted."""


def plot_axes(table: SweepTable) -> PlotAxes:
    """The x axis, hue and training size of the sweep plot (see :class:`PlotAxes`)."""
    sizes = sorted({row["D"] for row in table.rows})
    if not table.swept:
        return PlotAxes("D", None, None)
    x = table.swept[0]
    if len(table.swept) > 1:
        return PlotAxes(x, table.swept[1], sizes[-1] if len(sizes) > 1 else None)
    return PlotAxes(x, "D" if len(sizes) > 1 else None, None)


def plot_table(
    table: SweepTable, x: str, hue: str | None, only_d: int | None
) -> list[dict[str, Cell]]:
    """Rows for :func:`~cpmp.experiment.plots.plot_sweep`: C (mean, std) per (x, hue) cell.

    A cell with several jobs (the same x and hue, other overrides differing) plots the mean
    of their C and the std between them.
    """
    cells: dict[tuple[str, str], list[dict[str, Cell]]] = {}
    for row in table.rows:
        if only_d is None or row["D"] == only_d:
            key = (repr(row[x]), repr(row[hue]) if hue else "")
            cells.setdefault(key, []).append(row)
    out = []
    for rows in cells.values():
        values = [r["C"] for r in rows if r["C"] is not None]
        if not values:
            continue
        entry = {x: _plot_value(rows[0][x]), "C": float(np.mean(values))}
        std = rows[0]["C_std"] if len(rows) == 1 else float(np.std(values))
        entry["C_std"] = math.nan if std is None else std
        if hue:
            entry[hue] = _plot_value(rows[0][hue])
        out.append(entry)
    return out


def _plot_value(value: Cell) -> str | int | float:
    """Numbers stay numbers (a numeric x axis); everything else becomes text (``None`` -> ``-``)."""
    if value is None:
        return "-"
    return value if isinstance(value, int | float) and not isinstance(value, bool) else str(value)


def _cell(value: Cell, std: Cell = None, digits: int = 2, percent: bool = False) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "–"
    if isinstance(value, bool) or not isinstance(value, int | float):
        return str(value)
    scale = 100.0 if percent else 1.0
    text = f"{scale * value:.{digits}f}"
    if std is not None:
        text += f" ± {scale * std:.{digits}f}"
    return text + (" %" if percent else "")


def render_markdown(table: SweepTable) -> str:
    """A Markdown table of the sweep: counts and distances as mean ± std over seeds."""
    keys = table.override_keys
    header = ["job", *keys, "D", "W", "I", "C", "distance", "progress MAE", "strategy map"]
    lines = [
        f"# cpmp sweep `{table.sweep_dir}`",
        "",
        f"{len({r['job'] for r in table.rows})} jobs; swept: "
        + (", ".join(f"`{k}`" for k in table.swept) or "nothing")
        + ". W / I / C: wrong start / incomplete / complete out of `n_boxes` boxes, mean ± std "
        "over seeds; distance: switch-state distance in feature space; strategy map: share of "
        "the grid with the correct initial strategy (largest D only).",
        "",
        "| " + " | ".join(header) + " |",
        "|" + " --- |" * len(header),
    ]
    for row in table.rows:
        cells = [
            row["job"],
            *("–" if row[k] is None else str(row[k]) for k in keys),
            str(row["D"]),
            *(_cell(row[k], row[f"{k}_std"], 1) for k in ("W", "I", "C")),
            _cell(row["distance_mean"], row["distance_std"]),
            _cell(row["progress_mae"], row["progress_mae_std"], 3),
            _cell(row["strategy_accuracy"], row["strategy_accuracy_std"], 1, percent=True),
        ]
        lines.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
    return "\n".join(lines) + "\n"


def render_csv(table: SweepTable) -> str:
    """The table as CSV text (header = :attr:`SweepTable.columns`; ``None`` -> empty cell)."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=table.columns, lineterminator="\n")
    writer.writeheader()
    for row in table.rows:
        writer.writerow({k: "" if row.get(k) is None else row[k] for k in table.columns})
    return buffer.getvalue()


def write_aggregate(table: SweepTable, out_dir: str | Path | None = None) -> Path:
    """Write :data:`OUTPUT_FILES` atomically into ``out_dir``; returns the ``aggregate.json`` path.

    ``out_dir`` defaults to the sweep directory. The plot shows C against :func:`plot_axes`.
    """
    out = Path(out_dir) if out_dir is not None else table.sweep_dir
    x, hue, only_d = plot_axes(table)
    plot_rows = plot_table(table, x, hue, only_d)
    plot: dict[str, Cell] = {"x": x, "y": "C", "hue": hue, "D": only_d, "file": None}
    if plot_rows:
        title = "complete episodes C (mean ± std)"
        if only_d is not None:
            title += f", D = {only_d}"
        plot_sweep(plot_rows, x, "C", hue, out / "aggregate.png", title=title)
        plot["file"] = "aggregate.png"
    else:
        log.warning("no C values to plot; aggregate.png not written")
    atomic_write_text(out / "aggregate.md", render_markdown(table))
    atomic_write_text(out / "aggregate.csv", render_csv(table))
    return write_json(out / "aggregate.json", {**table.to_dict(), "plot": plot})


def aggregate_sweep(cfg: DictConfig, run_dir: str | Path) -> Path:
    """Job of ``scripts/aggregate.py``: aggregate ``cfg.sweep_dir``; returns aggregate.json.

    The files are written into the sweep directory (``run_dir``, the aggregate job's own
    directory, is not used).
    """
    sweep_dir = cfg.get("sweep_dir")
    if not sweep_dir:
        raise ConfigError(
            "sweep_dir is required: sweep_dir=logs/experiment-multirun/<timestamp> "
            "(the directory a multirun of scripts/experiment.py printed)"
        )
    return write_aggregate(collect_sweep(Path(str(sweep_dir))))
