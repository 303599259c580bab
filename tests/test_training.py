import csv

from cpmp.sequencer import ConcurrentSequencer


def test_lightning_csv_logger_records_loss(train_demos, tmp_path):
    seq = ConcurrentSequencer.fit(train_demos, "klr", seed=0, logger="csv", log_dir=str(tmp_path))
    (metrics,) = tmp_path.rglob("metrics.csv")
    rows = list(csv.DictReader(metrics.open()))
    losses = [float(r["train/loss"]) for r in rows if r.get("train/loss")]
    assert len(losses) == seq.fit_summary["epochs"]
    assert losses[-1] <= losses[0]
    assert seq.fit_summary["loss"] <= losses[0]


def test_lbfgs_reaches_the_convex_optimum(train_demos):
    # KLR's loss is convex: more LBFGS steps must not find a meaningfully lower loss
    short = ConcurrentSequencer.fit(train_demos, "klr", seed=0, logger=None)
    long = ConcurrentSequencer.fit(train_demos, "klr", seed=0, logger=None, max_epochs=8)
    assert long.fit_summary["loss"] > short.fit_summary["loss"] - 1e-6
