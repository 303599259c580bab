"""Evaluate a checkpoint offline on a file's test split (no simulator).

python scripts/evaluate.py checkpoint=logs/train/.../model.pt data.path=my_demos.h5
"""

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from cpmp.experiment.cli import run_job
from cpmp.experiment.jobs import evaluate_checkpoint


@hydra.main(version_base="1.3", config_path="../conf", config_name="evaluate")
def main(cfg: DictConfig) -> None:
    run_job(evaluate_checkpoint, cfg, HydraConfig.get().runtime.output_dir)


if __name__ == "__main__":
    main()
