"""Aggregate a multirun of scripts/experiment.py into one table (json, md, csv) and a plot.

python scripts/experiment.py -m predictor=klr,klr_sparse predictor.support_scale=0.5,2.0
python scripts/aggregate.py sweep_dir=logs/experiment-multirun/<timestamp>

The files are written into sweep_dir; the path of aggregate.json is printed last.
"""

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from cpmp.experiment.aggregate import aggregate_sweep
from cpmp.experiment.cli import run_job


@hydra.main(version_base="1.3", config_path="../conf", config_name="aggregate")
def main(cfg: DictConfig) -> None:
    run_job(aggregate_sweep, cfg, HydraConfig.get().runtime.output_dir)


if __name__ == "__main__":
    main()
