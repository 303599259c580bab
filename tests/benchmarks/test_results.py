"""docs/results.md and the README's headline table are what the committed results/*.json render
(cpmp/benchmarks/results.py, scripts/render_results.py), so no number can drift from its run."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import pytest

from cpmp.benchmarks.results import (
    BEGIN,
    END,
    SECTIONS,
    headline,
    load_result,
    main,
    merge_synthetic,
    render_results,
    replace_block,
)
from cpmp.benchmarks.synthetic import summarise
from cpmp.errors import ConfigError, CpmpFileError

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "results"


def test_the_committed_page_is_what_the_committed_json_renders() -> None:
    page = (ROOT / "docs" / "results.md").read_text(encoding="utf-8")
    assert page == render_results(RESULTS), "run `python scripts/render_results.py`"


def test_the_readme_headline_is_what_the_committed_json_renders() -> None:
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert readme.count(BEGIN) == 1 and readme.count(END) == 1
    assert replace_block(readme, headline(RESULTS)) == readme, (
        "run `python scripts/render_results.py`"
    )
    # the headline's simulator row is the committed report's mean C at D = 3
    c3 = json.loads((RESULTS / "simulator.json").read_text())["reproduction"]["3"]["C"]
    block = readme[readme.index(BEGIN) : readme.index(END)]
    assert f"**{c3:.1f}**" in block


def test_the_merged_worlds_record_their_source_runs() -> None:
    worlds = load_result(RESULTS, "worlds.json")
    assert set(worlds["sources"]) == set(worlds["settings"]["policies"])
    # every summary cell is the bench's own summary of the merged rows
    assert worlds["summary"] == summarise(worlds["rows"])


# --- rendering small synthetic results -------------------------------------------------------


def synthetic_rows(policies: dict[str, int], world: str = "two_point") -> list[dict[str, Any]]:
    """One row per policy at D = 3, seed 0: ``policies[name]`` of 10 episodes complete."""
    return [
        {
            "world": world,
            "task": 0,
            "D": 3,
            "seed": 0,
            "policy": name,
            "complete": c,
            "wrong_start": 10 - c,
            "incomplete": 0,
            "n_episodes": 10,
        }
        for name, c in policies.items()
    ]


def synthetic_run(policies: dict[str, int], world: str = "two_point") -> dict[str, Any]:
    rows = synthetic_rows(policies, world)
    settings = {
        "worlds": [world],
        "policies": list(policies),
        "sizes": [3],
        "seeds": [0],
        "episodes": 10,
        "tasks": 1,
        "family_seeds": [0],
        "family_episodes": 10,
    }
    families = [world] if world == "procedural" else []
    return {"settings": settings, "rows": rows, "summary": summarise(rows), "families": families}


def small_results(folder: Path, c_sim: float = 3.0) -> Path:
    """Small results files (one per section), as the runs would write them, under ``folder``."""
    report = {
        "experiment": {
            "name": "tiny",
            "seeds": [0, 1],
            "demos_per_strategy": 2,
            "train_per_strategy": 1,
            "train_sizes": [3],
            "n_boxes": 4,
            "feature_noise": 0.0,
        },
        "predictor": {"kind": "klr"},
        "sequencer": {"start_rule": "learned"},
        "task": {"settle_time": 0.2},
        "reproduction": {
            "3": {
                **{"W": 4 - c_sim, "W_std": 0.5, "I": 0.0, "I_std": 0.0, "C": c_sim},
                **{"C_std": 0.5, "distance_mean": 0.1, "distance_std": 0.01},
                "paper": {"W": 3, "I": 4, "C": 13, "distance_mean": 0.13, "distance_std": 0.08},
            }
        },
        "progress": {
            "by_train_size": {
                "3": {"mae": 0.03, "mae_std": 0.0, "mae_first": 0.02, "mae_last": 0.04}
            }
        },
        "files": {"report.json": "all numbers"},
    }
    scale = {
        "settings": {"worlds": ["two_point"], "sizes": [12], "seed": 0, "held_out": 5},
        "machine": {"cpus": 2},
        "rows": [
            {"world": "two_point", "D": 12, "samples": 1234, "fit_s": 1.25, "peak_rss_gb": 0.5}
            | {"supports": 17, "mae": 0.0312, "complete": 5, "episodes": 5}
        ],
        "summary": {"two_point": {"exponents": {"fit": None}}},
        "lerobot": {"world": "two_point", "D": 400, "source": "lerobot", "samples": 150000}
        | {"fit_s": 30.5, "peak_rss_gb": 0.9, "supports": 700, "mae": 0.025, "complete": 5}
        | {"episodes": 5, "write_s": 2.5, "frames": 150000, "files": 8, "import_s": 12.34}
        | {"import_rss_gb": 1.5},
    }
    scale["settings"] |= {"episodes": 5, "dtype": "auto"}
    scale["rows"][0]["dtype"] = "float64"
    condition = {"complete": 4, "n_episodes": 5, "switch_error": {"mean_abs": 0.05}}
    clock = {
        "settings": {"seeds": [0], "demos": 6, "episodes": 5},
        "conditions": {"rate_100hz": {}, "sensor_10hz": {}},
        "reference": "rate_100hz",
        "worlds": {
            "two_point": {
                "conditions": {
                    "rate_100hz": condition | {"complete": 5, "switch_error": {"mean_abs": 0.012}},
                    "sensor_10hz": condition,
                },
                "scripted": {
                    n: {"complete": 5, "n_episodes": 5} for n in ("rate_100hz", "sensor_10hz")
                },
            }
        },
    }
    ratios = {"mae": 0.97, "supports": 0.24, "supports_all": 0.23, "tick": 0.9, "tick_floor": 0.88}
    ratios |= {"batch": 0.4, "step": 0.95, "fit": 2.5, "complete": 4.0}
    ratios["met"] = {"mae": True, "supports": True, "tick": False, "fit": False, "complete": True}
    sparse = {
        "settings": {"worlds": ["slip"], "sizes": [9], "seeds": [0, 1], "held_out": 6}
        | {"episodes": 20, "tasks": 10},
        "targets": {"mae": 1.1, "supports": 0.25, "tick": 0.5, "fit": 2.0, "complete": -1.0},
        "rows": [],
        "summary": {"slip": {"9": {"seeds": 2, "ratios": ratios}}},
    }
    files = {
        "simulator.json": report,
        "worlds.json": merge_synthetic(
            [
                ("old.json", synthetic_run({"scripted": 10, "defaults": 6})),
                ("new.json", synthetic_run({"defaults": 7})),
            ]
        ),
        "procedural.json": synthetic_run({"scripted": 10, "defaults": 4}, "procedural"),
        "clock.json": clock,
        "clock_procedural.json": {
            **clock,
            "settings": {"seeds": [0], "demos": 6, "episodes": 5, "tasks": 2},
            "scoring": "world",
            "worlds": {
                "procedural": clock["worlds"]["two_point"]
                | {"conditions": {n: condition | {"n_episodes": 10} for n in clock["conditions"]}}
            },
        },
        "clock_sim.json": {
            "settings": {"sim_seeds": [0, 1], "sim_demos": 6, "sim_boxes": 5},
            "conditions": clock["conditions"],
            "reference": "rate_100hz",
            "worlds": {
                "sim": {
                    "conditions": {
                        "rate_100hz": condition | {"complete": 9, "n_episodes": 10},
                        "sensor_10hz": condition | {"complete": 8, "n_episodes": 10},
                    }
                }
            },
        },
        "start.json": {"n_boxes": 10, "seeds": [0], "rows": [], "mean_per_20": {"3": {"r": 4.5}}},
        "scale.json": scale,
        "sparse.json": sparse,
    }
    folder.mkdir(parents=True, exist_ok=True)
    for name, result in files.items():
        (folder / name).write_text(json.dumps(result))
    return folder


def test_merge_replaces_a_policy_with_the_later_run_and_says_so() -> None:
    merged = merge_synthetic(
        [
            ("old.json", synthetic_run({"scripted": 10, "paper": 2, "defaults": 6})),
            ("new.json", synthetic_run({"defaults": 7})),
        ]
    )
    assert merged["sources"] == {
        "scripted": "old.json",
        "paper": "old.json",
        "defaults": "new.json",
    }
    assert merged["settings"]["policies"] == ["scripted", "paper", "defaults"]
    assert [(r["policy"], r["complete"]) for r in merged["rows"]] == [
        ("scripted", 10),
        ("paper", 2),
        ("defaults", 7),
    ]
    assert merged["summary"]["two_point"]["defaults"]["3"]["vs_scripted"] == 0.7
    with pytest.raises(ConfigError, match=r"new\.json"):
        merge_synthetic(
            [("old.json", synthetic_run({"a": 1})), ("new.json", synthetic_run({"b": 1}, "relay"))]
        )


def test_every_section_renders_its_numbers_and_settings(tmp_path: Path) -> None:
    page = render_results(small_results(tmp_path))
    for section in SECTIONS:
        assert f"## {section.title}" in page and f"`results/{section.file}`" in page
    assert "per seed (0, 1) 6 scripted demonstrations (3 train / 3 test)" in page
    assert "| 3 | 1.0 ± 0.5 | 0.0 ± 0.0 | 3.0 ± 0.5 | 3 / 4 / 13 |" in page
    assert "#### Reproduction (Table I)" in page  # the report's headings under the section's
    assert "| two_point | defaults | 70 / 30 / 0 |" in page  # the later run's row
    assert "`defaults` from `new.json`" in page  # and where it came from
    assert "Merged from 2 runs (`sources` in the JSON)" in page
    assert "| procedural | defaults | 40 / 60 / 0 (40 % of scripted) |" in page
    # klr_sparse against the default: its ratios, a missed bound marked, C as a difference
    assert "| slip | 9 | 0.97 | 0.24 | 0.23 | 0.90 ! | 0.88 | 0.40 | 0.95 | 2.50 ! | +4.0 |" in page
    assert "on every world (slip): per world, D = 9 and seed (0, 1)" in page
    assert "The `sim` rows" not in page  # none in this JSON
    bound = "issue #23's bound (MAE ≤ 1.1x, supports ≤ 0.25x, tick ≤ 0.5x, fit ≤ 2x, C ≥ −1)."
    assert bound in page  # read from the JSON's targets
    assert (
        "| r | 4.5 |" in page
        and "| two_point | 12 | 1,234 | 1.2 | 0.50 | 17 | 0.0312 | 5/5 |" in page
    )
    # the scale section's lerobot row: in the table, its import below it, said in the intro
    assert "| two_point via LeRobot v3 | 400 | 150,000 | 30.5 | 0.90 | 700 | 0.0250 | 5/5 |" in page
    assert "400 episodes (150,000 frames, 8 data files) written in 2.5 s" in page
    assert "cpmp-import 12.3 s, peak RSS 1.50 GB" in page
    assert "The last row: 400 demonstrations of two_point written as a LeRobot v3" in page
    assert "`dtype=auto`: float64 below 50,000 training samples" in page
    assert "from there on (float64 in these rows)" in page
    # the clock section: each condition's completions and switch-time error, the scripted below
    assert "| world | rate_100hz | sensor_10hz |" in page
    assert "| two_point | 5/5 (12 ms) | 4/5 (50 ms) |" in page
    assert "| two_point (scripted) | 5/5 | 5/5 |" in page
    assert "per world and seed (0) a fit on 6 demonstrations and 5 held-out episodes" in page
    # the procedural family's clock section: its tasks pooled, the scripted policy below
    assert "| procedural | 4/10 (50 ms) | 4/10 (50 ms) |" in page
    assert "its first 2 tasks, per task and seed (0) a fit on 6 demonstrations" in page
    # the simulator's clock section: its own file, seeds and boxes
    assert "| sim | 9/10 (50 ms) | 8/10 (50 ms) |" in page
    assert "per seed (0, 1) a fit on 6 simulated demonstrations and 5 held-out boxes" in page


def test_headline_puts_the_simulator_beside_the_paper_and_every_world(tmp_path: Path) -> None:
    table = headline(small_results(tmp_path, c_sim=2.5))
    lines = table.splitlines()
    assert lines[0] == "| | D = 3 |"
    assert "| simulator, the paper's Table I: W / I / C of 20 | 3 / 4 / 13 |" in lines
    assert any(line.endswith("| 1.5 / 0.0 / **2.5** |") for line in lines)
    assert "| two_point, cpmp's defaults: C % | 70 |" in lines
    assert "| procedural, cpmp's defaults: C % | 40 |" in lines


def test_a_missing_or_malformed_file_names_it_and_the_command(tmp_path: Path) -> None:
    folder = small_results(tmp_path / "r")
    (folder / "start.json").unlink()
    command = re.escape("run `python scripts/bench_start.py --out results/start.json`, then")
    with pytest.raises(CpmpFileError, match=r"start\.json: missing; " + command):
        render_results(folder)
    (folder / "start.json").write_text("{not json")
    with pytest.raises(CpmpFileError, match=r"start\.json: not readable JSON"):
        render_results(folder)
    (folder / "start.json").write_text(json.dumps({"rows": []}))
    with pytest.raises(CpmpFileError, match=r"start\.json: no n_boxes, seeds, mean_per_20"):
        render_results(folder)
    (folder / "start.json").write_text(json.dumps({"n_boxes": 1, "seeds": [0], "mean_per_20": 3}))
    with pytest.raises(CpmpFileError, match=r"start\.json: malformed"):
        render_results(folder)


def test_the_command_writes_both_files_and_check_says_when_stale(tmp_path: Path, capsys) -> None:
    folder = small_results(tmp_path / "r")
    page, readme = tmp_path / "results.md", tmp_path / "README.md"
    readme.write_text(f"# x\n\n{BEGIN}\nold table\n{END}\n\nrest\n")
    args = ["--results", str(folder), "--page", str(page), "--readme", str(readme)]
    assert main([*args, "--check"]) == 1  # nothing rendered yet
    assert not page.exists() and "old table" in readme.read_text()
    assert main(args) == 0
    assert page.read_text() == render_results(folder)
    text = readme.read_text()
    assert text == f"# x\n\n{BEGIN}\n{headline(folder)}{END}\n\nrest\n"
    assert main([*args, "--check"]) == 0
    small_results(folder, c_sim=1.0)  # a new run's JSON: both files are stale again
    assert main([*args, "--check"]) == 1
    assert "out of date" in capsys.readouterr().out
    readme.write_text("no markers\n")
    assert main(args) == 2
    assert "README.md: no `<!-- results:begin -->`" in capsys.readouterr().err
    assert list(tmp_path.glob(".*tmp*")) == []  # written atomically: no temporary left


def test_the_sparse_section_says_where_its_simulator_rows_come_from(tmp_path: Path) -> None:
    folder = small_results(tmp_path)
    sparse = json.loads((folder / "sparse.json").read_text())
    sparse["settings"] |= {"worlds": ["slip", "sim"], "sim_seeds": [0, 1], "sim_boxes": 20}
    sparse["note"] = "The sim rows come from a run of their own"
    (folder / "sparse.json").write_text(json.dumps(sparse))
    page = render_results(folder)
    assert "on every world (slip): per world" in page  # the simulator is not a synthetic world
    assert (
        "The `sim` rows: the simulator, the main job's full-run demonstrations of seeds 0, 1 "
        "(the balanced D of them), 20 reproduction boxes each. The sim rows come from a run of "
        "their own." in page
    )


def test_the_clock_sections_say_how_their_run_scored_and_which_sequencer_ran(
    tmp_path: Path,
) -> None:
    """A clock run written by the current bench (``scoring: world``) is described as scored
    like the worlds table; one without it as the earlier bench's stricter count, run with the
    sequencer before the speed envelopes."""
    folder = small_results(tmp_path)
    for name in ("clock.json", "clock_sim.json"):
        clock = json.loads((folder / name).read_text())
        clock.pop("scoring", None)
        (folder / name).write_text(json.dumps(clock))
    old = render_results(folder)
    assert "This run predates the worlds' scoring in bench_clock" in old
    assert old.count("before its speed envelopes") == 2  # both clock sections
    for name in ("clock.json", "clock_sim.json"):
        clock = json.loads((folder / name).read_text())
        (folder / name).write_text(json.dumps({**clock, "scoring": "world"}))
    new = render_results(folder)
    assert "Episodes are scored as in the worlds table" in new
    assert "before its speed envelopes" not in new and "predates" not in new
    # a merged run says where its rows come from (its note)
    clock = json.loads((folder / "clock.json").read_text())
    (folder / "clock.json").write_text(json.dumps({**clock, "note": "Merged from 2 runs."}))
    assert "condition within 1 episode per 20 of the 100 Hz run. Merged from 2 runs." in (
        render_results(folder)
    )
