"""Loading a sequencer checkpoint whose kind is not known in advance.

Each sequencer writes and reads its own checkpoints (``save``/``load``, through
:func:`cpmp.io.save_checkpoint` and :func:`cpmp.io.load_checkpoint`); :func:`load_sequencer`
reads any of them, for the jobs that evaluate a given ``model.pt``.
"""

from __future__ import annotations

from pathlib import Path

from cpmp.baselines import BCSequencer, GoalNearestSequencer
from cpmp.baselines.bc import CHECKPOINT_FORMAT as BC_FORMAT
from cpmp.baselines.goal_nearest import CHECKPOINT_FORMAT
from cpmp.config.bc import KIND as BC
from cpmp.config.goal_nearest import KIND
from cpmp.errors import CheckpointFormatError, CpmpFileError
from cpmp.sequencer import ConcurrentSequencer


def load_sequencer(path: str | Path) -> ConcurrentSequencer | GoalNearestSequencer | BCSequencer:
    """Load any sequencer checkpoint cpmp writes: the checkpoint's own format decides the kind.

    The main job's ``model_D<d>.pt`` and ``train.py``'s ``model.pt`` are a
    :class:`~cpmp.sequencer.ConcurrentSequencer` with any predictor, or a
    :class:`~cpmp.baselines.GoalNearestSequencer` or :class:`~cpmp.baselines.BCSequencer`.
    All share the interface offline
    evaluation needs (``graphs``, ``feature_names``, ``node_keys``, ``progress``, ``predictor``
    with ``scaler`` and ``stateful``, ``replay``).

    Args:
        path: the checkpoint file.

    Returns:
        The sequencer.

    Raises:
        CpmpFileError: a missing, damaged or untrusted file (as each loader says), or a file
            of none of these formats (naming them).
    """
    try:
        return ConcurrentSequencer.load(path)
    except CheckpointFormatError as err:
        if err.found not in (CHECKPOINT_FORMAT, BC_FORMAT) and err.damaged:
            raise CpmpFileError(
                f"{path} is a damaged checkpoint: its content does not match the SHA-256 stored "
                "in it; copy it again from its source, or retrain the model with scripts/train.py"
            ) from err
        if err.found == BC_FORMAT:
            return BCSequencer.load(path)
        if err.found != CHECKPOINT_FORMAT:
            raise CpmpFileError(
                f"{path} is neither a cpmp sequencer nor a {KIND} or {BC} checkpoint; give a "
                "model.pt written by scripts/train.py or a model_D<d>.pt of scripts/experiment.py"
            ) from err
    return GoalNearestSequencer.load(path)
