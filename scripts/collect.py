"""Record N scripted demonstrations into an HDF5 file in the Hydra run directory
(``cpmp-collect``).

python scripts/collect.py n_demos=15 seed=0 balanced=true task.width_range=[0.1,0.3]
"""

from cpmp.cli.main import collect_main

if __name__ == "__main__":
    collect_main()
