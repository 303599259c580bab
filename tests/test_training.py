import csv

import pytest

from cpmp.sequencer import ConcurrentSequencer


@pytest.mark.parametrize("solver", ["newton", "lbfgs"])
def test_lightning_csv_logger_records_loss(train_demos, tmp_path, solver):
    seq = ConcurrentSequencer.fit(
        train_demos, "klr", seed=0, logger="csv", log_dir=str(tmp_path), solver=solver
    )
    (metrics,) = tmp_path.rglob("metrics.csv")
    rows = list(csv.DictReader(metrics.open()))
    losses = [float(r["train/loss"]) for r in rows if r.get("train/loss")]
    assert len(losses) == seq.fit_summary["epochs"] == {"newton": 1, "lbfgs": 3}[solver]
    assert losses == pytest.approx(seq.fit_summary["loss_history"], rel=1e-12)
    assert losses[-1] <= losses[0]
    assert seq.fit_summary["loss"] == pytest.approx(losses[-1], rel=1e-12)


def test_newton_reaches_the_convex_optimum(train_demos):
    # KLR's loss is convex: neither more LBFGS steps nor a second Newton epoch find a lower loss
    newton = ConcurrentSequencer.fit(train_demos, "klr", seed=0, logger=None)
    again = ConcurrentSequencer.fit(train_demos, "klr", seed=0, logger=None, max_epochs=2)
    lbfgs = ConcurrentSequencer.fit(
        train_demos, "klr", seed=0, logger=None, solver="lbfgs", max_epochs=8
    )
    assert newton.fit_summary["loss"] <= lbfgs.fit_summary["loss"] + 1e-12
    assert again.fit_summary["newton_iterations"] == 0
    assert again.fit_summary["loss"] == newton.fit_summary["loss"]
