"""The predictor comparison: every predictor and baseline on the same data (``cpmp-compare``).

python scripts/compare.py                              # experiment=compare
python scripts/compare.py experiment=compare_tiny      # the smallest, for a quick look
python scripts/compare.py compare.predictors=[klr,mlp] sequencer=paper
"""

from cpmp.cli.main import compare_main

if __name__ == "__main__":
    compare_main()
