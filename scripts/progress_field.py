"""The paper's Fig. 3 on synthetic 2-D trajectories: ``python scripts/progress_field.py``."""

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from cpmp.experiment.config import predictor_options
from cpmp.experiment.examples import progress_field_example


@hydra.main(version_base="1.3", config_path="../conf", config_name="progress_field")
def main(cfg: DictConfig) -> None:
    kind, options = predictor_options(cfg.predictor)
    result = progress_field_example(
        HydraConfig.get().runtime.output_dir,
        n_trajectories=cfg.n_trajectories,
        seed=cfg.seed,
        predictor=kind,
        predictor_options=options,
    )
    print(f"support points: {result['n_support']}, training MAE: {result['train_mae']:.4f}")
    print(result["png"])


if __name__ == "__main__":
    main()
