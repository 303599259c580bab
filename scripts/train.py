"""Train a sequencer from your own demonstrations and save a checkpoint.

python scripts/train.py data.path=my_demos.h5 predictor=klr
"""

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from cpmp.experiment.cli import run_job
from cpmp.experiment.jobs import train_from_file


@hydra.main(version_base="1.3", config_path="../conf", config_name="train")
def main(cfg: DictConfig) -> None:
    run_job(train_from_file, cfg, HydraConfig.get().runtime.output_dir)


if __name__ == "__main__":
    main()
