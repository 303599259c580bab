#!/usr/bin/env bash
# Create (or update) the project's virtual environment in .venv with everything cpmp needs:
# the core and every extra (.[all]), plus the test tools (.[dev]).
# torch is pinned first so pip takes the CPU build from local disk instead of a CUDA build.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  "$PY" -m venv .venv
fi
stamp=.venv/.cpmp-installed
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ] || [ setup.py -nt "$stamp" ]; then
  .venv/bin/python -m pip install -q --upgrade pip
  .venv/bin/python -m pip install -q "torch==2.13.0"
  .venv/bin/python -m pip install -q -e ".[all,dev]"
  touch "$stamp"
fi
