"""Render docs/results.md and the README's headline table from the committed benchmark JSON
in results/ (each number lives in one place). Run from the repository root.

python scripts/render_results.py [--check] [--results results] [--page docs/results.md]
    [--readme README.md]
"""

from cpmp.benchmarks.results import main

if __name__ == "__main__":
    raise SystemExit(main())
