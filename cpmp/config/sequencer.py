"""The options of the transition rule (``conf/sequencer/paper.yaml``, ``coupled.yaml``)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from cpmp.config.validation import finite_number
from cpmp.errors import ConfigError

SWITCH_RULES = ("paper", "peak")
"""Values of :attr:`SequencerConfig.switch_rule` (see :mod:`cpmp.sequencer.switching`)."""
REMOVED_SEQUENCER_OPTIONS: dict[str, tuple[object, str]] = {
    "min_exit": (
        0.0,
        "the exit gate (a transition also needing the current node's φ above min_exit) was "
        "removed with issue #32: it was off by default and nothing set it; the threshold on "
        "p = φ_current · (1 - φ_next) and the coupling's progress bounds decide when a node "
        "may be left",
    ),
    "start_kernel": (
        "shared",
        "the isotropic start heads (extra predictor heads for the initial nodes, "
        "start_kernel=isotropic) were removed with issue #32: the learned start rule (the "
        "default) reads no φ, and the independent and joint start rules read the nodes' own "
        "progress predictors, as start_kernel=shared (the default) did",
    ),
}
"""Sequencer options that no longer exist: name -> (the value at which the option did
nothing, why it went). :func:`existing_sequencer_options` names them as removed rather than
unknown; a checkpoint that holds one at that value loads as before."""
REMOVED_SEQUENCER_VALUES: dict[tuple[str, str], str] = {
    ("switch_rule", "plateau"): (
        "the plateau rule (p above the threshold for patience seconds without a new maximum) "
        "was removed with issue #32: it missed switches whose p crosses the threshold near its "
        "peak, and peak, the default, fires on a plateau as it did; use peak or paper"
    ),
}
"""Option values that no longer exist: (name, value) -> why, and what to use instead."""
COUPLINGS = ("none", "context")
"""Values of :attr:`SequencerConfig.coupling` (see :mod:`cpmp.sequencer.switching`)."""
NONFINITE_POLICIES = ("hold", "raise")
"""Values of :attr:`SequencerConfig.nonfinite`."""
START_RULES = ("independent", "joint", "learned")
"""Values of :attr:`SequencerConfig.start_rule`."""
BRANCHES = ("none", "learned")
"""Values of :attr:`SequencerConfig.branch`."""


@dataclass
class SequencerConfig:
    """The transition rule's parameters.

    The defaults are cpmp's recommended configuration (``sequencer=coupled``); ``sequencer=paper``
    and :data:`cpmp.sequencer.PAPER_OPTIONS` set ``switch_rule``, ``coupling``, ``recovery``,
    ``start_rule``, ``branch`` and ``joint`` back to the paper's.

    Attributes:
        threshold: a transition fires only when ``p = φ_current · (1 - φ_next) > threshold``
            (paper: 0.65).
        patience: the "50 ms" of the rule [s] (paper: 0.05): ``p`` must not have improved over
            the last ``patience`` seconds.
        min_improvement: an increase of ``p`` smaller than this does not count as improving
            (``p(t) <= p(t - patience) + min_improvement``). Attractors converge
            asymptotically, so ``p`` keeps creeping up by tiny amounts; with a strict
            comparison (``0``) such a transition might never fire.
        switch_rule: ``paper`` (fire when ``p(t) > threshold`` and ``p(t) <= p(t - patience) +
            min_improvement``, the paper's sentence read literally) or ``peak`` (the default:
            ``paper``, and also when ``p`` has fallen back from a peak above the threshold
            within the last ``patience``, as it does right after an event); see
            :mod:`cpmp.sequencer.switching`.
        coupling: ``none`` (paper: graphs coupled only through the features) or ``context``:
            hold back a transition while another variable runs an MP never seen at that
            demonstrated switch, or one that has progressed less than at every demonstrated
            one, or while a feature the active MP moves is faster than at every demonstrated
            instance of that switch (its speed envelope; learned from the labels; see
            :mod:`cpmp.sequencer.switching` and :mod:`cpmp.sequencer.motion`).
        progress_margin: with ``coupling=context``, another variable's MP counts as not far
            enough while its predicted φ is more than this below the least progress it had at
            a demonstrated switch (``None``: compare MPs only).
        recovery: resolve stalls (no switch and no motion for ``stall_time``) with a switch
            the demonstrator made in that context and nearest state, the most consistent with
            the coupling then the most probable (however low its ``p``, unless
            ``recovery_threshold`` asks more: nothing changes a stall, so waiting is no option);
            with none, give up (a ``give_up`` note) unless the task is at its demonstrated end
            (see :mod:`cpmp.sequencer.switching`).
        stall_time: seconds without any switch and without motion that count as a stall
            (features that move alike under every demonstrated MP and go on through its
            switches unbent, such as a distractor's wobble, are not motion:
            :func:`cpmp.sequencer.motion.ambient_features`).
        rest_speed: features count as at rest below this speed, in training ranges per second.
        recovery_threshold: the least ``p`` a recovery transition needs (default 0: any
            switch the demonstrator made there; above 0, a stall below it gives up instead).
        start_rule: ``independent`` (paper): each graph starts at its own initial node of
            highest entry probability ``1 - φ`` (φ of the node's own progress predictor).
            ``joint``: choose among the combinations of initial MPs seen together in a
            demonstration the one with the highest summed log entry probability, so graphs
            cannot start in a mixture of strategies that was never demonstrated (the coupling
            the paper's discussion proposes). ``learned`` (cpmp's default): the demonstrated
            combination that a multinomial logistic regression on the demonstrations' first
            states gives the highest probability, on the features weighted by how well they
            separate the demonstrated starts, so features that vary at the start without
            deciding it (a home jitter, a distractor) cannot mislead it, and without the
            ambient features (moving alike under every MP: a drift separates a handful of
            first states by chance) (:class:`cpmp.sequencer.branches.StartChoice`; the branch
            choice of a virtual root). A sequencer built without it (not by a fit) uses
            ``joint``.
        nonfinite: what a tick with non-finite features or φ does: ``hold`` (keep every MP,
            note it once per run of such ticks) or ``raise`` (:class:`~cpmp.errors.DataError`).
            A non-finite φ never fires.
        stale_time: without a stamp, a feature vector equal to the last one is a repeat of
            that measurement (a sensor slower than the loop) for up to this many seconds, and
            adds no evidence to the switching rule; unchanged for longer, the state counts as
            at rest (:mod:`cpmp.sequencer.timing`).
        branch: at a node with several demonstrated successors (a cycle's exit: again or move
            on), ``learned`` lets only the successor the demonstrator took in the most similar
            states fire (a multinomial logistic regression on the features at the demonstrated
            switches out of that node; :mod:`cpmp.sequencer.branches`); ``none`` (paper): the
            most probable ``p`` fires.
            ``learned`` also scales the entry probability of the demonstrated switches whose
            target φ reads "done" where the demonstrator entered it (a node re-entered in a
            loop: :func:`cpmp.sequencer.branches.entry_scales`).
        joint: with ``coupling=context``, a switch always demonstrated in the same sample as
            another variable's switch into the same MP (a bowl served as the last pour ends)
            waits until that variable has switched or its rule decides to switch in the same
            tick, and a recovery takes both (:attr:`cpmp.sequencer.switching.Coupling.joint`).
            A partner whose ``p`` was below the switch's at every demonstrated instance, and
            below the threshold at one, is taken along instead of waited for
            (:attr:`cpmp.sequencer.switching.JointPartner.carried`).
    """

    threshold: float = 0.65
    patience: float = 0.05
    min_improvement: float = 1e-3
    switch_rule: str = "peak"
    coupling: str = "context"
    progress_margin: float | None = 0.2
    recovery: bool = True
    stall_time: float = 1.0
    rest_speed: float = 0.01
    recovery_threshold: float = 0.0
    start_rule: str = "learned"
    nonfinite: str = "hold"
    stale_time: float = 0.25
    branch: str = "learned"
    joint: bool = True

    def __post_init__(self) -> None:
        for name in (
            "threshold",
            "patience",
            "min_improvement",
            "stall_time",
            "rest_speed",
            "recovery_threshold",
            "stale_time",
        ):
            finite_number(getattr(self, name), f"sequencer option {name}")
        if not 0.0 <= self.threshold < 1.0:
            raise ConfigError(f"threshold must be in [0, 1), got {self.threshold}")
        margin = self.progress_margin
        if margin is not None and (
            isinstance(margin, bool)
            or not isinstance(margin, (int, float))
            or not 0.0 <= margin <= 1.0
        ):
            raise ConfigError(f"progress_margin must be null or in [0, 1], got {margin!r}")
        if not 0.0 <= self.recovery_threshold < 1.0:
            raise ConfigError(
                f"recovery_threshold must be in [0, 1), got {self.recovery_threshold}"
            )
        if self.patience < 0.0:
            raise ConfigError(f"patience must be >= 0 seconds, got {self.patience}")
        if self.min_improvement < 0.0:
            raise ConfigError(f"min_improvement must be >= 0, got {self.min_improvement}")
        if self.stall_time <= 0.0 or self.rest_speed <= 0.0:
            raise ConfigError(
                f"stall_time and rest_speed must be > 0, got {self.stall_time} and "
                f"{self.rest_speed}"
            )
        if self.stale_time <= 0.0:
            raise ConfigError(f"stale_time must be > 0 seconds, got {self.stale_time}")
        for name in ("recovery", "joint"):
            if not isinstance(getattr(self, name), bool):
                raise ConfigError(f"{name} must be true or false, got {getattr(self, name)!r}")
        for name, allowed in (
            ("switch_rule", SWITCH_RULES),
            ("coupling", COUPLINGS),
            ("start_rule", START_RULES),
            ("nonfinite", NONFINITE_POLICIES),
            ("branch", BRANCHES),
        ):
            value = getattr(self, name)
            if value not in allowed:
                gone = REMOVED_SEQUENCER_VALUES.get((name, str(value)))
                raise ConfigError(
                    f"{name} must be one of {', '.join(map(repr, allowed))}, got {value!r}"
                    + (f" ({gone})" if gone else "")
                )


def existing_sequencer_options(
    options: Mapping[str, object], *, inert: bool = False
) -> dict[str, object]:
    """``options`` without the sequencer options that no longer exist.

    Args:
        options: sequencer option name -> value.
        inert: drop a removed option silently where it holds the value at which it did
            nothing (a checkpoint written before its removal); otherwise every removed option
            is an error.

    Returns:
        The options that exist.

    Raises:
        ConfigError: a removed option (:data:`REMOVED_SEQUENCER_OPTIONS`), named as removed,
            with why.
    """
    removed = REMOVED_SEQUENCER_OPTIONS
    gone = [
        name
        for name in options
        if name in removed and not (inert and options[name] == removed[name][0])
    ]
    if gone:
        reasons = "; ".join(f"{name}: {removed[name][1]}" for name in gone)
        raise ConfigError(
            f"removed sequencer option(s) {', '.join(gone)} ({reasons}); drop them"
            + (", or refit the checkpoint" if inert else "")
        )
    return {k: v for k, v in options.items() if k not in removed}
