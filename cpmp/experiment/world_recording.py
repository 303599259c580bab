"""A rerun recording of one synthetic world's episode (``scripts/record_world.py``).

The worlds of :mod:`cpmp.worlds` (the reactive ones among them) have no robot to draw, but what
a sequencer decided there reads the same way as on the simulator: the features, every node's
φ, the transition probabilities against the threshold, the switches, holds and recoveries, the
start decision and an incomplete episode's cause. :func:`record_world_episode` runs one episode
of a world with a fitted sequencer, exactly as :func:`cpmp.worlds.protocol.evaluate` does, and
writes it with :class:`~cpmp.recordings.EpisodeRecorder`; :func:`main` fits the defaults on a
world's demonstrations and records one held-out episode.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from cpmp.errors import ConfigError, CpmpError
from cpmp.experiment.reproduction import EpisodeLogger
from cpmp.recordings import EpisodeRecorder
from cpmp.sequencer import ConcurrentSequencer
from cpmp.worlds.protocol import EpisodeRun, World, run_episode
from cpmp.worlds.registry import make_world, world_names

HELD_OUT_SEED = 1000
"""The recorded episode of seed ``s`` is drawn with ``HELD_OUT_SEED + s`` (as the benchmarks)."""


def record_world_episode(
    world: World, seq: ConcurrentSequencer, context: object, path: str | Path
) -> EpisodeRun:
    """Run one episode of ``world`` with ``seq`` and record it to ``path`` (``.rrd``).

    The loop is :func:`cpmp.worlds.protocol.run_episode`, the one
    :func:`cpmp.worlds.protocol.evaluate` runs, so the episode and its outcome are the ones the
    benchmarks count.

    Args:
        world: a registered world (:func:`cpmp.worlds.registry.make_world`).
        seq: a sequencer fitted on the world's demonstrations.
        context: the episode's context (``world.contexts(n, seed)[i]``).
        path: the recording to write (atomically).

    Returns:
        The scored episode, an incomplete one with its cause.
    """
    mp_names = {v: list(seq.graphs[v].ordered_nodes()) for v in world.variables}
    with EpisodeRecorder(
        path,
        feature_names=list(world.feature_names),
        mp_names=mp_names,
        episode=world.name,
        metadata={"world": world.name, "strategy": world.strategy(context)},
        threshold=seq.config.threshold,
    ) as recorder:
        episode = run_episode(world, seq, context, on_tick=EpisodeLogger(recorder, seq))
        recorder.log_outcome(
            episode.time,
            episode.outcome,
            f"strategy {episode.strategy}",
            success=episode.outcome == "complete",
            cause=episode.cause,
        )
    return episode


def main(argv: list[str] | None = None) -> int:
    """``scripts/record_world.py``: fit cpmp's defaults on a world and record an episode.

    Returns:
        0, or 2 after a :class:`~cpmp.errors.CpmpError` (a bad option).
    """
    parser = argparse.ArgumentParser(
        description="Fit cpmp's defaults on a synthetic world's demonstrations and write a "
        "rerun recording of one held-out episode (open it with `rerun FILE`)."
    )
    parser.add_argument("world", help=f"one of {', '.join(world_names(family=False))}")
    parser.add_argument("--demos", type=int, default=9, help="demonstrations (9)")
    parser.add_argument("--seed", type=int, default=0, help="demonstrations and fit (0)")
    parser.add_argument("--episode", type=int, default=0, help="held-out episode index (0)")
    parser.add_argument("--out", default=None, help="the .rrd (logs/<world>_episode_<i>.rrd)")
    args = parser.parse_args(argv)
    try:
        if args.world not in world_names(family=False):
            raise ConfigError(
                f"unknown world {args.world!r}; one of {', '.join(world_names(family=False))}"
            )
        if args.demos < 1 or args.episode < 0:
            raise ConfigError("--demos must be >= 1 and --episode >= 0")
        world = make_world(args.world)
        seq = ConcurrentSequencer.fit(world.demonstrations(args.demos, args.seed), seed=args.seed)
        context = world.contexts(args.episode + 1, HELD_OUT_SEED + args.seed)[args.episode]
        out = Path(args.out or f"logs/{args.world}_episode_{args.episode}.rrd")
        out.parent.mkdir(parents=True, exist_ok=True)
        episode = record_world_episode(world, seq, context, out)
    except CpmpError as error:
        print(f"error: {error}")
        return 2
    cause = f"; {episode.cause.describe()}" if episode.cause is not None else ""
    print(f"{out}: {episode.outcome} ({episode.strategy}, {episode.time:.2f} s){cause}")
    return 0
