"""Record N scripted demonstrations into an HDF5 file in the Hydra run directory.

Usage: python scripts/collect.py n_demos=15 seed=0 balanced=true task.width_range=[0.1,0.3]
"""

from __future__ import annotations

from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from cpmp.sim import TaskConfig
from cpmp.sim.collect import collect_demonstrations


@hydra.main(version_base="1.3", config_path="../conf", config_name="collect")
def main(cfg: DictConfig) -> str:
    """Write the demos and print the file path."""
    task = TaskConfig.from_dict(cfg.task)
    out = Path(HydraConfig.get().runtime.output_dir) / cfg.output
    path, _ = collect_demonstrations(task, int(cfg.n_demos), int(cfg.seed), out, bool(cfg.balanced))
    print(path)
    return str(path)


if __name__ == "__main__":
    main()
