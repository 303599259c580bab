"""Record one held-out episode of a synthetic world with cpmp's defaults (rerun ``.rrd``).

python scripts/record_world.py peg [--demos 9] [--seed 0] [--episode 1] [--out logs/peg.rrd]
"""

from cpmp.experiment.world_recording import main

if __name__ == "__main__":
    raise SystemExit(main())
