"""The paper's Fig. 3 on synthetic 2-D trajectories (``cpmp-progress-field``).

python scripts/progress_field.py [predictor=klr_sparse]
"""

from cpmp.cli.main import progress_field_main

if __name__ == "__main__":
    progress_field_main()
