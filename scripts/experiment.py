"""The main job: collect demos in the simulator, train, evaluate, report.

python scripts/experiment.py                      # experiment=quick
python scripts/experiment.py experiment=full      # the paper's sizes over 5 seeds
python scripts/experiment.py -m launcher=joblib predictor=klr,klr_sparse,mlp
"""

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from cpmp.experiment.cli import run_job
from cpmp.experiment.jobs import run_experiment


@hydra.main(version_base="1.3", config_path="../conf", config_name="experiment")
def main(cfg: DictConfig) -> None:
    run_job(run_experiment, cfg, HydraConfig.get().runtime.output_dir)


if __name__ == "__main__":
    main()
