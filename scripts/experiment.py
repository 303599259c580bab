"""The main job: collect demos in the simulator, train, evaluate, report (``cpmp-experiment``).

python scripts/experiment.py                      # experiment=quick
python scripts/experiment.py experiment=full      # the paper's sizes over 5 seeds
python scripts/experiment.py -m launcher=joblib predictor=klr,klr_sparse,mlp
"""

from cpmp.cli.main import experiment_main

if __name__ == "__main__":
    experiment_main()
