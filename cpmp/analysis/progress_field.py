"""Worked examples on synthetic data (no simulator needed)."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from cpmp.evaluation.offline import activation_progress, progress_errors
from cpmp.experiment.plots import plot_progress_field
from cpmp.io import atomic_write_text
from cpmp.records import JsonValue
from cpmp.sequencer.sequencer import ConcurrentSequencer
from cpmp.worlds.two_point import curved_trajectories


def progress_field_example(
    out_dir: str | Path,
    *,
    n_trajectories: int,
    seed: int,
    predictor: str,
    predictor_options: Mapping[str, object] | None = None,
) -> dict[str, JsonValue]:
    """The paper's Fig. 3: a progress predictor's field over the plane, supports marked.

    The predictor is fitted on curved 2-D trajectories; its predicted progress is plotted over
    the plane with the support points marked. Writes ``progress_field.png`` and
    ``progress_field.json`` (support count, training MAE) into ``out_dir``; returns the JSON
    content plus the PNG path. The defaults of the command (``cpmp-progress-field``) are in
    ``conf/progress_field.yaml``.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    demos = curved_trajectories(n_trajectories, seed=seed)
    seq = ConcurrentSequencer.fit(
        demos, predictor=predictor, seed=seed, logger=None, **(predictor_options or {})
    )
    support = None
    if hasattr(seq.predictor, "support"):
        mask = seq.predictor.support_mask[0].numpy()
        scaled = seq.predictor.support[0].detach().numpy()[mask]
        support = scaled * seq.predictor.scaler.scale.numpy() + seq.predictor.scaler.offset.numpy()
    png = plot_progress_field(
        lambda pts: seq.progress(pts)[:, 0],
        [d.features for d in demos],
        support if support is not None else np.zeros((0, 2)),
        out / "progress_field.png",
        bounds=((0.0, 1.0), (0.0, 1.0)),
        title=f"{predictor}: predicted progress of 'move' ({n_trajectories} trajectories)",
    )
    result: dict[str, JsonValue] = {
        "predictor": predictor,
        "n_trajectories": n_trajectories,
        "n_support": None if support is None else len(support),
        "train_mae": progress_errors(activation_progress(seq, demos))["mae"],
        "png": str(png),
    }
    atomic_write_text(out / "progress_field.json", json.dumps(result, indent=2))
    return result
