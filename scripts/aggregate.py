"""Aggregate a multirun of scripts/experiment.py into one table (json, md, csv) and a plot
(``cpmp-aggregate``).

python scripts/experiment.py -m predictor=klr,klr_sparse predictor.support_scale=0.5,2.0
python scripts/aggregate.py sweep_dir=logs/experiment-multirun/<timestamp>

The files are written into sweep_dir; the path of aggregate.json is printed last.
"""

from cpmp.cli.main import aggregate_main

if __name__ == "__main__":
    aggregate_main()
