"""Evaluate a checkpoint offline on a file's test split, no simulator (``cpmp-evaluate``).

python scripts/evaluate.py checkpoint=logs/train/.../model.pt data.path=my_demos.h5
"""

from cpmp.cli.main import evaluate_main

if __name__ == "__main__":
    evaluate_main()
