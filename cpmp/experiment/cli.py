"""Shared behaviour of the Hydra entry points: clear one-line errors, output path printed last."""

from __future__ import annotations

import logging
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from cpmp.errors import CpmpError

log = logging.getLogger("cpmp")


def run_job(job: Callable[[Any, Path], Path], cfg: Any, run_dir: str | Path) -> Path:
    """Run ``job(cfg, run_dir)``; print its output path last. A user error (:class:`CpmpError`)
    is logged as one line and exits with status 2 instead of a traceback."""
    import torch

    torch.set_num_threads(max(1, int(cfg.get("threads", 1) or 1)))
    try:
        out = job(cfg, Path(run_dir))
    except CpmpError as err:
        log.error("%s: %s", type(err).__name__, err)
        print(f"error: {err}", file=sys.stderr)
        sys.exit(2)
    print(out)
    return out
