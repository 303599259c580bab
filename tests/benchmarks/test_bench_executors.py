"""The executor benchmark (:mod:`cpmp.benchmarks.executors`; named apart from
tests/experiment/test_executors.py, which tests the executors): what it measures and reports,
not how fast (the numbers are machine-dependent)."""

from __future__ import annotations

import json

import pytest

from cpmp.benchmarks.executors import ExecutorBenchSettings, main, markdown
from cpmp.errors import ConfigError


@pytest.mark.slow
def test_quick_run_compares_every_backend_with_inline(tmp_path, capsys):
    """``--quick`` on inline and local: both run the same small jobs with one torch thread,
    local's results are inline's, every timing is written, and the table has a row each."""
    out = tmp_path / "bench.json"
    code = main(["--quick", "--backends", "local", "--out", str(out), "--folder", str(tmp_path)])
    assert code == 0
    result = json.loads(out.read_text())
    assert list(result["backends"]) == ["inline", "local"]  # inline first, the reference
    for name, entry in result["backends"].items():
        small = entry["small"]
        assert small["identical"] is True, name
        assert small["torch_threads"] == [1] or name == "inline"
        assert small["wall_s"] >= small["first_round_s"] + small["steady_round_s"] > 0
        assert "main_job" not in entry  # the quick run leaves the main job out
    assert result["backends"]["local"]["small"]["slots"] == 2
    table = markdown(result)
    assert table.count("\n| inline | 1 |") == 1 and "\n| local | 2 |" in table
    assert "| local |" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"backends": ("inline", "ray")}, "unknown backend"),
        ({"jobs": 0}, "jobs must be an integer >= 1"),
        ({"workers": True}, "workers must be an integer >= 1"),
    ],
)
def test_bad_settings_are_config_errors(options, message):
    with pytest.raises(ConfigError, match=message):
        ExecutorBenchSettings(**options)
