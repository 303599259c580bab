import json
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "scripts"))

import bench_sequencer  # noqa: E402


def test_bench_sequencer_prints_json(capsys):
    assert bench_sequencer.main(["--predictors", "klr", "--ticks", "20"]) == 0
    out = json.loads(capsys.readouterr().out)
    row = out["predictors"]["klr"]
    assert out["n_features"] == 3 and row["n_nodes"] == 6
    # 6 synthetic demos, stated support rule: 108 for the 6 nodes, plus 51 for the start heads
    # of the 3 initial nodes (a_go 21, b_go 21, b_wait 9: the same activations as those nodes)
    assert row["n_support_total"] == 108 + 51
    assert row["step_ms_mean"] > 0 and row["state_bytes"] > 0


def test_bench_sequencer_bad_file_is_a_clear_error(tmp_path, capsys):
    assert bench_sequencer.main(["--data", str(tmp_path / "missing.h5")]) == 2
    assert "error:" in capsys.readouterr().err


@pytest.mark.parametrize("bad", ["svm"])
def test_bench_sequencer_unknown_predictor(bad, capsys):
    assert bench_sequencer.main(["--predictors", bad, "--ticks", "5"]) == 2
    assert "unknown predictor" in capsys.readouterr().err
