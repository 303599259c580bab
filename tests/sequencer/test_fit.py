"""The fit module: the sequencer's only door to Lightning; the split of a fit's demonstrations."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from cpmp.config import FitConfig
from cpmp.data import Demonstration
from cpmp.errors import DataError
from cpmp.sequencer import ConcurrentSequencer
from cpmp.sequencer.fit import fit_demos, fit_parts

INFERENCE_ONLY = """
import json, sys
import numpy as np
import cpmp.sequencer
from cpmp.sequencer import ConcurrentSequencer

seq = ConcurrentSequencer.load(sys.argv[1])
x = np.asarray(json.loads(sys.argv[2]))
seq.reset(0.0, x[0])
for k, row in enumerate(x[1:], start=1):
    seq.step(0.01 * k, row)
batch = seq.batched(2)
batch.reset(0.0, np.stack([x[0], x[0]]))
batch.step(0.01, np.stack([x[1], x[1]]))
stepped = "lightning" in sys.modules
import cpmp.sequencer.fit
print(json.dumps({"stepped": stepped, "fit_module": "lightning" in sys.modules}))
"""
"""Load a checkpoint and step it, single and batched, then import the fit module; print whether
Lightning was loaded after each."""


@pytest.mark.slow
def test_loading_and_stepping_a_checkpoint_never_imports_lightning(
    fitted_klr: ConcurrentSequencer, train_demos: list[Demonstration], tmp_path: Path
) -> None:
    path = fitted_klr.save(tmp_path / "model.pt")
    features = train_demos[0].features[:5].tolist()
    proc = subprocess.run(
        [sys.executable, "-c", INFERENCE_ONLY, str(path), json.dumps(features)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    seen = json.loads(proc.stdout.strip().splitlines()[-1])
    assert seen == {"stepped": False, "fit_module": True}  # the probe sees Lightning arrive


def test_fit_config_builds_the_sequencer_on_fit_parts(train_demos: list[Demonstration]) -> None:
    config = FitConfig.from_options("klr", seed=2)
    parts = fit_parts(train_demos, config)
    seq = ConcurrentSequencer.fit_config(train_demos, config)
    assert {v: g.to_dict() for v, g in parts.graphs.items()} == {
        v: g.to_dict() for v, g in seq.graphs.items()
    }
    assert parts.feature_names == seq.feature_names
    assert parts.initial_combinations == seq.initial_combinations
    np.testing.assert_array_equal(parts.feature_range, seq.feature_range)
    x = train_demos[1].features[::7]
    with torch.no_grad():
        phi = parts.predictor.eval()(torch.from_numpy(np.ascontiguousarray(x))).numpy()
    np.testing.assert_array_equal(phi, seq.progress(x))  # the same seed: the same fit
    assert parts.summary.n_demos == seq.fit_summary.n_demos == len(train_demos)
    assert len(parts.demos) == len(train_demos)


def test_fit_demos_holds_out_a_seeded_share(train_demos: list[Demonstration]) -> None:
    a = fit_demos(train_demos, None, 0.34, seed=3)
    assert a.validation is not None and len(a.validation) == 2 and len(a.train) == 4
    assert {d.name for d in a.train} | {d.name for d in a.validation} == {
        d.name for d in train_demos
    }
    b = fit_demos(train_demos, None, 0.34, seed=3)
    assert [d.name for d in b.validation or []] == [d.name for d in a.validation]
    assert fit_demos(train_demos, None, 0.0, seed=3).validation is None


def test_fit_demos_refuses_validation_with_other_features(
    train_demos: list[Demonstration],
) -> None:
    demo = train_demos[0]
    other = Demonstration(
        time=demo.time,
        features=demo.features,
        labels=demo.labels,
        feature_names=[f"other_{i}" for i in range(demo.features.shape[1])],
        name="other",
    )
    with pytest.raises(DataError, match="validation demonstrations have features"):
        fit_demos(train_demos, [other], 0.0, seed=0)


def test_dtype_auto_fits_small_data_in_float64_and_large_data_in_float32(
    train_demos: list[Demonstration], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import cpmp.config.predictors as options

    n = sum(d.n_samples for d in train_demos)
    assert n < options.FLOAT32_FROM_SAMPLES
    small = fit_parts(train_demos, FitConfig.from_options("klr"))
    assert small.predictor.config.dtype == "float64" and small.predictor.dtype_ == torch.float64
    monkeypatch.setattr(options, "FLOAT32_FROM_SAMPLES", n)  # these demos count as large
    seq = ConcurrentSequencer.fit(train_demos, logger=None)
    assert seq.predictor.config.dtype == "float32"
    assert {b.dtype for b in seq.predictor.buffers() if b.is_floating_point()} == {torch.float32}
    # the type the fit used is the checkpoint's: loaded, it steps in float32 as fitted
    loaded = ConcurrentSequencer.load(seq.save(tmp_path / "model.pt"))
    assert loaded.predictor.config.dtype == "float32"
    x = train_demos[0].features[::9]
    np.testing.assert_array_equal(loaded.progress(x), seq.progress(x))
    # float32 and float64 fits of the same data agree to float32's rounding
    f64 = ConcurrentSequencer.fit(train_demos, logger=None, dtype="float64")
    assert f64.predictor.config.dtype == "float64"
    assert not np.array_equal(seq.progress(x), f64.progress(x))
    np.testing.assert_allclose(seq.progress(x), f64.progress(x), atol=2e-3)
    # an explicit type is kept whatever the size
    explicit = fit_parts(train_demos, FitConfig.from_options("klr", dtype="float64"))
    assert explicit.predictor.config.dtype == "float64"
