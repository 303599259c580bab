"""The jobs for your own demonstrations (no simulator): ``cpmp-train`` and ``cpmp-evaluate``.

``cpmp-train`` trains a sequencer from an HDF5 file of demonstrations, ``cpmp-evaluate``
evaluates a checkpoint offline on one and writes ``evaluation.json`` and ``evaluation.md``.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, TypedDict

from omegaconf import DictConfig

from cpmp.data.datafile import list_splits, load_demonstrations
from cpmp.data.demonstration import Demonstration
from cpmp.errors import ConfigError, CpmpFileError, DataError
from cpmp.experiment.config import job_fit_settings
from cpmp.experiment.console import stage
from cpmp.experiment.output import write_json
from cpmp.io import atomic_write_text
from cpmp.records import JsonValue

if TYPE_CHECKING:
    from cpmp.baselines.bc import BCSequencer
    from cpmp.baselines.goal_nearest import GoalNearestSequencer
    from cpmp.sequencer.sequencer import ConcurrentSequencer

# The sequencers, their fit and evaluation, the plots and the report (SciPy, Lightning,
# matplotlib, MuJoCo, rerun: seconds) are imported by the functions that use them, after the
# file and split are checked: a job with a bad file fails without them.

log = logging.getLogger(__name__)


class UnknownMP(TypedDict):
    """An MP labelled in the evaluated demonstrations that the model has no node for."""

    variable: str
    """Its control variable."""
    mp: str
    """Its name."""
    known_variable: bool
    """Whether the model knows the variable (a renamed MP) or not (a variable not trained on)."""
    activations: int
    """How many activations of it the demonstrations hold."""
    demos: list[str]
    """The demonstrations with one, in their order."""


ALL_DEMOS_WARNING = (
    "every demonstration of the file was scored (no held-out split: the file has no "
    "`mask/test`, or data.split=null), so these numbers may include the demonstrations the "
    "model was trained on: they are not held-out numbers. Give the file a `mask/test` of "
    "demonstrations the model never saw (cpmp-import and save_demonstrations write one), or "
    "set data.split to such a split"
)
"""What the evaluation says when it scored every demonstration of a file."""


def _demo_file(cfg: DictConfig, auto_split: str) -> tuple[Path, str | None]:
    """The ``data`` group's file (checked to exist) and split.

    Args:
        cfg: the job's composed config.
        auto_split: what ``split: auto`` means when the file has that mask (else every
            demonstration).

    Returns:
        The file and the split (``None``: every demonstration).

    Raises:
        ConfigError: no ``data.path``.
        CpmpFileError: the file does not exist.
    """
    if not cfg.data.get("path"):
        raise ConfigError("data.path is required: give an HDF5 file of demonstrations")
    path = Path(str(cfg.data.path))
    if not path.is_file():
        raise CpmpFileError(f"demonstration file {path} does not exist (set data.path)")
    split = cfg.data.split
    if split == "auto":
        split = auto_split if auto_split in list_splits(path) else None
    return path, split


def _load_split(path: Path, split: str | None, use: str) -> list[Demonstration]:
    """The demonstrations of ``split`` (every one for ``None``), refusing an empty split.

    Args:
        path: the demonstration file.
        split: the mask's name, or ``None``.
        use: what the job does with them, for the message (``"train"``, ``"evaluate"``).

    Returns:
        The demonstrations.

    Raises:
        DataError: ``mask/<split>`` selects no demonstration (naming the split).
    """
    demos = load_demonstrations(path, split=split)
    if not demos and split is not None:
        total = len(load_demonstrations(path))  # the error path only: read them all to count
        raise DataError(
            f"{path}: split {split!r} (mask/{split}) is empty: it selects none of the file's "
            f"{total} demonstrations; mark the demonstrations to {use} on in mask/{split}, or "
            f"set data.split=null to {use} on all of them"
        )
    return demos


def train_from_file(cfg: DictConfig, run_dir: str | Path) -> Path:
    """Train a sequencer from a demonstration file and save ``model.pt`` into ``run_dir``.

    The file's ``mask/train`` split trains when present (else every demonstration); when it
    trains on ``mask/train`` and the file has ``mask/test``, those demonstrations validate
    the fit (their progress MAE is logged every epoch, ``val_mae`` in ``train_summary.json``).

    Returns:
        The checkpoint's path.
    """
    from cpmp.experiment.fitting import train_sequencer  # lazy: see the imports above

    settings = job_fit_settings(cfg)
    path, split = _demo_file(cfg, "train")
    demos = _load_split(path, split, "train")
    validation = None
    if split == "train" and "test" in list_splits(path):
        validation = load_demonstrations(path, split="test") or None
        if validation is None:
            log.warning("%s: mask/test is empty: the fit is not validated", path)
    run_dir = Path(run_dir)
    held_out = f", validated on {len(validation)} from split test" if validation else ""
    with stage(f"train on {len(demos)} demos from {path} (split {split or 'all'}){held_out}"):
        seq = train_sequencer(
            demos, settings, int(cfg.seed), log_dir=run_dir / "lightning", validation=validation
        )
    out = seq.save(run_dir / "model.pt")
    fit = {} if seq.fit_summary is None else seq.fit_summary.to_dict()
    write_json(
        run_dir / "train_summary.json",
        {"data": str(path), "split": split, "n_demos": len(demos), **fit},
    )
    log.info("graphs:\n%s", seq.describe())
    return out


def evaluate_checkpoint(cfg: DictConfig, run_dir: str | Path) -> Path:
    """Evaluate a checkpoint offline on a file's test split.

    Progress MAE per node, replay of the recorded feature streams, Fig. 6 plot; writes
    ``evaluation.json`` and ``evaluation.md``.

    Returns:
        The path of ``evaluation.json``.
    """
    from cpmp.evaluation.checkpoints import load_sequencer  # lazy: see the imports above
    from cpmp.evaluation.offline import evaluate_offline
    from cpmp.experiment.plots import plot_progress_curves

    if not cfg.get("checkpoint"):
        raise ConfigError("checkpoint is required: checkpoint=path/to/model.pt")
    checkpoint = Path(str(cfg.checkpoint))
    if not checkpoint.is_file():
        raise CpmpFileError(f"checkpoint {checkpoint} does not exist; train one with train.py")
    path, split = _demo_file(cfg, "test")
    seq = load_sequencer(checkpoint)  # any kind the main job or train.py writes
    demos = _load_split(path, split, "evaluate")
    if split is None:
        log.warning("%s: %s", path, ALL_DEMOS_WARNING)
    run_dir = Path(run_dir)
    unknown = _unknown_mps(seq, demos)
    if unknown:
        log.warning(
            "%s has MPs the model does not know, left out of the progress MAE (renamed? "
            "rename them back or retrain): %s",
            path,
            ", ".join(f"{u['variable']}/{u['mp']} ({u['activations']}x)" for u in unknown),
        )
    with stage(f"evaluate on {len(demos)} demos"):
        result = evaluate_offline(seq, demos)
    plot_progress_curves(
        {"held-out": result["curves"]},
        run_dir / "fig6_progress.png",
        title="Predicted vs expected progress",
    )
    out = {
        "checkpoint": str(cfg.checkpoint),
        "data": str(path),
        "split": split,
        "n_demos": len(demos),
        "model": _model_entry(seq),
        "unknown_mps": unknown,
        "progress": result["progress"],
        "replay": result["replay"],
    }
    json_path = write_json(run_dir / "evaluation.json", out)
    atomic_write_text(run_dir / "evaluation.md", _evaluation_markdown(out))
    return json_path


def _model_entry(
    seq: ConcurrentSequencer | GoalNearestSequencer | BCSequencer,
) -> dict[str, object]:
    """What an evaluated checkpoint is.

    Returns:
        ``sequencer`` (``learned``, ``goal_nearest`` or ``bc``) and ``predictor`` (its kind,
        ``none`` for a baseline, with a note on what its progress is).
    """
    from cpmp.baselines.bc import BCSequencer  # lazy: see the imports above
    from cpmp.baselines.goal_nearest import GoalNearestSequencer
    from cpmp.experiment.report import predictor_entry

    if isinstance(seq, (GoalNearestSequencer, BCSequencer)):
        entry = predictor_entry("none", {}, {"kind": seq.kind})
        return {"sequencer": seq.kind, "predictor": entry.pop("kind"), **entry}
    options = seq.predictor.spec()["config"]
    return {
        "sequencer": "learned",
        "predictor": seq.predictor.kind,
        "feature_weighting": options.get("feature_weighting"),
        "feature_scaling": options.get("feature_scaling"),
        "switch_rule": seq.config.switch_rule,
        "coupling": seq.config.coupling,
    }


def predictor_description(model: Mapping[str, object]) -> str:
    """How the reports name a learned sequencer's predictor: its kind and feature weighting.

    ``klr`` with ``path`` weighting is ``predictor=klr`` (cpmp's default), with ``none`` the
    paper's kernel ``predictor=paper``; both are kind ``klr``, so the weighting is
    always named.

    Args:
        model: :func:`_model_entry`'s entry of a learned sequencer.

    Returns:
        Markdown text such as ``predictor `klr` (feature weighting `path`, scaling `global`)``.
    """
    extra = [
        f"{label} `{model[key]}`"
        for key, label in (
            ("feature_weighting", "feature weighting"),
            ("feature_scaling", "scaling"),
        )
        if model.get(key) is not None
    ]
    return f"predictor `{model['predictor']}`" + (f" ({', '.join(extra)})" if extra else "")


def _unknown_mps(
    seq: ConcurrentSequencer | GoalNearestSequencer | BCSequencer, demos: list[Demonstration]
) -> list[UnknownMP]:
    """MPs labelled in ``demos`` that ``seq`` has no node for.

    A renamed MP, or every MP of a variable the model was not trained on.

    Args:
        seq: a fitted sequencer.
        demos: demonstrations.

    Returns:
        ``[{"variable", "mp", "known_variable", "activations", "demos"}]`` sorted by
        variable and MP.
    """
    found: dict[tuple[str, str], UnknownMP] = {}
    for m, demo in enumerate(demos):
        for v in demo.variables:
            graph = seq.graphs.get(v)
            for seg in demo.segments(v):
                if graph is not None and seg.mp in graph.nodes:
                    continue
                row = found.setdefault(
                    (v, seg.mp),
                    {
                        "variable": v,
                        "mp": seg.mp,
                        "known_variable": graph is not None,
                        "activations": 0,
                        "demos": [],
                    },
                )
                row["activations"] += 1
                name = demo.name or f"demo_{m}"
                if name not in row["demos"]:
                    row["demos"].append(name)
    return [found[k] for k in sorted(found)]


def _evaluation_markdown(out: Mapping[str, JsonValue]) -> str:
    p, r = out["progress"], out["replay"]
    lines = [
        f"# Offline evaluation of `{out['checkpoint']}`",
        "",
        f"{out['n_demos']} demos from `{out['data']}` (split {out['split'] or 'all'}).",
        "",
    ]
    if out["split"] is None:
        lines += [f"> **Warning:** {ALL_DEMOS_WARNING}.", ""]
    model = out["model"]
    if model["sequencer"] == "learned":
        lines += [
            f"Learned sequencer, {predictor_description(model)}, switching rule "
            f"`{model.get('switch_rule', '–')}`, coupling `{model.get('coupling', '–')}`.",
            "",
        ]
    else:
        lines += [f"Sequencer `{model['sequencer']}`: {model['note']}.", ""]
    if out.get("unknown_mps"):
        lines += [
            "**MPs the model does not know** (renamed, or of a variable the model was not "
            "trained on): left out of the progress MAE; a variable with one cannot match in "
            "the replay, a variable the model lacks is not replayed.",
            "",
            "| variable | MP | activations | demos |",
            "| --- | --- | --- | --- |",
        ]
        lines += [
            f"| {u['variable']}{'' if u['known_variable'] else ' (unknown)'} | {u['mp']} | "
            f"{u['activations']} | {', '.join(u['demos'])} |"
            for u in out["unknown_mps"]
        ]
        lines.append("")
    lines += [
        f"Progress MAE {p['mae']:.3f} (first 10 %: {p['mae_first']:.3f}, last 10 %: "
        f"{p['mae_last']:.3f}).",
        "",
        "| node | MAE |",
        "| --- | --- |",
    ]
    lines += [f"| {k} | {v:.3f} |" for k, v in p["per_node"].items()]
    dist = (
        "–" if r["distance_mean"] is None else f"{r['distance_mean']:.3f} ± {r['distance_std']:.3f}"
    )
    lines += [
        "",
        f"Replay: all variables reproduced in {100 * r['all_match']:.0f} % of the demos; "
        f"switch-state distance {dist}.",
        "",
        "| variable | sequence match |",
        "| --- | --- |",
    ]
    lines += [f"| {v} | {100 * m:.0f} % |" for v, m in r["sequence_match"].items()]
    return "\n".join(lines) + "\n"
