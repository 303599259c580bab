"""The worlds table (cpmp.benchmarks.synthetic, scripts/bench_synthetic.py): every registered
world and policy, counts that are each world's own closed loop, a documented JSON."""

from __future__ import annotations

import json

import pytest

from cpmp.benchmarks.synthetic import (
    POLICIES,
    TABLE,
    SyntheticSettings,
    main,
    markdown,
    run_synthetic_benchmark,
)
from cpmp.errors import ConfigError
from cpmp.sequencer.sequencer import PAPER_OPTIONS, ConcurrentSequencer
from cpmp.worlds import relay
from cpmp.worlds.registry import entry, world_names


def test_rows_count_each_worlds_own_closed_loop():
    """A row is the policy fitted on D demonstrations of seed s and run on the world's
    contexts of seed 1000 + s: the counts the world's own evaluation gives that fit."""
    settings = SyntheticSettings.quick(
        worlds=("relay",), policies=("defaults", "paper"), seeds=(1,), episodes=4
    )
    result = run_synthetic_benchmark(settings)
    rows = result["rows"]
    assert [(r["world"], r["policy"], r["D"], r["seed"]) for r in rows] == [
        ("relay", "defaults", 3, 1),
        ("relay", "paper", 3, 1),
    ]
    seq = ConcurrentSequencer.fit(
        relay.make_demonstrations(3, 1), "klr", seed=1, logger=None, **PAPER_OPTIONS
    )
    counts = relay.evaluate(seq, None, 4, 1001)
    assert {k: rows[1][k] for k in ("complete", "wrong_start", "incomplete")} == {
        k: counts[k] for k in ("complete", "wrong_start", "incomplete")
    }
    cell = result["summary"]["relay"]["paper"]["3"]
    assert cell["n_episodes"] == 4
    assert cell["complete_frac"] == pytest.approx(counts["complete"] / 4)


@pytest.mark.slow
def test_the_table_runs_the_registered_worlds_and_every_policy(run_script, tmp_path):
    assert SyntheticSettings().worlds == world_names()  # no list of worlds in the bench
    out = tmp_path / "synthetic.json"
    worlds = ("two_point", "procedural")  # short: a single world and a family
    done = run_script(
        "bench_synthetic.py", "--quick", "--worlds", *worlds, "--out", str(out), timeout=900
    )
    assert done.returncode == 0, done.stderr[-3000:]
    result = json.loads(out.read_text())
    assert list(result["summary"]) == list(worlds)
    for world, policies in result["summary"].items():
        assert list(policies) == list(TABLE)
        members = 2 if entry(world).family else 1
        for cell in (c for by_d in policies.values() for c in by_d.values()):
            assert cell["n_episodes"] == 2 * members
            assert sum(cell[k] for k in ("complete", "wrong_start", "incomplete")) == 2 * members
    assert result["families"] == ["procedural"]
    text = markdown(result)
    assert text.splitlines()[0].startswith("| world | policy | D=3: C / W / I %")
    assert "| two_point | scripted |" in done.stdout


def test_same_settings_give_the_same_table():
    settings = SyntheticSettings.quick(worlds=("two_point",), policies=("defaults",))
    assert run_synthetic_benchmark(settings) == run_synthetic_benchmark(settings)


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"worlds": ("nope",)}, "unknown world 'nope'"),
        ({"policies": ("magic",)}, "unknown policies"),
        ({"episodes": 0}, "episodes must be a positive integer"),
        ({"sizes": (3, 0)}, r"sizes\[1\] must be a positive integer"),
        ({"seeds": ()}, "at least one"),
    ],
)
def test_bad_settings_are_refused(options, message):
    with pytest.raises(ConfigError, match=message):
        SyntheticSettings(**options)


def test_bad_command_line_is_one_error_line(capsys, tmp_path):
    assert main(["--quick", "--episodes", "0", "--out", str(tmp_path / "x.json")]) == 2
    assert "bench_synthetic: error: episodes must be a positive integer" in capsys.readouterr().err
    assert not (tmp_path / "x.json").exists()


def test_every_table_policy_is_named():
    assert set(TABLE) <= set(POLICIES)
    assert TABLE[0] == "scripted"  # the fairness proof comes first in every world's rows
