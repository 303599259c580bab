"""The sequencer: learned progress turned into MP switches for every control variable.

:class:`ConcurrentSequencer` (``sequencer``) fits one sequence graph and one progress predictor
bank per control variable from demonstrations and steps them closed loop (``reset`` / ``step``,
``save`` / ``load``). Its parts, one module each:

* ``episode``: :class:`SequencerEpisode`, the state machine of one episode;
* ``batch``: :class:`BatchedSequencer`, N episodes with one predictor call per tick;
* ``switching``: the switching rules (the paper's threshold + 50 ms rule, the plateau rule),
  the learned cross-variable coupling and stall recovery;
* ``fit_data``: each node's training data and the checks after a fit;
* ``inputs``: the checks of what ``step`` is given (time, features).
"""

from cpmp.sequencer.batch import BatchedSequencer, EpisodeBatch
from cpmp.sequencer.episode import NodeIndex, SequencerEpisode
from cpmp.sequencer.sequencer import (
    CHECKPOINT_FORMAT,
    CHECKPOINT_VERSION,
    PAPER_OPTIONS,
    ConcurrentSequencer,
)
from cpmp.sequencer.switching import (
    COUPLINGS,
    SWITCH_RULES,
    Coupling,
    PaperRule,
    PlateauRule,
    StallDetector,
    SwitchRule,
    make_rule,
)

__all__ = [
    "CHECKPOINT_FORMAT",
    "CHECKPOINT_VERSION",
    "COUPLINGS",
    "PAPER_OPTIONS",
    "SWITCH_RULES",
    "BatchedSequencer",
    "ConcurrentSequencer",
    "Coupling",
    "EpisodeBatch",
    "NodeIndex",
    "PaperRule",
    "PlateauRule",
    "SequencerEpisode",
    "StallDetector",
    "SwitchRule",
    "make_rule",
]
