"""What a job shows while it runs: each stage logged with its duration, progress bars."""

from __future__ import annotations

import logging
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import TypeVar

from tqdm import tqdm

log = logging.getLogger(__name__)

T = TypeVar("T")


def progress_bar(items: list[T], desc: str) -> tqdm[T]:
    """A tqdm progress bar over ``items`` on stderr (cleared when done)."""
    return tqdm(items, desc=desc, leave=False, dynamic_ncols=True)


@contextmanager
def stage(name: str) -> Iterator[None]:
    """Log the start and the duration of a stage of a job."""
    log.info("stage %s: start", name)
    start = time.perf_counter()
    yield
    log.info("stage %s: done in %.1f s", name, time.perf_counter() - start)


@contextmanager
def timed(seconds: dict[str, float], key: str, name: str) -> Iterator[None]:
    """A logged :func:`stage` whose wall time [s] is added to ``seconds[key]``."""
    start = time.perf_counter()
    with stage(name):
        yield
    seconds[key] = seconds.get(key, 0.0) + time.perf_counter() - start
