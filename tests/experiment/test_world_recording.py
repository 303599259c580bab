"""Recording a synthetic world's episode: the same episode the benchmarks count, read back."""

from __future__ import annotations

import pytest

from cpmp.experiment.world_recording import HELD_OUT_SEED, main, record_world_episode
from cpmp.recordings import read_recording, read_views
from cpmp.sequencer import ConcurrentSequencer
from cpmp.worlds.protocol import run_episodes
from cpmp.worlds.registry import make_world


@pytest.fixture(scope="module")
def peg():
    world = make_world("peg")
    seq = ConcurrentSequencer.fit(world.demonstrations(3, 0), seed=0)
    return world, seq


def test_a_recorded_episode_is_the_one_the_benchmarks_count(peg, tmp_path):
    world, seq = peg
    contexts = world.contexts(2, HELD_OUT_SEED)
    counted = run_episodes(world, seq, contexts)
    for i, context in enumerate(contexts):
        path = tmp_path / f"e{i}.rrd"
        episode = record_world_episode(world, seq, context, path)
        assert episode.outcome == counted[i].outcome
        assert episode.sequences == counted[i].sequences
        summary = read_recording(path)
        assert summary.outcome == episode.outcome
        assert [(e.variable, e.source, e.target) for e in summary.transitions] == [
            (e.variable, e.source, e.target) for e in seq.events
        ]
        assert summary.start is not None and summary.start.chosen == episode.initial
        if episode.outcome == "incomplete":
            assert summary.cause is not None and summary.cause == episode.cause
            # the demonstrated sequences run to the end without the goal, or a named switch
            assert summary.cause.reason == "task_unfinished" or (
                summary.cause.variable in world.variables
            )
        assert "features/" + world.feature_names[0] in summary.entity_paths
        # nothing 3D to draw: no empty scene view, the status takes the left column
        views = read_views(path)
        assert "scene" not in [v.name for v in views]
        assert "status" in [v.name for v in views]


def test_the_command_records_and_rejects_an_unknown_world(tmp_path, capsys):
    out = tmp_path / "r.rrd"
    assert main(["two_point", "--demos", "2", "--out", str(out)]) == 0
    assert read_recording(out).outcome in ("complete", "wrong_start", "incomplete")
    assert main(["no_such_world"]) == 2
    assert "unknown world 'no_such_world'" in capsys.readouterr().out
