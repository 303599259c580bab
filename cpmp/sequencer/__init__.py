"""The sequencer: learned progress turned into MP switches for every control variable.

:class:`ConcurrentSequencer` (``sequencer``) fits one sequence graph and one progress predictor
bank per control variable from demonstrations and steps them closed loop (``reset`` / ``step``,
``save`` / ``load``). Its parts, one module each, imported in this order (each only from the
ones before it):

* ``inputs``: the checks of what ``step`` is given (time, stamps, features, demonstrations);
* ``timing``: the measurement time of each tick's features (clock steps, stamps, repeats);
* ``motion``: what the demonstrations say about motion: each switch's speed envelope and the
  ambient features (moving alike under every MP);
* ``switching``: the switching rules (the paper's threshold + 50 ms rule, the peak rule)
  on measurement time, the learned cross-variable coupling and stall recovery;
* ``fit_data``: each node's training data and the checks after a fit;
* ``glitches``: label glitches (``A A X A A``) repaired before the graphs are built;
* ``model``: :class:`NodeIndex` and :class:`TransitionModel`, what an episode reads of a
  fitted sequencer;
* ``watch``: :class:`ActivationWatch`, what an episode remembers of each pending switch
  (best ``p`` and why it has not fired) to explain an incomplete episode;
* ``episode``: :class:`SequencerEpisode`, the state machine of one episode;
* ``batch``: :class:`BatchedSequencer`, N episodes with one predictor call per tick, and
  :class:`EpisodeBatch`, what every batched policy shares;
* ``fit``: the fit itself (graphs, the predictor bank trained in Lightning, what the fit found);
  the one module that imports Lightning, not imported by this package: ``ConcurrentSequencer.
  fit_config`` imports it when it is called, so that loading and stepping never do;
* ``sequencer``: :class:`ConcurrentSequencer`, on top of all of them.
"""

from cpmp.sequencer.batch import (
    BatchedSequencer,
    EpisodeBatch,
    EpisodeRecord,
    Features,
    FittedSequencer,
    LiveMask,
    Stamps,
    Times,
)
from cpmp.sequencer.episode import SequencerEpisode
from cpmp.sequencer.glitches import LabelGlitch, repair_glitches
from cpmp.sequencer.inputs import checked_demonstrations, checked_features, checked_time
from cpmp.sequencer.model import NodeIndex, TransitionModel
from cpmp.sequencer.motion import SpeedLimit, SpeedMeter, ambient_features, learn_speed_limits
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
    JointPartner,
    PaperRule,
    PeakRule,
    StallDetector,
    SwitchRule,
    indicator_features,
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
    "EpisodeRecord",
    "Features",
    "FittedSequencer",
    "JointPartner",
    "LabelGlitch",
    "LiveMask",
    "NodeIndex",
    "PaperRule",
    "PeakRule",
    "SequencerEpisode",
    "SpeedLimit",
    "SpeedMeter",
    "StallDetector",
    "Stamps",
    "SwitchRule",
    "Times",
    "TransitionModel",
    "ambient_features",
    "checked_demonstrations",
    "checked_features",
    "checked_time",
    "indicator_features",
    "learn_speed_limits",
    "make_rule",
    "repair_glitches",
]
