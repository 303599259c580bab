"""Train a sequencer from your own demonstrations and save a checkpoint (``cpmp-train``).

python scripts/train.py data.path=my_demos.h5 predictor=klr
"""

from cpmp.cli.main import train_main

if __name__ == "__main__":
    train_main()
